"""The Python engine and the Rust engine side by side (issue 29), in one run.

For each case, both engines run the same scans in the same process, interleaved
(python, rust, python, rust, ...) so that both see the same load on a shared machine:

* the static grid (``bench_scaling``'s scenario) of N = 50 and N = 1,000 objects: CPU
  ms per frame and µs per detection over the steady frames after a warm-up (mean
  of the timed frames, best of ``--repeats`` runs);
* sim2 and robocup (2 s), seed 0: CPU µs per detection and per scan of the whole run
  (best of the repeats);
* a robot that reads the world as it reports: sim2, robocup (2 s) and robocup under
  the ``paper`` association model, the world asked for after each scan at its time:
  CPU µs per detection of the ingest calls and µs per ``world()`` call (best of the
  repeats);
* paper 004's negative information: leftbehind (200 s) with its sensor views beside
  the same scans without them, CPU µs per detection and per call (best of the repeats);
* the kernels alone: one ``ClassFilter.predict`` and one ``update`` of N objects
  (robocup.yaml's ``Robot``, a 2-mode IMM with a transition period, 2-D) for N = 1,
  10, 100, 1,000: µs per call (best of ``--repeats`` loops), what crossing to Rust
  costs and gains per call;
* the existence and coverage kernels alone (``semwm.mhf.kernels``): the region's and
  the view's probability, ``survive`` and the hull distance, N = 1 to 1,000, µs per call;
* within those runs, the CPU time of the expansion of each scan (step 5 of
  ``semwm.mhf.filter``, ``_expand_scan``: in Rust with the Rust engine), µs per scan;
* the share of the CPU time spent in the filters (``ClassFilter.predict``/``update``/
  ``combine`` and the factory's ``update``, ``combine`` and gate) and in the existence
  step (``existence_at``, ``leaving``, ``undetected``), cumulative, from one cProfile
  run of robocup per engine;
* parity: every frame of sim1, sim2 and robocup (2 s) over ``--seeds`` seeds with both
  engines: ids, classes and labels equal, and the largest difference of any published
  number (positions, velocities, covariances, existence, mode and class probabilities).

Writes ``engines.json`` and ``engines.md`` to ``benchmarks/out/``
(``benchmarks/results/`` with ``--update-results``).

    python benchmarks/bench_engines.py [--quick] [--repeats R] [--seeds S] [--update-results]

``--parity-seeds N`` (N = 20 when no number is given) runs the parity check of issue 29
alone, and only it: every scenario of ``semwm.sim.scenarios.SCENARIOS`` (sizes in
:data:`PARITY_CASES`), the kick trials of ``semwm.sim.kick`` and robocup under the
``paper`` association model, each over seeds 0 to N - 1, with both engines in step
(:class:`Lockstep`: every call the same answer or the same exception; after each the
published world, ``world(min_existence=1e-6)``, the hypothesis count and the 20 best
hypotheses' probabilities; every 10 calls the world half the reorder window back, now
and 0.5 s ahead). Per scenario it writes the frames and objects compared, whether ids,
classes, labels, confidence states and counts were equal everywhere, and the largest
difference of any published number to ``engines_parity.json`` and ``.md``
(``engines_parity_quick.*`` with ``--quick``: 2 seeds).

    python benchmarks/bench_engines.py --parity-seeds [N] [--quick] [--update-results]
"""

from __future__ import annotations

import argparse
import cProfile
import math
import pstats
import sys
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any
from unittest import mock

from tqdm import tqdm

sys.path.insert(0, str(Path(__file__).resolve().parent))

from baselines import BENCHMARKS, RESULTS, add_output_arguments, fmt, machine_info, write_results

from semwm.detection import BeforeHistoryError, Detection
from semwm.filters.engine import ENGINES, Engine, engine_description, rust_core
from semwm.knowledge.loader import load_knowledge
from semwm.knowledge.model import Knowledge
from semwm.knowledge.shipped import shipped_knowledge_path
from semwm.sim import kick
from semwm.sim.leftbehind import SensorViews
from semwm.sim.runner import scans
from semwm.sim.scenarios import SCENARIOS as SCENARIO_GENERATORS
from semwm.sim.scenarios import Scenario, make_scenario
from semwm.world import WorldModel
from semwm.world_types import WorldObject, WorldState

Scan = list[Detection]
SCENARIOS: dict[str, dict[str, Any]] = {"sim2": {}, "robocup": {"duration": 2.0}}
PARITY_SCENARIOS: dict[str, dict[str, Any]] = {"sim1": {}, **SCENARIOS}
GRID_SIZES = (50, 1000)
WARMUP, TIMED = 20, 30
FILTER_FUNCTIONS = {
    ("factory.py", "predict"),
    ("factory.py", "update"),
    ("factory.py", "combine"),
    ("factory.py", "mahalanobis_squared"),
}
"""The entry points of the filters, in Rust (semwm/filters/factory.py)."""
EXISTENCE_FUNCTIONS = {
    ("filter.py", "existence_at"),
    ("filter.py", "leaving"),
    ("filter.py", "undetected"),
}
"""The existence and missed-detection step of a scan (semwm/mhf/filter.py): its kernels
(survive, missed, the region and view probabilities, coverage) are in Rust, the glue
around them (per-object rates and margins, dicts of existence) and the re-weighting of
hypotheses are Python."""


def _with_region(knowledge: Knowledge, region: Any) -> Knowledge:
    world = knowledge.world.model_copy(update={"region": tuple(tuple(r) for r in region)})
    return knowledge.model_copy(update={"world": world})


def _case(name: str, sizes: dict[str, Any], seed: int = 0) -> tuple[Knowledge, list[Scan]]:
    scenario = make_scenario(name, seed, **sizes)
    knowledge = load_knowledge(shipped_knowledge_path(scenario.knowledge_file))
    if name == "grid":
        knowledge = _with_region(knowledge, scenario.region)
    return knowledge, list(scans(scenario.detections))


