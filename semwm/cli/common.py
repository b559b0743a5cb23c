"""What every ``semwm`` command shares: the parser class, exit statuses, errors,
and argument types that reject bad values with a one-line message."""

from __future__ import annotations

import argparse
import importlib.util
from typing import Any, NoReturn

EXIT_OK = 0
EXIT_INVALID = 1
EXIT_USAGE = 2

LOG_LEVELS = ("debug", "info", "warning", "error", "critical")
"""The values ``--log-level`` takes (Python logging's and uvicorn's names)."""

Subparsers = Any
"""``argparse``'s sub-parser action (``parser.add_subparsers()``): private type, so ``Any``."""


class CommandError(Exception):
    """A command cannot do what was asked; ``main`` prints ``semwm COMMAND: message``
    on one line (no traceback) and exits with ``status``."""

    def __init__(self, message: str, status: int = EXIT_USAGE) -> None:
        super().__init__(message)
        self.status = status


class Parser(argparse.ArgumentParser):
    """An ``ArgumentParser`` whose usage errors are one line on stderr:
    ``semwm simulate: error: argument --seed: invalid int value: 'x' (see semwm simulate --help)``.

    Sub-parsers inherit the class (``add_subparsers`` uses the parent's type).
    """

    def error(self, message: str) -> NoReturn:
        self.exit(EXIT_USAGE, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def description(docstring: str | None) -> str:
    """A module docstring as ``--help`` text: without reST's double backquotes."""
    return (docstring or "").replace("``", "")


def positive_float(text: str) -> float:
    """An ``argparse`` type: a finite number > 0."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number > 0, found {text!r}") from None
    if not value > 0.0 or value == float("inf"):
        raise argparse.ArgumentTypeError(f"expected a number > 0, found {text!r}")
    return value


def non_negative_int(text: str) -> int:
    """An ``argparse`` type: an integer >= 0."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an integer >= 0, found {text!r}") from None
    if value < 0:
        raise argparse.ArgumentTypeError(f"expected an integer >= 0, found {text!r}")
    return value


EXTRAS = {
    "mcap": ("mcap", "mcap"),
    "mqtt": ("paho", "paho-mqtt"),
    "foxglove": ("foxglove", "foxglove-sdk"),
    "ros2": ("rosbags", "rosbags"),
}
"""Each optional extra: the module it brings and the distribution that holds it."""


def require(extra: str, what: str) -> None:
    """A :class:`CommandError` naming the extra to install when ``what`` (an option
    or a command) needs an optional dependency that is not installed:
    ``--record needs mcap: pip install "semwm[mcap]"``. Checked before anything is
    written, so a missing extra leaves no file behind."""
    module, distribution = EXTRAS[extra]
    if importlib.util.find_spec(module) is None:
        raise CommandError(f'{what} needs {distribution}: pip install "semwm[{extra}]"')
