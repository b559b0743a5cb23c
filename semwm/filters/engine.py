"""Which engine runs the world model: ``"rust"`` (the compiled core ``semwm._core``,
built from ``core/`` by ``pip install``; the default wherever it is built) or
``"python"`` (numpy, the readable specification the Rust core is held to).

The Rust core runs the whole scan and keeps the filter's state between scans
(``core/src/mhf/filter.rs``; docs/engines.md). The extension is optional: where it was
not built (no Rust toolchain at install time) :func:`rust_core` is ``None``, the
Python engine runs, and asking for ``"rust"`` raises :class:`EngineUnavailable` with
the reason.
"""

from __future__ import annotations

import functools
import importlib
import os
from types import ModuleType
from typing import Final, Literal, get_args

__all__ = [
    "ENGINES",
    "ENGINE_ENV",
    "Engine",
    "EngineUnavailable",
    "default_engine",
    "engine_description",
    "resolve_engine",
    "rust_core",
    "rust_core_error",
]

Engine = Literal["python", "rust"]
ENGINES: Final[tuple[Engine, ...]] = get_args(Engine)
#: The environment variable :func:`resolve_engine` reads when no engine is given.
ENGINE_ENV: Final = "SEMWM_ENGINE"


class EngineUnavailable(RuntimeError):
    """``engine="rust"`` was asked for, but the Rust core is not built in this install."""


@functools.cache
def _import_core() -> tuple[ModuleType | None, str | None]:
    try:
        return importlib.import_module("semwm._core"), None
    except ImportError as error:
        return None, str(error)


def rust_core() -> ModuleType | None:
    """The compiled module ``semwm._core``, or ``None`` when it is not built."""
    return _import_core()[0]


def rust_core_error() -> str | None:
    """Why ``semwm._core`` could not be imported (``None`` when it was)."""
    return _import_core()[1]


def default_engine() -> Engine:
    """``"rust"`` where the extension is built, else ``"python"``."""
    return "rust" if rust_core() is not None else "python"


def resolve_engine(engine: str | None = None) -> Engine:
    """The engine to run: ``engine`` if given, else ``$SEMWM_ENGINE``, else
    :func:`default_engine` (``"rust"`` where the extension is built).

    Raises ``ValueError`` for an unknown name and :class:`EngineUnavailable` for
    ``"rust"`` when the extension is not built.
    """
    source = "engine"
    if engine is None:
        chosen = os.environ.get(ENGINE_ENV)
        if not chosen:
            return default_engine()
        engine, source = chosen, ENGINE_ENV
    name = engine.strip().lower()
    if name == "python":
        return "python"
    if name != "rust":
        raise ValueError(f"{source}: expected one of {', '.join(ENGINES)}; got {engine!r}")
    if rust_core() is None:
        raise EngineUnavailable(
            f"{source}='rust' needs the Rust core semwm._core, which this install does not "
            f"have ({rust_core_error()}). Install with a Rust toolchain (cargo) on PATH: "
            "`pip install .` builds it (docs/engines.md); or use engine 'python'."
        )
    return "rust"


def engine_description(engine: Engine) -> str:
    """``"python"`` or ``"rust (semwm-core 0.1.0)"``: what ``--version`` and ``/health`` say."""
    core = rust_core()
    if engine == "rust" and core is not None:
        return f"rust (semwm-core {core.__version__})"
    return engine