def _cpu_per_scan(
    knowledge: Knowledge, all_scans: list[Scan], engine: Engine
) -> tuple[list[float], list[float]]:
    """CPU seconds of each ingest call, one fresh world model, and of the expansion of
    its scan within it (step 5 of semwm.mhf.filter, ``_expand_scan``)."""
    model = WorldModel(knowledge, reorder_window=0.0, engine=engine)
    mhf = model._mhf
    expand = mhf._expand_scan
    inside = [0.0]

    def timed(*args: Any) -> Any:
        start = time.process_time()
        try:
            return expand(*args)
        finally:
            inside[0] += time.process_time() - start

    setattr(mhf, "_expand_scan", timed)  # noqa: B010 (mypy: no assignment to a method)
    spent, expanding = [], []
    for scan in all_scans:
        inside[0] = 0.0
        start = time.process_time()
        model.ingest(scan)
        spent.append(time.process_time() - start)
        expanding.append(inside[0])
    return spent, expanding


def _interleaved(
    repeats: int, measure: Callable[[Engine], float], engines: tuple[Engine, ...]
) -> dict[str, float]:
    """The best (smallest) of ``repeats`` measures per engine, run in turn."""
    best: dict[str, float] = {engine: float("inf") for engine in engines}
    for _ in range(repeats):
        for engine in engines:
            best[engine] = min(best[engine], measure(engine))
    return best


def grid(n: int, repeats: int, engines: tuple[Engine, ...]) -> dict[str, Any]:
    frames = WARMUP + TIMED
    knowledge, all_scans = _case("grid", {"n_objects": n, "duration": (frames - 1) / 10.0})

    expansion: dict[str, float] = {}

    def steady_ms(engine: Engine) -> float:
        spent, expanding = _cpu_per_scan(knowledge, all_scans, engine)
        ms = 1e3 * sum(spent[WARMUP : WARMUP + TIMED]) / TIMED
        if ms <= per_frame_best.get(engine, math.inf):
            per_frame_best[engine] = ms
            expansion[engine] = 1e6 * sum(expanding[WARMUP : WARMUP + TIMED]) / TIMED
        return ms

    per_frame_best: dict[str, float] = {}
    per_frame = _interleaved(repeats, steady_ms, engines)
    detections = sum(len(scan) for scan in all_scans[WARMUP : WARMUP + TIMED]) / TIMED
    return {
        "case": f"grid N = {n}",
        "detections_per_frame": detections,
        **{
            engine: {
                "ms_per_frame": ms,
                "us_per_detection": 1e3 * ms / detections,
                "expansion_us_per_scan": expansion[engine],
            }
            for engine, ms in per_frame.items()
        },
    }


def scenario(name: str, repeats: int, engines: tuple[Engine, ...]) -> dict[str, Any]:
    knowledge, all_scans = _case(name, SCENARIOS[name])
    detections = sum(len(scan) for scan in all_scans)
    expansion: dict[str, float] = {}
    best: dict[str, float] = {}

    def seconds(engine: Engine) -> float:
        spent, expanding = _cpu_per_scan(knowledge, all_scans, engine)
        if sum(spent) <= best.get(engine, math.inf):
            best[engine] = sum(spent)
            expansion[engine] = 1e6 * sum(expanding) / len(all_scans)
        return sum(spent)

    total = _interleaved(repeats, seconds, engines)
    label = name + (f" {SCENARIOS[name]['duration']:g} s" if SCENARIOS[name] else "")
    return {
        "case": label,
        "detections": detections,
        "scans": len(all_scans),
        **{
            engine: {
                "ms_per_frame": 1e3 * seconds / len(all_scans),
                "us_per_detection": 1e6 * seconds / detections,
                "expansion_us_per_scan": expansion[engine],
            }
            for engine, seconds in total.items()
        },
    }


QUERY_CASES: tuple[tuple[str, str, dict[str, Any], str | None], ...] = (
    ("sim2", "sim2", {}, None),
    ("robocup 2 s", "robocup", {"duration": 2.0}, None),
    ("robocup 2 s, paper", "robocup", {"duration": 2.0}, "paper"),
)
"""(label, scenario, sizes, association model or None for the knowledge's) of
:func:`queries`."""


def queries(repeats: int, engines: tuple[Engine, ...]) -> list[dict[str, Any]]:
    """A robot that reads the world as it reports: each case's scans (seed 0) ingested
    into a fresh world model (default options), the world asked for at each scan's time
    after it. CPU µs per detection of the ingest calls and µs per ``world()`` call,
    each the best of ``repeats`` runs, the engines in turn."""
    rows = []
    for label, name, sizes, model in QUERY_CASES:
        scenario = make_scenario(name, 0, **sizes)
        knowledge = _scenario_knowledge(scenario, model)
        all_scans = list(scans(scenario.detections))
        detections = sum(len(scan) for scan in all_scans)
        best: dict[str, dict[str, float]] = {}
        for _ in range(repeats):
            for engine in engines:
                world_model = WorldModel(knowledge, engine=engine)
                ingest = asked = 0.0
                objects = 0
                for scan in all_scans:
                    start = time.process_time()
                    world_model.ingest(scan)
                    middle = time.process_time()
                    objects += len(world_model.world(scan[0].time).objects)
                    asked += time.process_time() - middle
                    ingest += middle - start
                was = best.setdefault(engine, {"ingest": math.inf, "query": math.inf})
                was["ingest"] = min(was["ingest"], ingest)
                was["query"] = min(was["query"], asked)
                was["objects_per_query"] = objects / len(all_scans)
        rows.append(
            {
                "case": label,
                "detections": detections,
                "queries": len(all_scans),
                **{
                    engine: {
                        "ingest_us_per_detection": 1e6 * b["ingest"] / detections,
                        "us_per_query": 1e6 * b["query"] / len(all_scans),
                        "objects_per_query": b["objects_per_query"],
                    }
                    for engine, b in best.items()
                },
            }
        )
    return rows


