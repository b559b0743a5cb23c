"""``semwm simulate NAME``: run a scenario through the world model, print and write metrics.

Writes ``detections.jsonl``, ``truth.jsonl``, ``world.jsonl``, ``metrics.json`` and
``plot.png`` into ``--out`` (default ``runs/NAME-seedN``, with ``-no-ABLATION`` for
each ``--no-knowledge`` and ``-knowledge-STEM`` for ``--knowledge FILE``, so a
variant never overwrites the baseline). ``metrics.json`` records the knowledge
file and the ablations.

The knowledge is the scenario's shipped file (``sim2`` -> ``sim2.yaml``), read
from the checkout's ``knowledge/`` when run inside a semwm checkout (so edits
there take effect), else from the installed package; ``--knowledge FILE`` uses
any file instead.

Knowledge ablations (``--no-knowledge``) change the knowledge before the run, to
measure what a piece of knowledge is worth:

* ``door-relation``: remove every class's appearance relations (paper 002 eq. 4;
  in ``sim2`` "a Person appears near a Door"), leaving the base rates;
* ``taxonomy``: remove every is-a relation, each class keeping the settings it
  inherited (paper 002 eq. 8: ``Can`` then no longer matches ``CokeCan``).
"""

from __future__ import annotations

import argparse
import inspect
import sys
from pathlib import Path
from typing import Any

from semwm.cli.common import (
    EXIT_INVALID,
    CommandError,
    Subparsers,
    description,
    positive_float,
)
from semwm.cli.simulate_team import add_team_options, simulate_team
from semwm.knowledge.loader import UnknownFormatError, load_document
from semwm.knowledge.model import Knowledge, KnowledgeDocument
from semwm.knowledge.problems import KnowledgeError
from semwm.knowledge.resolve import resolve
from semwm.knowledge.shipped import checkout_knowledge_directory, shipped_knowledge_path
from semwm.sim.ablations import ABLATIONS, ablate
from semwm.sim.metrics import Metrics
from semwm.sim.runner import run_scenario, write_run
from semwm.sim.scenarios import SCENARIOS, Scenario, make_scenario

SIZED = [
    name for name, make in SCENARIOS.items() if "duration" in inspect.signature(make).parameters
]
"""The scenarios whose duration ``--duration`` sets."""


def format_summary(metrics: Metrics, n_detections: int) -> str:
    """The metrics as a small two-column table."""
    g = metrics.gospa
    accuracy = metrics.class_accuracy

    def pct(value: float | None) -> str:
        return "n/a" if value is None else f"{100.0 * value:.1f} %"

    rows = [
        (f"GOSPA (c={g.c:g}, p={g.p:g}, alpha=2)", f"{g.total:.3f}"),
        ("  localisation", f"{g.localisation:.3f}"),
        ("  missed", f"{g.missed:.3f}"),
        ("  false", f"{g.false:.3f}"),
        ("ID switches", str(metrics.id_switches)),
        (
            "false objects (mean/frame, total)",
            f"{metrics.false_objects.mean:.3f}, {metrics.false_objects.total}",
        ),
        (
            "missed objects (mean/frame, total)",
            f"{metrics.missed_objects.mean:.3f}, {metrics.missed_objects.total}",
        ),
        ("class accuracy (exact)", pct(accuracy.exact)),
        ("class accuracy (taxonomy)", pct(accuracy.compatible)),
        ("time per detection", f"{1e3 * metrics.time_per_detection.get('mean_s', 0.0):.3f} ms"),
        ("detections / truth frames", f"{n_detections} / {metrics.n_frames}"),
    ]
    width = max(len(name) for name, _ in rows)
    return "\n".join(f"{name:<{width}}  {value}" for name, value in rows)


def default_out(name: str, seed: int, ablations: list[str], knowledge: Path | None) -> Path:
    """``runs/NAME-seedN[-knowledge-STEM][-no-ABLATION...]``: one folder per variant."""
    parts = [f"{name}-seed{seed}"]
    if knowledge is not None:
        parts.append(f"knowledge-{knowledge.stem}")
    parts += [f"no-{ablation}" for ablation in ablations]
    return Path("runs") / "-".join(parts)


