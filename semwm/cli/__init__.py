"""semwm: a knowledge-driven semantic world model for robots.

Commands:

* ``semwm serve --knowledge FILE``: the HTTP service (OpenAPI at /docs);
* ``semwm simulate NAME``: run a simulated scenario through the world model;
  writes detections, truth, world, metrics and a plot. NAME is one of:
{scenarios};
* ``semwm knowledge validate|convert|show``: check, convert (XML <-> YAML) and
  inspect knowledge files;
* ``semwm replay|record|journal``: feed a recording or a data dir back through a
  world model, record to MCAP, export or compact a journal (docs/persistence.md).

``semwm COMMAND --help`` describes each command's options.
"""

from __future__ import annotations

import argparse
import logging
import os
import sys
import textwrap
from collections.abc import Callable, Sequence
from importlib import metadata

from semwm.cli.common import (
    EXIT_USAGE,
    LOG_LEVELS,
    CommandError,
    Parser,
    Subparsers,
    description,
)
from semwm.cli.knowledge import add_knowledge_command
from semwm.cli.persistence import add_journal_command, add_record_command, add_replay_command
from semwm.cli.serve import add_serve_command
from semwm.cli.simulate import add_simulate_command

COMMANDS: list[Callable[[Subparsers], object]] = [
    add_serve_command,
    add_simulate_command,
    add_knowledge_command,
    add_replay_command,
    add_record_command,
    add_journal_command,
]
"""Each adds one command (group) to the ``semwm`` parser: add a command here."""


def version() -> str:
    """The installed distribution's version (else the package's ``__version__``)."""
    try:
        return metadata.version("semwm")
    except metadata.PackageNotFoundError:
        from semwm import __version__

        return __version__


def scenario_names() -> list[str]:
    """Every name ``semwm simulate`` takes: :data:`semwm.sim.scenarios.SCENARIOS` and kick."""
    from semwm.sim.scenarios import SCENARIOS

    return [*SCENARIOS, "kick"]


def engine_line() -> str:
    """Which engine runs (``$SEMWM_ENGINE``, else python) and whether the Rust core is
    built: what ``semwm --version`` adds to the version."""
    from semwm.filters.engine import EngineUnavailable, resolve_engine, rust_core

    core = rust_core()
    built = f"built (semwm-core {core.__version__})" if core is not None else "not built"
    engine: str
    try:
        engine = resolve_engine()
    except (ValueError, EngineUnavailable) as error:
        engine = f"none: {error}"
    return f"engine: {engine}; Rust core: {built}"


def build_parser() -> argparse.ArgumentParser:
    """The ``semwm`` parser with every command of :data:`COMMANDS`."""
    parser = Parser(
        prog="semwm",
        description=description(__doc__).replace(
            "{scenarios}",
            textwrap.fill(
                ", ".join(scenario_names()), 78, initial_indent="  ", subsequent_indent="  "
            ),
        ),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument(
        "--version", action="version", version=f"semwm {version()} ({engine_line()})"
    )
    parser.add_argument(
        "--log-level",
        choices=LOG_LEVELS,
        default=None,
        help="log level of semwm and the server (default: warning; serve: info)",
    )
    subparsers = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for add_command in COMMANDS:
        add_command(subparsers)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line; returns the exit status.

    Usage errors (bad option values, unknown commands) and a command's
    :class:`CommandError` are one line on stderr, never a traceback.
    """
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exit_:  # --help, --version, usage errors (already printed)
        return exit_.code if isinstance(exit_.code, int) else EXIT_USAGE
    logging.basicConfig(
        level=(args.log_level or "warning").upper(),
        format="%(asctime)s %(levelname)s %(name)s: %(message)s",
    )
    try:
        status: int = args.func(args)
    except CommandError as error:
        print(f"semwm {args.command}: {error}", file=sys.stderr)
        return error.status
    except KeyboardInterrupt:
        print(f"semwm {args.command}: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:  # `semwm simulate sim1 | head -1`: the reader has gone
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())  # no error at exit
        return 141
    return status