class _Counted:
    """A world model whose ``ingest`` calls are counted."""

    def __init__(self, model: WorldModel) -> None:
        self.model = model
        self.calls = 0

    def ingest(self, *args: Any, **kwargs: Any) -> Any:
        self.calls += 1
        return self.model.ingest(*args, **kwargs)


def views(repeats: int, engines: tuple[Engine, ...]) -> dict[str, Any]:
    """Paper 004's negative information: leftbehind (200 s, seed 0) with its robot's and
    its fixed camera's sensor views (``SensorViews``: each scan with its sensor report,
    the empty ones posted too), beside the same scans without them. CPU µs per detection
    and per ``ingest`` call, the best of ``repeats`` runs, the engines in turn."""
    scenario = make_scenario("leftbehind", 0, poses=True)
    knowledge = _scenario_knowledge(scenario, None)
    all_scans = list(scans(scenario.detections))
    detections = sum(len(scan) for scan in all_scans)
    best: dict[str, dict[str, float]] = {}
    calls: dict[bool, int] = {}
    for _ in range(repeats):
        for engine in engines:
            for with_views in (False, True):
                model = _Counted(WorldModel(knowledge, engine=engine, reorder_window=0.0))
                feed: Any = SensorViews(model, scenario) if with_views else model
                start = time.process_time()
                for scan in all_scans:
                    feed.ingest(scan)
                spent = time.process_time() - start
                key = "views" if with_views else "plain"
                row = best.setdefault(engine, {})
                row[key] = min(row.get(key, math.inf), spent)
                calls[with_views] = model.calls
    return {
        "case": "leftbehind 200 s",
        "detections": detections,
        "calls": {"plain": calls[False], "views": calls[True]},
        **{
            engine: {
                key: {
                    "us_per_detection": 1e6 * seconds / detections,
                    "us_per_call": 1e6 * seconds / calls[key == "views"],
                }
                for key, seconds in row.items()
            }
            for engine, row in best.items()
        },
    }


KERNEL_SIZES = (1, 10, 100, 1000)


