"""The knowledge files shipped with semwm (``sim1``, ``sim2``, ``robocup``; XML and YAML).

They live in ``knowledge/`` at the top of the repository; an installed package
carries them as package data in ``semwm/shipped_knowledge/``.
"""

from __future__ import annotations

from importlib import resources
from pathlib import Path

_SUFFIXES = (".xml", ".yaml", ".yml")


def _directory() -> Path:
    """The directory holding the shipped files: the repository's, else the package data."""
    repository = Path(__file__).resolve().parents[2] / "knowledge"
    if repository.is_dir():
        return repository
    return Path(str(resources.files("semwm") / "shipped_knowledge"))


def list_shipped() -> list[str]:
    """File names of the shipped knowledge files, sorted (``["robocup.xml", ...]``)."""
    directory = _directory()
    if not directory.is_dir():
        return []
    return sorted(p.name for p in directory.iterdir() if p.suffix in _SUFFIXES)


def shipped_knowledge_path(name: str) -> Path:
    """The path of the shipped knowledge file ``name`` (for example ``"sim2.yaml"``).

    Raises
    ------
    FileNotFoundError
        When no shipped file has that name; the message lists those that exist.
    """
    path = _directory() / name
    if path.name != name or not path.is_file():
        shipped = ", ".join(list_shipped()) or "none"
        raise FileNotFoundError(f"no shipped knowledge file {name!r}; shipped: {shipped}")
    return path