def _load(path: Path) -> KnowledgeDocument:
    """The document in ``path``; else a :class:`CommandError` with its first problem."""
    try:
        return load_document(path)
    except KnowledgeError as error:
        first, count = str(error.problems[0]), len(error.problems)
        more = f" (and {count - 1} more: semwm knowledge validate {path})" if count > 1 else ""
        raise CommandError(first + more, EXIT_INVALID) from None
    except UnknownFormatError as error:
        raise CommandError(str(error), EXIT_INVALID) from None
    except OSError as error:
        raise CommandError(f"{path}: {error.strerror or error}", EXIT_INVALID) from None


def simulate_kick(args: argparse.Namespace) -> int:
    """``semwm simulate kick``: paper 004's kick experiment (:mod:`semwm.sim.kick`)."""
    from semwm.sim.kick import MODELS, PAPER_TABLE_I, run_kick, write_kick

    path = args.knowledge or shipped_knowledge_path("robocup_kick.yaml")
    try:
        knowledge = resolve(_load(path), source=str(path))
    except KnowledgeError as error:
        raise CommandError(str(error.problems[0]), EXIT_INVALID) from None
    out = args.out or Path("runs") / f"kick-seed{args.seed}"
    if out.exists() and not out.is_dir():
        raise CommandError(f"--out {out}: exists and is not a folder")
    result = run_kick(knowledge, seed=args.seed, trials=args.trials)
    write_kick(result, out, str(path))
    summary = result.summary()
    print(f"kick (seed {args.seed}, {args.trials} trials), knowledge {path}: wrote {out}")
    print(f"{'world model':<12}  {'time to see (s)':>16}  {'paper 004 Table I':>18}")
    for model in MODELS:
        row = summary[model]
        mean, std = PAPER_TABLE_I[model]
        never = f"  ({row['never_seen']} never seen)" if row["never_seen"] else ""
        print(
            f"{model:<12}  {row['mean']:>8.2f} ± {row['std']:<5.2f}  {mean:>10.2f} ± {std:<5.2f}"
            + never
        )
    return 0


def scenario_knowledge(scenario: Scenario) -> Path:
    """The knowledge file ``scenario`` is meant for: a shipped one, or one of a folder
    of the repository (``metadata["knowledge_dir"]``, e.g. ``benchmarks/knowledge``
    for the datasheet-only files of ``datasheet`` and ``patrol``), looked for in the
    semwm checkout around the current directory, then next to this source."""
    folder = scenario.metadata.get("knowledge_dir")
    if folder is None:
        return shipped_knowledge_path(scenario.knowledge_file)
    roots = [Path(__file__).resolve().parents[2]]
    checkout = checkout_knowledge_directory()
    if checkout is not None:
        roots.insert(0, checkout.parent)
    for root in roots:
        path = root / str(folder) / scenario.knowledge_file
        if path.is_file():
            return path
    raise CommandError(
        f"scenario {scenario.name} runs on {folder}/{scenario.knowledge_file} of a semwm "
        "checkout, which the installed package does not carry: run it inside a checkout, "
        "or give --knowledge FILE"
    )


def _check_fits(scenario: Scenario, knowledge: Knowledge, path: Path) -> None:
    """A :class:`CommandError` (one line) when the scenario detects a class or uses a
    detector that ``knowledge`` lacks, or has another dimension: before the run,
    instead of the world model refusing the first scan."""
    classes = sorted({d.cls for d in scenario.detections} - set(knowledge.classes))
    detectors = sorted(
        {d.detector or knowledge.default_detector for d in scenario.detections}
        - set(knowledge.detectors)
    )
    missing = [f"class {name!r}" for name in classes]
    missing += [f"detector {name!r}" for name in detectors]
    if missing:
        raise CommandError(
            f"{path} has no {', '.join(missing)} that scenario {scenario.name} detects; "
            "add them, or run without --knowledge (the scenario's own knowledge)",
            EXIT_INVALID,
        )
    dimension = len(scenario.region)
    if knowledge.world.dimension != dimension:
        raise CommandError(
            f"{path} is {knowledge.world.dimension}-D; scenario {scenario.name} is {dimension}-D",
            EXIT_INVALID,
        )