def kernels(repeats: int, engines: tuple[Engine, ...]) -> list[dict[str, Any]]:
    """µs per predict and per update call of N IMM objects, each engine."""
    import numpy as np

    from semwm.filters.factory import FilterFactory

    knowledge = load_knowledge(shipped_knowledge_path("robocup.yaml"))
    rows = []
    for n in KERNEL_SIZES:
        rng = np.random.default_rng(n)
        row: dict[str, Any] = {"n": n}
        for engine in engines:
            flt = FilterFactory(knowledge, engine).filter_for("Robot")
            x, P, mu = flt.initial_states(rng.normal(size=(n, flt.dim)))
            dt = rng.uniform(0.01, 0.2, size=n)
            z = rng.normal(size=(n, flt.dim))
            R = np.repeat(np.eye(flt.dim)[None] * 0.01, n, axis=0)
            loops = max(3, 3000 // n)

            def per_call(call: Callable[[], object], loops: int = loops) -> float:
                best = float("inf")
                for _ in range(repeats):
                    start = time.perf_counter()
                    for _ in range(loops):
                        call()
                    best = min(best, (time.perf_counter() - start) / loops)
                return 1e6 * best

            xp, Pp, mup = flt.predict(x, P, mu, dt)
            row[engine] = {
                "predict_us": per_call(lambda: flt.predict(x, P, mu, dt)),  # noqa: B023
                "update_us": per_call(lambda: flt.update(xp, Pp, mup, z, R)),  # noqa: B023
            }
        rows.append(row)
    return rows


def existence_kernels(repeats: int, engines: tuple[Engine, ...]) -> list[dict[str, Any]]:
    """µs per call of the existence and coverage kernels on N objects, each engine: the
    region's inside probability (2-D, with margins), the view's (7 x 7 Gauss-Hermite),
    ``survive`` and the hull distance to 12 detections."""
    import numpy as np

    from semwm.mhf.kernels import existence_kernels as choose
    from semwm.mhf.measurement import SensorView

    rows = []
    for n in KERNEL_SIZES:
        rng = np.random.default_rng(n)
        position = rng.uniform(-5.0, 5.0, size=(n, 2))
        A = rng.normal(size=(n, 2, 2)) * 0.3
        covariance = A @ np.swapaxes(A, -1, -2) + 0.01 * np.eye(2)
        margin = np.full((n, 2), 0.1)
        region = ((-4.0, 4.0), (-4.0, 4.0))
        view = SensorView(0.0, None, np.zeros(2), 0.3, 4.0, 0.8)
        r, mu, f = rng.uniform(size=n), np.full(n, 0.1), np.full(n, 2.0)
        corners = rng.uniform(-3.0, 3.0, size=(12, 2))
        loops = max(3, 3000 // n)
        row: dict[str, Any] = {"n": n}
        for engine in engines:
            k = choose(engine)

            def per_call(call: Callable[[], object], loops: int = loops) -> float:
                best = float("inf")
                for _ in range(repeats):
                    start = time.perf_counter()
                    for _ in range(loops):
                        call()
                    best = min(best, (time.perf_counter() - start) / loops)
                return 1e6 * best

            row[engine] = {
                "inside_us": per_call(
                    lambda: k.inside_probability(position, covariance, region, margin)  # noqa: B023
                ),
                "in_view_us": per_call(
                    lambda: k.in_view_probability(position, covariance, view, None)  # noqa: B023
                ),
                "survive_us": per_call(lambda: k.survive(r, mu, f, 0.1)),  # noqa: B023
                "hull_us": per_call(lambda: k.hull_distance(position, corners)),  # noqa: B023
            }
        rows.append(row)
    return rows


def filter_share(engines: tuple[Engine, ...]) -> dict[str, Any]:
    """Share of robocup's ingest CPU time inside the filter entry points (cProfile)."""
    knowledge, all_scans = _case("robocup", SCENARIOS["robocup"])
    shares: dict[str, Any] = {}
    for engine in engines:
        model = WorldModel(knowledge, reorder_window=0.0, engine=engine)
        profile = cProfile.Profile()
        profile.enable()
        for scan in all_scans:
            model.ingest(scan)
        profile.disable()
        stats: dict[Any, Any] = pstats.Stats(profile).stats  # type: ignore[attr-defined]
        total = sum(own for (_, _, own, _, _) in stats.values())
        inside = sum(
            cumulative
            for (file, _, function), (_, _, _, cumulative, _) in stats.items()
            if (Path(file).name, function) in FILTER_FUNCTIONS and "filters" in file
        )
        calls = sum(
            primitive
            for (file, _, function), (primitive, _, _, _, _) in stats.items()
            if (Path(file).name, function) in FILTER_FUNCTIONS and "filters" in file
        )
        existence = sum(
            cumulative
            for (file, _, function), (_, _, _, cumulative, _) in stats.items()
            if (Path(file).name, function) in EXISTENCE_FUNCTIONS and "mhf" in file
        )
        shares[engine] = {
            "filters_share": inside / total,
            "filter_calls": calls,
            "existence_share": existence / total,
        }
    return shares


def _numbers(obj: WorldObject) -> list[float]:
    """Every number a published object has: position, velocity, covariance, existence,
    last seen and created, mode and class probabilities, confidence."""
    values = [*obj.position, *(obj.velocity or ()), *sum(obj.covariance, ()), obj.existence]
    values += [obj.last_seen, obj.created]
    values += [*(obj.mode_probabilities or {}).values()]
    values += [*(obj.class_probabilities or {}).values()]
    values += [] if obj.confidence is None else [obj.confidence.value]
    return values


def _keys(obj: WorldObject) -> tuple[Any, ...]:
    """What must be equal: id, class, label, the modes and classes named, the confidence
    state, whether it is tentative."""
    return (
        obj.id,
        obj.cls,
        obj.label,
        tuple(obj.mode_probabilities or ()),
        tuple(obj.class_probabilities or ()),
        None if obj.confidence is None else obj.confidence.state,
        obj.tentative,
    )


def parity(seeds: int) -> dict[str, Any]:
    """Frame by frame, both engines, every parity scenario and seed."""
    result: dict[str, Any] = {}
    for name, sizes in PARITY_SCENARIOS.items():
        largest, frames, mismatched = 0.0, 0, 0
        for seed in range(seeds):
            knowledge, all_scans = _case(name, sizes, seed)
            python = WorldModel(knowledge, engine="python")
            rust = WorldModel(knowledge, engine="rust")
            for scan in all_scans:
                python.ingest(scan)
                rust.ingest(scan)
                expected = python.world(min_existence=1e-6).objects
                got = rust.world(min_existence=1e-6).objects
                frames += 1
                if [(o.id, o.cls, o.label) for o in got] != [
                    (o.id, o.cls, o.label) for o in expected
                ]:
                    mismatched += 1
                    continue
                for g, e in zip(got, expected, strict=True):
                    a, b = _numbers(g), _numbers(e)
                    if len(a) != len(b):
                        mismatched += 1
                        break
                    largest = max([largest, *(abs(x - y) for x, y in zip(a, b, strict=True))])
        result[name] = {
            "seeds": seeds,
            "frames": frames,
            "mismatched_frames": mismatched,
            "largest_difference": largest,
        }
    return result


# --------------------------------------------------------------- the parity mode
QUERIES_EVERY = 10
"""Every this many calls the world is also asked for in the past, now and ahead."""
HYPOTHESES = 20
"""The most probable hypotheses compared (their probabilities, rank by rank)."""
TOLERANCE = 1e-9
"""Issue 29: published numbers within this of each other."""


@dataclass(frozen=True)
class ParityCase:
    """One row of the parity run: a scenario with its sizes, run by :func:`parity_run`."""

    label: str
    scenario: str  # a name of semwm.sim.scenarios.SCENARIOS, or "kick" (semwm.sim.kick)
    sizes: dict[str, Any] = field(default_factory=dict)
    covers: str = ""  # what it exercises (the results' last column)
    reorder_window: float = 1.0
    views: bool = False  # leftbehind's poses as sensor views (SensorViews), empty scans
    association_model: str | None = None  # another model than the knowledge's


PARITY_CASES: tuple[ParityCase, ...] = (
    ParityCase("sim1", "sim1", covers="paper 002 sim. 1 (20 s): taxonomy, class labels, clutter"),
    ParityCase("sim2", "sim2", covers="paper 002 sim. 2: an IMM person, door relations, misses"),
    ParityCase("robocup", "robocup", covers="10 s: robots' labelled self-reports, 5 m ranges"),
    ParityCase("grid", "grid", covers="25 static objects seen every frame, 5 s; the region"),
    ParityCase(
        "tabletop_wrong_labels",
        "tabletop_wrong_labels",
        covers="wrong and superclass labels, confusion",
    ),
    ParityCase("corner_occlusion", "corner_occlusion", covers="a person hidden 2-4 s twice"),
    ParityCase("door_exits", "door_exits", covers="people entering and leaving by the door, 60 s"),
    ParityCase("datasheet", "datasheet", covers="learnt coverage (scan hulls), 60 s"),
    ParityCase("patrol", "patrol", covers="a moving 6 m scanner: range coverage, 90 s"),
    ParityCase(
        "leftbehind, no poses",
        "leftbehind",
        {"poses": False},
        "200 s: learnt coverage of a patrolling robot and a fixed camera",
        reorder_window=0.0,
    ),
    ParityCase(
        "leftbehind, views",
        "leftbehind",
        {"poses": True},
        "200 s: sensor views (looked at), empty scans",
        reorder_window=0.0,
        views=True,
    ),
    ParityCase("region_edge", "region_edge", covers="3-D, objects on the region's edges"),
    ParityCase(
        "kick, 5 trials",
        "kick",
        {"trials": 5},
        "paper 004's closed loop: a kick (act), views, a teammate's late messages",
    ),
    ParityCase(
        "robocup 5 s, paper",
        "robocup",
        {"duration": 5.0},
        "the paper association model (one cluster, eqs. 5-8)",
        association_model="paper",
    ),
)
"""Every scenario of semwm.sim.scenarios.SCENARIOS, the kick, and the paper model."""


@dataclass
class Tally:
    """What one run of a case compared, and the differences found."""

    frames: int = 0  # calls that may change the world (scans, empty scans, actions)
    objects: int = 0  # published objects compared after them
    queries: int = 0  # world() answers compared at other times (past, now, ahead)
    differing: int = 0  # calls after which something discrete differed
    largest: float = 0.0  # the largest difference of a published number
    largest_relative: float = 0.0  # the same relative to the number (where it is above 1)
    largest_hypotheses: float = 0.0  # of the best hypotheses' probabilities
    first: str | None = None  # the first difference, said in words

    def add(self, other: Tally) -> None:
        self.frames += other.frames
        self.objects += other.objects
        self.queries += other.queries
        self.differing += other.differing
        self.largest = max(self.largest, other.largest)
        self.largest_relative = max(self.largest_relative, other.largest_relative)
        self.largest_hypotheses = max(self.largest_hypotheses, other.largest_hypotheses)
        self.first = self.first or other.first


def _largest(a: list[float], b: list[float]) -> float:
    return max((abs(x - y) for x, y in zip(a, b, strict=True)), default=0.0)


def _largest_relative(a: list[float], b: list[float]) -> float:
    """The largest difference relative to the numbers' size where it is above 1 (a
    covariance of 1e4 m^2, an object unseen for a minute, rounds at 1e-12)."""
    pairs = zip(a, b, strict=True)
    return max((abs(x - y) / max(1.0, abs(x), abs(y)) for x, y in pairs), default=0.0)


class Lockstep:
    """Both engines fed the same calls, the Python engine first; quacks like a
    ``WorldModel`` (``ingest``, ``act``, ``world``) and answers with the Python engine's
    values, so a closed loop (``semwm.sim.kick``) or ``SensorViews`` drives both. Every
    difference is tallied (:class:`Tally`), none raised: the run goes on."""

    def __init__(self, knowledge: Knowledge, tally: Tally, **options: Any) -> None:
        self.python = WorldModel(knowledge, engine="python", **options)
        self.rust = WorldModel(knowledge, engine="rust", **options)
        self.tally = tally

    def _differs(self, what: str) -> None:
        self.tally.differing += 1
        if self.tally.first is None:
            self.tally.first = f"call {self.tally.frames}: {what}"

    def _both(self, name: str, *args: Any, **kwargs: Any) -> tuple[Any, Any]:
        outcomes: list[tuple[Any, Exception | None]] = []
        for model in (self.python, self.rust):
            try:
                outcomes.append((getattr(model, name)(*args, **kwargs), None))
            except Exception as error:  # compared, then raised again
                outcomes.append((None, error))
        (expected, p_error), (got, r_error) = outcomes
        if (type(p_error), str(p_error)) != (type(r_error), str(r_error)):
            self._differs(f"{name}: the Python engine raised {p_error!r}, Rust {r_error!r}")
        if p_error is not None:
            raise p_error
        return expected, got

    def _changed(self, name: str, *args: Any, **kwargs: Any) -> Any:
        try:
            expected, got = self._both(name, *args, **kwargs)
        except Exception:
            self.compare()
            raise
        if got != expected:
            self._differs(f"{name} answered {expected!r} (Python), {got!r} (Rust)")
        self.compare()
        return expected

    def ingest(self, *args: Any, **kwargs: Any) -> Any:
        return self._changed("ingest", *args, **kwargs)

    def act(self, *args: Any, **kwargs: Any) -> Any:
        return self._changed("act", *args, **kwargs)

    def world(self, *args: Any, **kwargs: Any) -> WorldState:
        expected, got = self._both("world", *args, **kwargs)
        self._same_state(expected, got, "world")
        state: WorldState = expected
        return state

    def _same_state(self, expected: WorldState, got: WorldState, what: str) -> bool:
        """The same objects (keys and count) with every number's difference tallied."""
        keys = [_keys(o) for o in expected.objects]
        other = [_keys(o) for o in got.objects]
        if other != keys or got.time != expected.time:
            pairs = enumerate(zip(keys, other, strict=False))  # the first object differing
            at = next((i for i, (a, b) in pairs if a != b), None)
            said = (
                f"object {at}: Python {keys[at]}, Rust {other[at]}"
                if at is not None
                else f"Python {len(keys)} objects at {expected.time}, Rust {len(other)} at "
                f"{got.time}"
            )
            self._differs(f"{what} at {expected.time}: {said}")
            return False
        for e, g in zip(expected.objects, got.objects, strict=True):
            a, b = _numbers(e), _numbers(g)
            if len(a) != len(b):
                self._differs(f"{what}: object {e.id} has other numbers")
                return False
            self.tally.largest = max(self.tally.largest, _largest(a, b))
            relative = _largest_relative(a, b)
            self.tally.largest_relative = max(self.tally.largest_relative, relative)
        return True

    def compare(self) -> None:
        """After a call: the published world, counts and best hypotheses; every
        :data:`QUERIES_EVERY` calls the world in the past, now and 0.5 s ahead."""
        python, rust, tally = self.python, self.rust, self.tally
        expected = python.world(min_existence=1e-6)
        self._same_state(expected, rust.world(min_existence=1e-6), "the world")
        tally.objects += len(expected.objects)
        counts = ("hypothesis_count", "cluster_count", "track_count", "object_count")
        for name in (*counts, "latest_time", "replayed_scans"):
            if getattr(rust, name) != getattr(python, name):
                self._differs(f"{name}: Python {getattr(python, name)}, Rust {getattr(rust, name)}")
        p_best = [h.probability for h in python.hypotheses(HYPOTHESES)]
        r_best = [h.probability for h in rust.hypotheses(HYPOTHESES)]
        if len(p_best) != len(r_best):
            self._differs(f"{len(p_best)} best hypotheses (Python), {len(r_best)} (Rust)")
        else:
            tally.largest_hypotheses = max(tally.largest_hypotheses, _largest(p_best, r_best))
        tally.frames += 1
        now = python.latest_time
        if tally.frames % QUERIES_EVERY == 0 and now is not None:
            window = python.reorder_window
            for at in ([now - 0.5 * window] if window > 0.0 else []) + [now, now + 0.5]:
                try:
                    answers = self._both("world", at, min_existence=1e-6)
                except BeforeHistoryError:
                    continue  # both refused alike (_both compared the messages)
                self._same_state(*answers, f"world({at:g})")
                tally.queries += 1


def _scenario_knowledge(scenario: Scenario, model: str | None) -> Knowledge:
    """The knowledge a scenario is meant for (shipped, or its ``knowledge_dir``), with the
    grid's region and another association model where asked for."""
    directory = scenario.metadata.get("knowledge_dir")
    if isinstance(directory, str):
        knowledge = load_knowledge(BENCHMARKS.parent / directory / scenario.knowledge_file)
    else:
        knowledge = load_knowledge(shipped_knowledge_path(scenario.knowledge_file))
    update: dict[str, Any] = {}
    if scenario.name == "grid":
        update["region"] = tuple(tuple(r) for r in scenario.region)
    if model is not None:
        update["association_model"] = model
    if update:
        world = knowledge.world.model_copy(update=update)
        knowledge = knowledge.model_copy(update={"world": world})
    return knowledge


@contextmanager
def _kick_in_lockstep(tally: Tally) -> Iterator[None]:
    """``semwm.sim.kick`` makes its world models in ``run_trial``: each is a
    :class:`Lockstep` meanwhile."""

    def made(knowledge: Knowledge, **options: Any) -> Lockstep:
        return Lockstep(knowledge, tally, **options)

    with mock.patch.object(kick, "WorldModel", made):
        yield


def parity_run(case: ParityCase, seed: int) -> Tally:
    """One case and seed with both engines in step."""
    tally = Tally()
    if case.scenario == "kick":
        knowledge = load_knowledge(shipped_knowledge_path("robocup_kick.yaml"))
        with _kick_in_lockstep(tally):
            kick.run_kick(knowledge, seed, trials=int(case.sizes["trials"]))
        return tally
    scenario = make_scenario(case.scenario, seed, **case.sizes)
    knowledge = _scenario_knowledge(scenario, case.association_model)
    both = Lockstep(knowledge, tally, reorder_window=case.reorder_window)
    model: Lockstep | SensorViews = SensorViews(both, scenario) if case.views else both
    for scan in scans(scenario.detections):
        model.ingest(scan)
    return tally


def run_parity(
    seeds: int, cases: tuple[ParityCase, ...] = PARITY_CASES, *, require_all: bool = True
) -> dict[str, Any]:
    """Every case over seeds 0 to ``seeds`` - 1: the tallies per case and seed.
    ``require_all``: refuse to run without a case for every scenario of SCENARIOS."""
    if rust_core() is None:
        raise SystemExit("bench_engines: semwm._core is not built (docs/engines.md)")
    missing = sorted(set(SCENARIO_GENERATORS) - {case.scenario for case in cases})
    if missing and require_all:
        raise SystemExit(f"bench_engines: no parity case for {', '.join(missing)}")
    rows = []
    machine = machine_info()  # now: the commit whose code runs
    started = time.process_time()
    with tqdm(total=len(cases) * seeds, desc="parity", unit="run") as bar:
        for case in cases:
            total = Tally()
            per_seed = []
            spent = time.process_time()
            for seed in range(seeds):
                bar.set_postfix_str(f"{case.label}, seed {seed}")
                tally = parity_run(case, seed)
                if tally.first is not None:
                    tally.first = f"seed {seed}, {tally.first}"
                    tqdm.write(f"{case.label}: {tally.first}")
                per_seed.append({"seed": seed, **asdict(tally)})
                total.add(tally)
                bar.update()
            rows.append(
                {
                    "case": case.label,
                    "scenario": case.scenario,
                    "sizes": case.sizes,
                    "covers": case.covers,
                    "reorder_window": case.reorder_window,
                    "seeds": seeds,
                    **asdict(total),
                    "equal": total.differing == 0,
                    "cpu_seconds": time.process_time() - spent,
                    "per_seed": per_seed,
                }
            )
    return {
        "machine": machine,
        "engines": {engine: engine_description(engine) for engine in ENGINES},
        "seeds": seeds,
        "queries_every": QUERIES_EVERY,
        "hypotheses": HYPOTHESES,
        "cpu_seconds": time.process_time() - started,
        "cases": rows,
    }


def parity_markdown(doc: dict[str, Any]) -> str:
    machine = doc["machine"]
    equal = all(row["equal"] for row in doc["cases"])
    largest = max((row["largest"] for row in doc["cases"]), default=0.0)
    relative = max((row.get("largest_relative", 0.0) for row in doc["cases"]), default=0.0)
    holds = equal and relative <= TOLERANCE
    lines = [
        "# Parity of the Python and the Rust engine (bench_engines.py --parity-seeds)",
        "",
        f"{machine['date']}, commit {machine.get('commit')}, {machine['processor']}, "
        f"{machine['cpu_count']} cores, Python {machine['python']}; engines "
        f"{', '.join(doc['engines'].values())}; seeds 0-{doc['seeds'] - 1}; "
        f"{doc['cpu_seconds'] / 60.0:.1f} min of CPU.",
        "",
        "Both engines in step, every call (scans, empty scans with a sensor view, kicks, "
        "late scans) compared: what it answered or raised; after it the published world "
        "(`world(min_existence=1e-6)`: ids, classes, labels, modes and classes named, "
        "confidence states, tentative flags, and every number: position, velocity, "
        "covariance, existence, last seen, created, mode and class probabilities, "
        "confidence), the hypothesis, cluster, version and object counts, the "
        f"{doc['hypotheses']} best hypotheses' probabilities; every "
        f"{doc['queries_every']} calls the world half the reorder window back, now and "
        '0.5 s ahead. "calls differing": calls after which something that must be '
        'equal was not; "relative": each difference divided by the number where that is '
        "above 1 (a covariance of 1e4 m² rounds at 1e-12).",
        "",
        f"**Parity {'holds' if holds else 'does not hold'}: ids, classes, labels and "
        f"counts {'equal everywhere' if equal else 'differ'}; the largest difference of a "
        f"published number {largest:.2g}, {relative:.2g} relative to the numbers above 1 "
        f"(issue 29: at most {TOLERANCE:g}).**",
        "",
        "| case | seeds | calls | objects compared | queries | ids, classes, labels, "
        "counts equal | calls differing | largest difference | relative | largest "
        "hypothesis difference | CPU s | covers |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for row in doc["cases"]:
        lines.append(
            f"| {row['case']} | {row['seeds']} | {row['frames']:,} | {row['objects']:,} "
            f"| {row['queries']:,} | {'yes' if row['equal'] else '**no**'} "
            f"| {row['differing']} | {row['largest']:.2g} "
            f"| {row.get('largest_relative', 0.0):.2g} "
            f"| {row['largest_hypotheses']:.2g} | {row['cpu_seconds']:.0f} | {row['covers']} |"
        )
    firsts = [row for row in doc["cases"] if row["first"]]
    if firsts:
        lines += ["", "First difference per case:", ""]
        lines += [f"- {row['case']}: {row['first']}" for row in firsts]
    return "\n".join(lines) + "\n"


def run(quick: bool, repeats: int, seeds: int) -> dict[str, Any]:
    if rust_core() is None:
        raise SystemExit("bench_engines: semwm._core is not built (docs/engines.md)")
    engines: tuple[Engine, ...] = ENGINES
    cases = [grid(n, repeats, engines) for n in (GRID_SIZES[:1] if quick else GRID_SIZES)]
    cases += [scenario(name, repeats, engines) for name in SCENARIOS]
    for case in cases:
        case["speedup"] = case["python"]["us_per_detection"] / case["rust"]["us_per_detection"]
    return {
        "machine": machine_info(),
        "engines": {engine: engine_description(engine) for engine in engines},
        "repeats": repeats,
        "cases": cases,
        "queries": queries(repeats, engines),
        "views": views(repeats, engines),
        "kernels": kernels(repeats, engines),
        "existence_kernels": existence_kernels(repeats, engines),
        "filter_share_robocup": filter_share(engines),
        "parity": parity(seeds),
    }


def markdown(doc: dict[str, Any]) -> str:
    machine = doc["machine"]
    lines = [
        "# The Python and the Rust engine (bench_engines.py)",
        "",
        f"{machine['date']}, {machine['processor']}, {machine['cpu_count']} cores, Python "
        f"{machine['python']}; engines {', '.join(doc['engines'].values())}; CPU time, "
        f"best of {doc['repeats']} interleaved runs.",
        "",
        "| case | detections / frame | Python µs/det | Rust µs/det | Python ms/frame "
        "| Rust ms/frame | Python / Rust |",
        "|---|---|---|---|---|---|---|",
    ]
    for case in doc["cases"]:
        per_frame = case.get("detections_per_frame") or case["detections"] / case["scans"]
        lines.append(
            f"| {case['case']} | {fmt(per_frame, 4)} | {fmt(case['python']['us_per_detection'])} "
            f"| {fmt(case['rust']['us_per_detection'])} | {fmt(case['python']['ms_per_frame'])} "
            f"| {fmt(case['rust']['ms_per_frame'])} | {case['speedup']:.2f}x |"
        )
    lines += [
        "",
        "The expansion of a scan (step 5 of semwm.mhf.filter: the clusters a detection "
        "touches joined, expanded, merged, pruned and split; in Rust with the Rust engine) "
        "within the same runs, CPU µs per scan:",
        "",
        "| case | Python | Rust | Python / Rust |",
        "|---|---|---|---|",
    ]
    whole = "in the scan's one core call"  # the Rust engine's scan is not split in Python
    for case in doc["cases"]:
        p_us = case["python"].get("expansion_us_per_scan")
        r_us = case["rust"].get("expansion_us_per_scan")
        if p_us is not None and r_us is not None:
            ratio = f"{p_us / r_us:.2f}x" if r_us > 0.0 else "-"
            rust = fmt(r_us) if r_us > 0.0 else whole
            lines.append(f"| {case['case']} | {fmt(p_us)} | {rust} | {ratio} |")
    lines += [
        "",
        "A robot that reads the world as it reports: the scans ingested, the world asked "
        "for at each scan's time after it (default options), CPU µs per detection of the "
        "ingest calls and µs per `world()` call, each the best of the repeats:",
        "",
        "| case | detections | queries | objects / query | Python ingest µs/det "
        "| Rust ingest µs/det | Python µs/query | Rust µs/query | Python / Rust (query) |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for row in doc.get("queries", []):
        p, r = row["python"], row["rust"]
        lines.append(
            f"| {row['case']} | {row['detections']} | {row['queries']} "
            f"| {fmt(r['objects_per_query'], 3)} | {fmt(p['ingest_us_per_detection'])} "
            f"| {fmt(r['ingest_us_per_detection'])} | {fmt(p['us_per_query'])} "
            f"| {fmt(r['us_per_query'])} | {p['us_per_query'] / r['us_per_query']:.1f}x |"
        )
    seen = doc.get("views")
    if seen is not None:
        lines += [
            "",
            f"Paper 004's negative information: {seen['case']} (seed 0, "
            f"{seen['detections']} detections) with its robot's and fixed camera's sensor "
            f"views ({seen['calls']['views']} ingest calls: each scan with its sensor report, "
            f"the empty ones too) beside the same scans without them "
            f"({seen['calls']['plain']} calls), CPU µs, best of the repeats:",
            "",
            "| engine | per detection, no views | per detection, views | per call, views "
            "| views / no views |",
            "|---|---|---|---|---|",
        ]
        for engine in ENGINES:
            row = seen[engine]
            lines.append(
                f"| {engine} | {fmt(row['plain']['us_per_detection'])} "
                f"| {fmt(row['views']['us_per_detection'])} | {fmt(row['views']['us_per_call'])} "
                f"| {row['views']['us_per_detection'] / row['plain']['us_per_detection']:.2f}x |"
            )
    lines += [
        "",
        "The kernels alone, µs per call (robocup's Robot: IMM, 2 modes, 4 states, 2-D):",
        "",
        "| N objects | predict Python | predict Rust | ratio | update Python "
        "| update Rust | ratio |",
        "|---|---|---|---|---|---|---|",
    ]
    for row in doc.get("kernels", []):
        p, r = row["python"], row["rust"]
        lines.append(
            f"| {row['n']} | {fmt(p['predict_us'])} | {fmt(r['predict_us'])} "
            f"| {p['predict_us'] / r['predict_us']:.1f}x | {fmt(p['update_us'])} "
            f"| {fmt(r['update_us'])} | {p['update_us'] / r['update_us']:.1f}x |"
        )
    lines += [
        "",
        "The existence and coverage kernels alone, µs per call (2-D; the hull of 12 detections):",
        "",
        "| N objects | inside Python | inside Rust | in view Python | in view Rust "
        "| survive Python | survive Rust | hull Python | hull Rust |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for row in doc.get("existence_kernels", []):
        p, r = row["python"], row["rust"]
        lines.append(
            f"| {row['n']} | {fmt(p['inside_us'])} | {fmt(r['inside_us'])} "
            f"| {fmt(p['in_view_us'])} | {fmt(r['in_view_us'])} "
            f"| {fmt(p['survive_us'])} | {fmt(r['survive_us'])} "
            f"| {fmt(p['hull_us'])} | {fmt(r['hull_us'])} |"
        )
    share = doc["filter_share_robocup"]
    lines += [
        "",
        "Share of robocup's ingest CPU time (cProfile) inside the filters: "
        + ", ".join(
            f"{engine} {100 * s['filters_share']:.1f} % ({s['filter_calls']} calls)"
            if s["filter_calls"]
            else f"{engine}: {whole} (Engine.process_and_advance)"
            for engine, s in share.items()
        )
        + "; inside the existence step (existence_at, leaving, undetected): "
        + ", ".join(
            f"{engine} {100 * s.get('existence_share', 0.0):.1f} %"
            if s["filter_calls"]
            else f"{engine}: {whole}"
            for engine, s in share.items()
        )
        + ".",
        "",
        "| parity | seeds | frames | frames with other ids/classes | largest difference |",
        "|---|---|---|---|---|",
    ]
    for name, p in doc["parity"].items():
        lines.append(
            f"| {name} | {p['seeds']} | {p['frames']} | {p['mismatched_frames']} "
            f"| {p['largest_difference']:.2g} |"
        )
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> dict[str, Any]:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true", help="grid N = 50 only, 1 repeat")
    parser.add_argument("--repeats", type=int, default=3, help="runs per engine (best kept)")
    parser.add_argument("--seeds", type=int, default=5, help="seeds of the parity check")
    parser.add_argument(
        "--parity-seeds",
        type=int,
        nargs="?",
        const=20,
        default=None,
        metavar="N",
        help="only the parity check of every scenario, over N seeds (20 if no N is given); "
        "writes engines_parity.*",
    )
    add_output_arguments(parser)
    args = parser.parse_args(argv)
    if args.parity_seeds is not None:
        seeds = min(args.parity_seeds, 2) if args.quick else args.parity_seeds
        doc = run_parity(seeds)
        write_results(
            RESULTS,
            "engines_parity",
            doc,
            parity_markdown(doc),
            args.quick,
            update_results=args.update_results,
        )
        return doc
    repeats = 1 if args.quick else args.repeats
    seeds = min(args.seeds, 2) if args.quick else args.seeds
    doc = run(args.quick, repeats, seeds)
    write_results(
        RESULTS, "engines", doc, markdown(doc), args.quick, update_results=args.update_results
    )
    return doc


if __name__ == "__main__":
    main()
