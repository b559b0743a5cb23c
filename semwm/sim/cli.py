"""``semwm simulate NAME``: run a scenario through the world model, print and write metrics.

Knowledge ablations (``--no-knowledge``) change the scenario's shipped knowledge
before the run, to measure what a piece of knowledge is worth:

* ``door-relation``: remove every class's appearance relations (paper 002 eq. 4;
  in ``sim2`` "a Person appears near a Door"), leaving the base rates;
* ``taxonomy``: remove every is-a relation, each class keeping the settings it
  inherited (paper 002 eq. 8: ``Can`` then no longer matches ``CokeCan``).
"""

from __future__ import annotations

import argparse
from collections.abc import Callable
from pathlib import Path
from typing import Any

from semwm.knowledge.loader import load_document
from semwm.knowledge.model import ClassSpec, KnowledgeDocument
from semwm.knowledge.resolve import resolve
from semwm.knowledge.shipped import shipped_knowledge_path
from semwm.sim.metrics import Metrics
from semwm.sim.runner import run_scenario, write_run
from semwm.sim.scenarios import SCENARIOS, make_scenario


def without_appearance_relations(document: KnowledgeDocument) -> KnowledgeDocument:
    """``document`` with no appearance relations: every class's new objects appear
    at its base rate (``new_frequency``) everywhere.

    Each class gets an explicit empty tuple, so none inherits a parent's relations.
    """
    classes = tuple(spec.model_copy(update={"appearance": ()}) for spec in document.classes)
    return document.model_copy(update={"classes": classes})


def without_taxonomy(document: KnowledgeDocument) -> KnowledgeDocument:
    """``document`` with no is-a relations; each class keeps every setting it
    inherited (resolved first, then written out in full)."""
    knowledge = resolve(document)
    classes = []
    for spec in document.classes:
        resolved = knowledge.classes[spec.name]
        classes.append(
            ClassSpec(
                name=spec.name,
                is_a=(),
                detection_frequency=resolved.detection_frequency,
                new_frequency=resolved.new_frequency,
                appearance=resolved.appearance,
                filter=resolved.filter,
                measurement_noise=resolved.measurement_noise,
                initial_covariance=resolved.initial_covariance,
                initial_velocity_covariance=resolved.initial_velocity_covariance,
                max_position_variance=resolved.max_position_variance,
                max_time_without_update=resolved.max_time_without_update,
                category=resolved.category,
            )
        )
    return document.model_copy(update={"classes": tuple(classes)})


ABLATIONS: dict[str, Callable[[KnowledgeDocument], KnowledgeDocument]] = {
    "door-relation": without_appearance_relations,
    "taxonomy": without_taxonomy,
}


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


def simulate(args: argparse.Namespace) -> int:
    """Run ``semwm simulate``; returns the exit status."""
    sizes: dict[str, Any] = {}
    if args.duration is not None:
        if args.name == "sim2":
            print("semwm simulate: sim2's duration is set by the person's walk; --duration ignored")
        else:
            sizes["duration"] = args.duration
    scenario = make_scenario(args.name, args.seed, **sizes)
    document = load_document(shipped_knowledge_path(scenario.knowledge_file))
    for ablation in args.no_knowledge:
        document = ABLATIONS[ablation](document)
    knowledge = resolve(document, source=scenario.knowledge_file)
    result = run_scenario(scenario, knowledge, progress=not args.no_progress)
    out = Path(args.out) if args.out else Path("runs") / f"{args.name}-seed{args.seed}"
    write_run(result, out)
    ablated = f" without {', '.join(args.no_knowledge)}" if args.no_knowledge else ""
    print(f"{args.name} (seed {args.seed}){ablated}: wrote {out}")
    print(format_summary(result.metrics, result.n_detections))
    return 0


def add_simulate_command(subparsers: Any) -> argparse.ArgumentParser:
    """Add ``simulate`` to the ``semwm`` command line's sub-parsers."""
    parser: argparse.ArgumentParser = subparsers.add_parser(
        "simulate",
        help="run a simulated scenario through the world model and report metrics",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument(
        "name",
        metavar="NAME",
        choices=sorted(SCENARIOS),
        help="scenario: " + ", ".join(sorted(SCENARIOS)),
    )
    parser.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    parser.add_argument("--out", default=None, help="output directory (default runs/NAME-seedN)")
    parser.add_argument(
        "--no-knowledge",
        action="append",
        default=[],
        choices=sorted(ABLATIONS),
        metavar="NAME",
        help="remove a piece of knowledge: " + ", ".join(sorted(ABLATIONS)),
    )
    parser.add_argument("--duration", type=float, default=None, help="scenario duration (s)")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    parser.set_defaults(func=simulate)
    return parser
