"""Run a scenario through the world model, measure it, and write the run to disk.

:func:`run_scenario` feeds the scenario's detections scan by scan (one scan =
equal ``(time, source)``) into :meth:`WorldModel.ingest`, queries
:meth:`WorldModel.world` at every truth time, times the ingest calls only, and
computes the metrics of :mod:`semwm.sim.metrics`. :func:`write_run` writes the
files ``semwm simulate`` promises: ``detections.jsonl``, ``truth.jsonl``,
``world.jsonl``, ``metrics.json`` and ``plot.png``.
"""

from __future__ import annotations

import json
import time as clock
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, replace
from itertools import groupby
from pathlib import Path
from typing import Any, Protocol

import numpy as np
from tqdm import tqdm

from semwm.detection import Detection
from semwm.knowledge.model import Knowledge
from semwm.knowledge.taxonomy import Taxonomy
from semwm.mhf.rates import StreamReport
from semwm.sim.metrics import Metrics, Point, compute_metrics, unobserved_floor
from semwm.sim.scenarios import Scenario, TruthFrame
from semwm.world_types import WorldObject, WorldState


class WorldModelLike(Protocol):
    """What the runner needs of a world model (``semwm.WorldModel`` has it)."""

    def ingest(self, detections: Sequence[Detection]) -> Any: ...

    def world(self, time: float | None = None) -> WorldState: ...


WorldModelFactory = Callable[[Knowledge], WorldModelLike]


def default_world_model(knowledge: Knowledge) -> WorldModelLike:
    """``semwm.WorldModel(knowledge, reorder_window=0.0)``."""
    from semwm.world import WorldModel

    model: WorldModelLike = WorldModel(knowledge, reorder_window=0.0)
    return model


@dataclass(frozen=True)
class RunResult:
    """A finished run: the scenario, the world at every truth time, the metrics.

    ``scan_seconds[i]`` and ``scan_sizes[i]``: wall time of the i-th ingest call
    and the number of detections it carried.
    """

    scenario: Scenario
    knowledge: Knowledge
    worlds: list[WorldState]
    metrics: Metrics
    scan_seconds: list[float]
    scan_sizes: list[int]
    rates: tuple[StreamReport, ...] = ()
    """Per source and detector, the clutter and detection rates the data showed beside
    the knowledge's (:meth:`semwm.WorldModel.rate_report`; empty for a model without)."""

    @property
    def n_detections(self) -> int:
        return len(self.scenario.detections)


def scans(detections: Sequence[Detection]) -> Iterator[list[Detection]]:
    """Consecutive detections with equal ``(time, source)``: one scan each.

    ``detections`` must be sorted by time (scenarios are).
    """
    for _, group in groupby(detections, key=lambda d: (d.time, d.source)):
        yield list(group)


def taxonomy_of(knowledge: Knowledge) -> Taxonomy:
    """The is-a taxonomy of resolved knowledge."""
    return Taxonomy({name: c.parents for name, c in knowledge.classes.items()})


def truth_points(frame: TruthFrame) -> list[Point]:
    return [Point(o.id, o.cls, o.position) for o in frame.objects]


def world_points(state: WorldState) -> list[Point]:
    return [Point(o.id, o.cls, o.position) for o in state.objects]


def _timing(seconds: Sequence[float], sizes: Sequence[int]) -> dict[str, float]:
    total = float(sum(seconds))
    count = int(sum(sizes))
    per = np.asarray(seconds) / np.maximum(np.asarray(sizes), 1) if seconds else np.zeros(1)
    return {
        "mean_s": total / count if count else 0.0,
        "median_scan_s": float(np.median(per)),
        "p95_scan_s": float(np.percentile(per, 95)),
        "max_scan_s": float(np.max(per)),
        "total_ingest_s": total,
    }


