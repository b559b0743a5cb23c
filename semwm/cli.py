"""The ``semwm`` command line (minimal: only ``semwm knowledge ...`` so far)."""

from __future__ import annotations

import argparse
from collections.abc import Sequence

from api.cli import add_serve_command
from semwm.cli_knowledge import add_knowledge_commands
from semwm.persistence.cli import add_journal_command, add_record_command, add_replay_command
from semwm.sim.cli import add_simulate_command


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="semwm", description=__doc__)
    subparsers = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    add_knowledge_commands(subparsers)
    add_serve_command(subparsers)
    add_simulate_command(subparsers)
    add_replay_command(subparsers)
    add_record_command(subparsers)
    add_journal_command(subparsers)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line; returns the exit status."""
    args = build_parser().parse_args(argv)
    status: int = args.func(args)
    return status


if __name__ == "__main__":
    raise SystemExit(main())
