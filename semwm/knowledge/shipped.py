"""The knowledge files shipped with semwm (``sim1``, ``sim2``, ``robocup``; XML and YAML).

They live in ``knowledge/`` at the top of the repository; an installed package
carries copies as package data in ``semwm/shipped_knowledge/``.

Which copy is read, first found:

1. the working tree's: ``knowledge/`` of the semwm checkout containing the current
   directory (a folder with a ``pyproject.toml`` naming the project ``semwm``), so
   that editing ``knowledge/sim2.yaml`` in a checkout takes effect in ``semwm
   simulate`` and the notebooks even after a plain ``pip install .``;
2. the repository's next to this source file (an editable install);
3. the installed package data.
"""

from __future__ import annotations

import tomllib
from importlib import resources
from pathlib import Path

_SUFFIXES = (".xml", ".yaml", ".yml")


def _is_semwm_checkout(folder: Path) -> bool:
    """``folder`` has ``knowledge/`` and a ``pyproject.toml`` whose project is ``semwm``."""
    pyproject = folder / "pyproject.toml"
    if not (pyproject.is_file() and (folder / "knowledge").is_dir()):
        return False
    try:
        project = tomllib.loads(pyproject.read_text(encoding="utf-8")).get("project", {})
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError):
        return False
    return isinstance(project, dict) and project.get("name") == "semwm"


def checkout_knowledge_directory(start: Path | None = None) -> Path | None:
    """``knowledge/`` of the semwm checkout containing ``start`` (default: the
    current directory), or ``None`` outside a checkout."""
    here = (start or Path.cwd()).resolve()
    for folder in (here, *here.parents):
        if _is_semwm_checkout(folder):
            return folder / "knowledge"
    return None


def _directory() -> Path:
    """The directory holding the shipped files (see the module docstring for the order)."""
    checkout = checkout_knowledge_directory()
    if checkout is not None:
        return checkout
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