def run_scenario(
    scenario: Scenario,
    knowledge: Knowledge,
    *,
    progress: bool = True,
    world_model_factory: WorldModelFactory | None = None,
    gospa_c: float | None = None,
    gospa_p: float = 1.0,
) -> RunResult:
    """Feed ``scenario`` into a fresh world model and evaluate it at every truth time.

    Scans with a time at or before a truth time are ingested before the world is
    queried at that time. Only the ``ingest`` calls are timed
    (:func:`time.perf_counter`). ``gospa_c`` defaults to the scenario's
    ``metadata["gospa_c"]`` (else 1 m).
    """
    factory = world_model_factory or default_world_model
    model = factory(knowledge)
    all_scans = list(scans(scenario.detections))
    seconds: list[float] = []
    sizes: list[int] = []
    worlds: list[WorldState] = []
    next_scan = 0
    with tqdm(
        total=len(scenario.detections),
        disable=not progress,
        desc=scenario.name,
        unit="det",
        leave=False,
    ) as bar:
        for frame in scenario.truth:
            while next_scan < len(all_scans) and all_scans[next_scan][0].time <= frame.time:
                scan = all_scans[next_scan]
                start = clock.perf_counter()
                model.ingest(scan)
                seconds.append(clock.perf_counter() - start)
                sizes.append(len(scan))
                bar.update(len(scan))
                next_scan += 1
            worlds.append(model.world(time=frame.time))
    c = gospa_c if gospa_c is not None else scenario_gospa_c(scenario)
    metrics = compute_metrics(
        [truth_points(f) for f in scenario.truth],
        [world_points(w) for w in worlds],
        c=c,
        p=gospa_p,
        compatible=taxonomy_of(knowledge).compatible,
    )
    metrics = replace(metrics, time_per_detection=_timing(seconds, sizes))
    report = getattr(model, "rate_report", None)
    rates = tuple(report()) if callable(report) else ()
    return RunResult(scenario, knowledge, worlds, metrics, seconds, sizes, rates)


def scenario_gospa_c(scenario: Scenario) -> float:
    """The scenario's GOSPA cut-off ``metadata["gospa_c"]`` (m), else 1 m."""
    return float(str(scenario.metadata.get("gospa_c", 1.0)))


def scenario_floor(scenario: Scenario, gospa_c: float | None = None, gospa_p: float = 1.0) -> float:
    """:func:`semwm.sim.metrics.unobserved_floor` of a scenario: the mean GOSPA (scored as
    :func:`run_scenario` scores) that no tracker can avoid on its detections."""
    return unobserved_floor(
        [(f.time, truth_points(f)) for f in scenario.truth],
        [(d.time, d.position) for d in scenario.detections],
        c=gospa_c if gospa_c is not None else scenario_gospa_c(scenario),
        p=gospa_p,
    )


def metrics_document(result: RunResult, ablations: Sequence[str] = ()) -> dict[str, object]:
    """What ``metrics.json`` holds: the run's settings (scenario, seed, knowledge
    file, the knowledge ablations applied to it) and its metrics."""
    scenario = result.scenario
    return {
        "scenario": scenario.name,
        "seed": scenario.seed,
        "knowledge": result.knowledge.source or scenario.knowledge_file,
        "ablations": list(ablations),
        "duration": scenario.duration,
        "n_detections": result.n_detections,
        "n_scans": len(result.scan_sizes),
        **result.metrics.to_dict(),
    }


def _object_dict(obj: WorldObject) -> dict[str, object]:
    return obj.to_dict()


def write_run(result: RunResult, out_dir: str | Path, *, ablations: Sequence[str] = ()) -> Path:
    """Write the run's files into ``out_dir`` (created if needed); returns it.

    ``ablations``: the names of the knowledge ablations the run's knowledge had
    (recorded in ``metrics.json``).
    """
    from semwm.sim.plot import plot_run  # matplotlib only when a run is written

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    with (out / "detections.jsonl").open("w", encoding="utf-8") as f:
        for detection in result.scenario.detections:
            f.write(json.dumps(detection.to_dict()) + "\n")
    with (out / "truth.jsonl").open("w", encoding="utf-8") as f:
        for frame in result.scenario.truth:
            f.write(json.dumps(frame.to_dict()) + "\n")
    with (out / "world.jsonl").open("w", encoding="utf-8") as f:
        for frame, state in zip(result.scenario.truth, result.worlds, strict=True):
            objects = [_object_dict(o) for o in state.objects]
            f.write(json.dumps({"time": frame.time, "objects": objects}) + "\n")
    document = metrics_document(result, ablations)
    document["rates"] = [{"source": r.source, **r.to_dict()} for r in result.rates]
    (out / "metrics.json").write_text(json.dumps(document, indent=2) + "\n", encoding="utf-8")
    plot_run(result.scenario, result.worlds, result.metrics, out / "plot.png")
    return out
