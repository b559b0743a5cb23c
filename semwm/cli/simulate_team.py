"""``semwm simulate ... --levels 1|2``: the team options (docs/team.md).

With ``--levels`` the scenario is played through :func:`semwm.sim.team_run.run_team`
(sources with their own clocks, network latency, flat or two-level) and
``metrics.json`` gains ``team``: CPU per level, messages and bytes between levels,
detections dropped as late, clock estimates.
"""

from __future__ import annotations

import argparse
import json
from collections.abc import Sequence
from pathlib import Path

from semwm.knowledge.model import Knowledge
from semwm.sim.runner import RunResult, write_run
from semwm.sim.scenarios import Scenario


def latency_range(text: str) -> tuple[float, float]:
    """``LOW,HIGH`` (or one value) in seconds."""
    low, _, high = text.partition(",")
    try:
        values = (float(low), float(high or low))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected LOW,HIGH in seconds; got {text!r}") from None
    if not 0.0 <= values[0] <= values[1]:
        raise argparse.ArgumentTypeError(f"need 0 <= LOW <= HIGH; got {text!r}")
    return values


def add_team_options(parser: argparse.ArgumentParser) -> None:
    team = parser.add_argument_group("team (docs/team.md)")
    team.add_argument(
        "--levels",
        type=int,
        choices=(1, 2),
        default=None,
        help="1: every detection to one model over the network; 2: local models per "
        "source report to a global model (paper 000)",
    )
    team.add_argument(
        "--clock-offset",
        type=float,
        default=0.0,
        metavar="S",
        help="source clocks off by up to +-S s (with --levels)",
    )
    team.add_argument(
        "--latency",
        type=latency_range,
        default=(0.0, 0.0),
        metavar="LOW,HIGH",
        help="one-way message latency range in s (with --levels)",
    )
    team.add_argument("--no-sync", action="store_true", help="do not estimate clock offsets")
    team.add_argument(
        "--receiver",
        default="reorder",
        choices=("reorder", "hold"),
        help="reorder: process on arrival, replaying within the reorder window (the "
        "service); hold: a sorting buffer, phase-sensitive (docs/team.md)",
    )
    team.add_argument(
        "--strategy",
        default="scans",
        choices=("all", "updated", "detections", "scans", "ci", "information"),
        help="what local models send (with --levels 2)",
    )
    team.add_argument(
        "--continuity",
        type=float,
        default=0.99,  # semwm.team.CONTINUITY_PROBABILITY (not imported: start-up time)
        metavar="P",
        help="with --levels 2: the global model keeps a robot's report on the global "
        "object its local object went to, widening a report outside that object's P "
        "gate (semwm.team.Continuity); 0: every report associated afresh",
    )
    team.add_argument(
        "--drift-gate",
        type=float,
        default=0.95,
        metavar="P",
        help="with --levels 2: a robot also reports between periods when the global "
        "view of an object leaves the P gate of its local estimate (send-on-delta); "
        "0: only for new objects",
    )


def simulate_team(
    args: argparse.Namespace,
    scenario: Scenario,
    knowledge: Knowledge,
    out: Path,
    ablations: Sequence[str] = (),
) -> RunResult:
    """Run the team simulation, write the run and the ``team`` part of metrics.json."""
    from semwm.sim.team_run import Network, run_team

    network = Network(
        max_offset=args.clock_offset,
        latency=args.latency,
        sync=not args.no_sync,
        receiver=args.receiver,
    )
    team = run_team(
        scenario,
        knowledge,
        levels=args.levels,
        network=network,
        strategy=args.strategy,
        drift_gate=args.drift_gate if args.drift_gate > 0 else None,
        seed=args.seed,
        continuity=args.continuity if args.continuity > 0 else None,
    )
    write_run(team.result, out, ablations=ablations)
    metrics_file = out / "metrics.json"
    document = json.loads(metrics_file.read_text(encoding="utf-8"))
    document["team"] = team.to_dict()
    metrics_file.write_text(json.dumps(document, indent=2) + "\n", encoding="utf-8")
    print(
        f"levels {args.levels}: CPU local {team.cpu_local_s:.2f} s, global "
        f"{team.cpu_global_s:.2f} s; between levels {team.messages} messages, "
        f"{team.bytes} bytes; late dropped {team.late}"
    )
    return team.result