def simulate(args: argparse.Namespace) -> int:
    """Run ``semwm simulate``; returns the exit status."""
    if args.name == "kick":
        return simulate_kick(args)
    sizes: dict[str, Any] = {}
    if args.duration is not None:
        if args.name == "sim2":
            print(
                "semwm simulate: sim2's duration is set by the person's walk; --duration ignored",
                file=sys.stderr,
            )
        elif args.name not in SIZED:
            print(
                f"semwm simulate: {args.name} has a fixed duration; --duration ignored",
                file=sys.stderr,
            )
        else:
            sizes["duration"] = args.duration
    scenario = make_scenario(args.name, args.seed, **sizes)
    path = args.knowledge or scenario_knowledge(scenario)
    ablations = list(dict.fromkeys(args.no_knowledge))  # each once, in the order given
    document = ablate(_load(path), ablations)
    try:
        knowledge = resolve(document, source=str(path))
    except KnowledgeError as error:
        raise CommandError(str(error.problems[0]), EXIT_INVALID) from None
    _check_fits(scenario, knowledge, path)
    out = args.out or default_out(args.name, args.seed, ablations, args.knowledge)
    if out.exists() and not out.is_dir():
        raise CommandError(f"--out {out}: exists and is not a folder")
    if args.levels is not None:  # the team run (semwm/cli/simulate_team.py)
        result = simulate_team(args, scenario, knowledge, out, ablations)
    else:
        result = run_scenario(scenario, knowledge, progress=not args.no_progress)
        write_run(result, out, ablations=ablations)
    ablated = f" without {', '.join(ablations)}" if ablations else ""
    print(f"{args.name} (seed {args.seed}){ablated}, knowledge {path}: wrote {out}")
    print(format_summary(result.metrics, result.n_detections))
    for report in getattr(result, "rates", ()):
        for warning in report.warnings:
            print(f"warning: source {report.source!r}: {warning}", file=sys.stderr)
    return 0


def add_simulate_command(subparsers: Subparsers) -> argparse.ArgumentParser:
    """Add ``simulate`` to the ``semwm`` command line's sub-parsers."""
    parser: argparse.ArgumentParser = subparsers.add_parser(
        "simulate",
        help="run a simulated scenario through the world model and report metrics",
        description=description(__doc__),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument(
        "name",
        metavar="NAME",
        choices=sorted([*SCENARIOS, "kick"]),
        help="scenario: "
        + ", ".join(sorted([*SCENARIOS, "kick"]))
        + " (kick: paper 004's closed-loop kick experiment)",
    )
    parser.add_argument(
        "--trials",
        type=int,
        default=20,
        metavar="K",
        help="kick: trials per world model (default 20)",
    )
    parser.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    parser.add_argument(
        "--knowledge",
        type=Path,
        default=None,
        metavar="FILE",
        help="knowledge file (XML or YAML; default: the scenario's shipped file)",
    )
    parser.add_argument(
        "--out",
        type=Path,
        default=None,
        metavar="DIR",
        help="output folder (default runs/NAME-seedN, plus -knowledge-STEM, -no-ABLATION)",
    )
    parser.add_argument(
        "--no-knowledge",
        action="append",
        default=[],
        choices=sorted(ABLATIONS),
        metavar="NAME",
        help="remove a piece of knowledge (repeatable): " + ", ".join(sorted(ABLATIONS)),
    )
    parser.add_argument(
        "--duration",
        type=positive_float,
        default=None,
        metavar="SECONDS",
        help=f"scenario duration in s ({', '.join(SIZED)})",
    )
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    add_team_options(parser)
    parser.set_defaults(func=simulate)
    return parser
