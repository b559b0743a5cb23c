"""Speed of semwm's two engines beside Stone Soup JPDA: issue 29's table in one run.

One command measures every row of issue 29's speed table, with the Python engine
(the specification, ``WorldModel(..., engine="python")``), the Rust engine (the core,
``engine="rust"``) and, where it applies, Stone Soup JPDA, on the same data:

* the room (``sim2``) and RoboCup (2 s), seed 0: CPU µs per detection of the
  ``ingest`` calls (``time.process_time``) and wall µs per detection as the runner
  reports it (``semwm.sim.runner.run_scenario``, the measure every tracker gets in
  ``bench_trackers.py``); target: JPDA / semwm (the Rust engine, the default) >= 100x;
* the static grid of N = 50 objects (CPU ms per frame; target <= 0.1 ms) and N = 1,000
  (CPU µs per detection; target <= 3 µs), all detected every 10 Hz frame: the mean of
  the timed frames after the warm-up ones;
* a team's stream in process (5 robots x 10 detections x 30 Hz on 20 shared objects,
  ``sim1.yaml``: ``bench_teamload``'s layout, :func:`team_stream`): CPU ms per batch
  after 150 warm-up batches; target <= 0.1 ms;
* batches of 1,000 (a static grid of 100 objects, 10 frames per batch:
  ``bench_http.batch_case``) in process (CPU det/s of ``ingest``; target >= 500,000) and
  over HTTP (``semwm serve --engine E`` in its own process, one keep-alive client, wall
  det/s at the client: ``bench_http.over_http``; target >= 200,000);
* a RoboCup match of 8 s (seed 0): CPU µs per detection over the match and in each
  quarter of it (by the scans' times); target: flat (here: the last quarter within 20 %
  of the first). Stone Soup JPDA is not run on it (tens of CPU minutes). Once more per
  engine, not timed for the table: ``ingest`` by stage in each quarter and the versions
  and hypotheses stored (:func:`long_split`), what grows.

The runs are interleaved: Python engine, Rust engine, Stone Soup JPDA, and again,
``--repeats`` times, so that all three see the same load on a shared machine; each
figure is the best of the repeats (the run least disturbed by other load; for det/s
the highest). Each scenario run (the room, RoboCup, the long match) starts after
``gc.collect()``, every tracker's alike: the cyclic collector then collects, during the
run, what the run itself leaves, not what the sections before it left (the collector
stays on). Compare the ratios, measured side by side, rather than absolute times
across days.

Then, once per engine and not timed: memory (``tracemalloc``'s peak over 3 frames of
the static grid after its timed frames; bytes per stored object version: the Python
engine's :class:`~semwm.mhf.state.Track` with its arrays, measured, against the core's
version, estimated from the structs of ``core/src/mhf/state.rs`` and the sizes of each
stored version (:func:`core_version_bytes`)); where the Rust engine's ``ingest`` spends
its time: its parts timed without a profiler (``bench_http.model_timers``: validate,
core, publish, the rest) on each workload, and a cProfile of its ``ingest`` on RoboCup
2 s and on the batches of 1,000 (Python calls per detection, the share of the time in
the core's methods, the top functions by own time): where the Python glue around the
core spends its time.

The former ``--baseline REF`` (a second, older core imported from a ``git archive`` of
REF, side by side) is gone: both engines of this checkout are now the comparison, and
the Rust engine of another commit needs its own release build of the extension (the
archive has no ``semwm/_core``), minutes of a shared 2-core machine per run.

Writes ``speed.json`` and ``speed.md`` to ``benchmarks/out/`` (``benchmarks/results/``
with ``--update-results``).

    python benchmarks/bench_speed.py [--quick] [--repeats 3] [--update-results]
"""

from __future__ import annotations

import argparse
import cProfile
import gc
import io
import math
import pstats
import sys
import tempfile
import time
import tracemalloc
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))

import numpy as np
from baselines import RESULTS, add_output_arguments, fmt, machine_info, write_results
from tqdm import tqdm

ENGINES = ("python", "rust")
JPDA = "stonesoup_jpda"
SCENARIOS: dict[str, dict[str, Any]] = {"sim2": {}, "robocup": {"duration": 2.0}}
LONG = ("robocup", 8.0)
QUICK_LONG = ("robocup", 4.0)
GRID_SIZES = (50, 1000)
GRID_WARMUP, GRID_TIMED, GRID_TRACED = 10, 20, 3
QUICK_GRID_TIMED = 5
TEAM_SECONDS, QUICK_TEAM_SECONDS = 6.0, 3.0
BATCHES, QUICK_BATCHES = 20, 8
LONGER = (16.0, 32.0)
"""The long match once more at these lengths (s), once per engine: does its cost per
detection grow with its length?"""
QUARTERS = 4
FLAT = 1.2
"""The last quarter of the long match within this factor of the first: flat."""
TOP = 12
SCENARIOS_FOR_MEMORY = ("robocup", 2.0)


@dataclass(frozen=True)
class Row:
    """One row of issue 29's table: how it is measured and its target."""

    key: str
    measure: str
    unit: str
    target: str
    higher_is_better: bool = False


ROWS = (
    Row("sim2", "JPDA / semwm CPU per detection, the room (sim2)", "µs/det", ">= 100x"),
    Row("robocup", "JPDA / semwm CPU per detection, RoboCup 2 s", "µs/det", ">= 100x"),
    Row("grid50", "static grid N = 50, per frame", "ms/frame", "<= 0.1 ms"),
    Row("grid1000", "static grid N = 1,000, per detection", "µs/det", "<= 3 µs"),
    Row("team", "team stream in process (5 robots x 10 det x 30 Hz), per batch",
        "ms/batch", "<= 0.1 ms"),
    Row("batch", "batches of 1,000 in process", "det/s", ">= 500,000 det/s", True),
    Row("batch_http", "batches of 1,000 over HTTP", "det/s", ">= 200,000 det/s", True),
    Row("long", "RoboCup 8 s match, per detection", "µs/det", "flat over the match"),
)  # fmt: skip


# --------------------------------------------------------------------- scenarios


def _scenario(name: str, sizes: dict[str, Any]) -> tuple[Any, Any]:
    from semwm.knowledge.loader import load_knowledge
    from semwm.knowledge.shipped import shipped_knowledge_path
    from semwm.sim.scenarios import make_scenario

    scenario = make_scenario(name, 0, **sizes)
    return scenario, load_knowledge(shipped_knowledge_path(scenario.knowledge_file))


class _CpuTimed:
    """A tracker whose ``ingest`` calls are timed in CPU seconds (``process_time``),
    each with its scan's time; optionally under a profiler; the rest is delegated."""

    def __init__(self, tracker: Any, profile: cProfile.Profile | None = None) -> None:
        self._tracker = tracker
        self._profile = profile
        self.cpu_s = 0.0
        self.per_scan: list[tuple[float, int, float]] = []  # (time, detections, cpu s)

    def ingest(self, scan: Any) -> Any:
        if self._profile is not None:
            self._profile.enable()
        start = time.process_time()
        try:
            return self._tracker.ingest(scan)
        finally:
            took = time.process_time() - start
            self.cpu_s += took
            if self._profile is not None:
                self._profile.disable()
            self.per_scan.append((max(d.time for d in scan), len(scan), took))

    def __getattr__(self, name: str) -> Any:
        return getattr(self._tracker, name)


def _timed_run(
    name: str,
    sizes: dict[str, Any],
    tracker: str,
    profile: cProfile.Profile | None = None,
) -> dict[str, Any]:
    """One run of ``tracker`` (an engine, or :data:`JPDA`) on a scenario: CPU of its
    ingest calls, the runner's wall, and the CPU per detection of each quarter of it."""
    from semwm.sim.runner import run_scenario
    from semwm.world import WorldModel

    scenario, knowledge = _scenario(name, sizes)
    # a run starts with nothing left to collect: without it, the collections of what the
    # sections before it left landed in its ingest calls (the room: 9.2-12.5 us per
    # detection over six runs of one commit, 9.3-9.7 with it)
    gc.collect()
    if tracker in ENGINES:
        WorldModel(knowledge, engine=tracker)  # lazy imports outside the measured calls

        def build(k: Any) -> Any:
            return WorldModel(k, engine=tracker)

    else:
        from baselines import StoneSoupTracker, clutter_area, tuning_from_knowledge
        from bench_trackers import FULL

        rate = FULL[name][1]
        tuning = tuning_from_knowledge(knowledge, scan_rate=rate, area=clutter_area(scenario))
        mode = tracker.removeprefix("stonesoup_")

        def build(k: Any) -> Any:
            return StoneSoupTracker(tuning, mode, time_limit=600.0)

    timed: list[_CpuTimed] = []

    def factory(k: Any) -> Any:
        timed.append(_CpuTimed(build(k), profile))
        return timed[-1]

    result = run_scenario(scenario, knowledge, progress=False, world_model_factory=factory)
    n = result.n_detections
    scans = timed[0].per_scan
    end = max(t for t, _, _ in scans)
    quarters = []
    for q in range(QUARTERS):
        low, high = end * q / QUARTERS, end * (q + 1) / QUARTERS
        inside = [(k, c) for t, k, c in scans if (low < t <= high) or (q == 0 and t <= low)]
        dets = sum(k for k, _ in inside)
        quarters.append(sum(c for _, c in inside) / dets * 1e6 if dets else None)
    return {
        "detections": n,
        "cpu_us_per_detection": timed[0].cpu_s / n * 1e6,
        "wall_us_per_detection": result.metrics.time_per_detection["mean_s"] * 1e6,
        "quarters_cpu_us_per_detection": quarters,
        "gospa": result.metrics.gospa.total,
        "id_switches": result.metrics.id_switches,
    }


def _best_run(runs: list[dict[str, Any]]) -> dict[str, Any]:
    best = min(runs, key=lambda r: r["cpu_us_per_detection"])
    quarters = [
        min(
            (
                r["quarters_cpu_us_per_detection"][q]
                for r in runs
                if r["quarters_cpu_us_per_detection"][q] is not None
            ),
            default=None,
        )
        for q in range(QUARTERS)
    ]
    return {
        **best,
        "wall_us_per_detection": min(r["wall_us_per_detection"] for r in runs),
        "quarters_cpu_us_per_detection": quarters,
    }


# --------------------------------------------------------------------- the grid


def grid(n: int, engine: str, directory: Path, timed_frames: int = GRID_TIMED) -> dict[str, Any]:
    """The static grid of ``n`` objects, all detected every 10 Hz frame (one scan): CPU
    per frame over ``timed_frames`` after :data:`GRID_WARMUP`, then ``tracemalloc``'s peak
    over :data:`GRID_TRACED` more; the model is kept (``model``) for its memory."""
    from bench_http import _grid_knowledge

    from semwm.knowledge.loader import load_knowledge
    from semwm.sim.runner import scans
    from semwm.sim.scenarios import make_scenario
    from semwm.world import WorldModel

    frames = GRID_WARMUP + timed_frames + GRID_TRACED
    path, _ = _grid_knowledge(n, directory)
    scenario = make_scenario("grid", 0, n_objects=n, duration=(frames - 1) / 10.0)
    model = WorldModel(load_knowledge(path), engine=engine)
    all_scans = list(scans(scenario.detections))
    cpu: list[float] = []
    for scan in all_scans[: GRID_WARMUP + timed_frames]:
        started = time.process_time()
        model.ingest(scan)
        cpu.append(time.process_time() - started)
    tracemalloc.start()
    for scan in all_scans[GRID_WARMUP + timed_frames :]:
        model.ingest(scan)
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    steady = cpu[GRID_WARMUP:]
    return {
        "n": n,
        "frames_timed": len(steady),
        "ms_per_frame": float(np.mean(steady)) * 1e3,
        "us_per_detection": float(np.mean(steady)) * 1e6 / n,
        "warmup_ms": float(np.sum(cpu[:GRID_WARMUP])) * 1e3,
        "peak_traced_mb": peak / 1e6,
        "objects": model.object_count,
        "hypotheses": model.hypothesis_count,
        "model": model,
    }


# --------------------------------------------------------------------- the team


def team_batches(seconds: float) -> list[list[dict[str, Any]]]:
    """The team's stream of ``bench_teamload``: 5 robots x 10 detections x 30 Hz on 20
    shared objects (``sim1.yaml``), robot ``r`` seeing objects ``2r .. 2r + 9`` with 5 cm
    noise; one batch per robot and tick, in time order (robot ``r`` at ``r`` ms)."""
    from bench_teamload import NOISE, OBJECTS, PER_BATCH, RATE_HZ, ROBOTS

    rngs = [np.random.default_rng(robot) for robot in range(ROBOTS)]
    seen = [[OBJECTS[(2 * r + k) % len(OBJECTS)] for k in range(PER_BATCH)] for r in range(ROBOTS)]
    batches = []
    for tick in range(round(seconds * RATE_HZ)):
        for r in range(ROBOTS):
            noise = rngs[r].normal(0.0, NOISE, size=(PER_BATCH, 2))
            batches.append(
                [
                    {"time": tick / RATE_HZ + r * 1e-3, "class": cls, "source": f"r{r}",
                     "position": [x + noise[k, 0], y + noise[k, 1]]}
                    for k, (cls, (x, y)) in enumerate(seen[r])
                ]
            )  # fmt: skip
    return batches


def team_stream(
    seconds: float = TEAM_SECONDS, warmup_batches: int = 150, engine: str | None = None
) -> dict[str, Any]:
    """The team's stream (:func:`team_batches`) in process, one ``ingest`` per robot's
    batch; CPU per batch after ``warmup_batches`` (the mean of the timed batches).
    ``engine``: ``None``, the default one (``bench_teamload`` measures the machine's
    moment with it)."""
    from bench_teamload import PER_BATCH, RATE_HZ, ROBOTS

    from semwm.knowledge.loader import load_knowledge
    from semwm.knowledge.shipped import shipped_knowledge_path
    from semwm.world import WorldModel

    world = WorldModel(load_knowledge(shipped_knowledge_path("sim1.yaml")), engine=engine)
    batches = team_batches(seconds)
    for batch in batches[:warmup_batches]:
        world.ingest(batch)
    timed = batches[warmup_batches:]
    start = time.process_time()
    for batch in timed:
        world.ingest(batch)
    cpu = time.process_time() - start
    return {
        "engine": world.engine,
        "batches": len(timed),
        "detections_per_batch": PER_BATCH,
        "cpu_ms_per_batch": cpu / len(timed) * 1e3,
        "cpu_us_per_detection": cpu / (len(timed) * PER_BATCH) * 1e6,
        "objects": len(world.world().objects),
        "hypotheses": world.hypothesis_count,
        "offered_det_per_s": ROBOTS * PER_BATCH * RATE_HZ,
    }


# --------------------------------------------------------------------- batches


def batches_in_process(case: Any, engine: str) -> dict[str, Any]:
    """The batches of 1,000 in process: CPU det/s of ``ingest`` (and wall)."""
    from semwm.knowledge.loader import load_knowledge
    from semwm.world import WorldModel

    model = WorldModel(load_knowledge(case.knowledge), reorder_window=0.5, engine=engine)
    cpu = wall = 0.0
    for request in case.requests:
        started, cpu_started = time.perf_counter(), time.process_time()
        model.ingest(request)
        wall += time.perf_counter() - started
        cpu += time.process_time() - cpu_started
    return {
        "requests": len(case.requests),
        "detections": case.detections,
        "cpu_det_per_s": case.detections / cpu,
        "wall_det_per_s": case.detections / wall,
        "cpu_us_per_detection": cpu / case.detections * 1e6,
    }


def batches_over_http(case: Any, server: Any, client: Any) -> dict[str, Any]:
    """The batches of 1,000 over HTTP (``bench_http.over_http``): wall det/s at the client."""
    from bench_http import over_http

    run = over_http(case, server, client)
    n = case.detections
    return {
        "requests": len(case.requests),
        "detections": n,
        "wall_det_per_s": n / run["http"],
        "model_us_per_detection": 1e6
        * sum(run.get(f"stage:{s}", 0.0) for s in ("validate", "core", "publish", "model"))
        / n,
        "server_us_per_detection": 1e6 * run["latency"] / n,
    }


# --------------------------------------------------------------------- memory and profile


def python_version_bytes(tracks: Any) -> dict[str, Any]:
    """Bytes per stored version of the Python engine, measured: ``sys.getsizeof`` of each
    :class:`~semwm.mhf.state.Track` (its slots), of its arrays (``x``, ``P``, ``mu``,
    ``class_probs``: header and data; a view's data counted as its ``nbytes``) and of
    its ``sources`` set; class names and labels are shared strings, not counted."""
    total = 0
    count = 0
    for track in tracks:
        size = sys.getsizeof(track)
        for array in (track.x, track.P, track.mu, track.class_probs):
            size += sys.getsizeof(array) + (array.nbytes if array.base is not None else 0)
        size += sys.getsizeof(track.sources)
        total += size
        count += 1
    return {"versions": count, "bytes_per_version": total / count if count else None}


BTREE_CAPACITY = 11
"""Keys per node of Rust's ``BTreeMap`` (``2B - 1``, ``B = 6``)."""
BTREE_LEAF = 8 + BTREE_CAPACITY * (8 + 24) + 4 + 4
"""Bytes of a leaf node of the track table ``BTreeMap<u64, Entry>``: the parent pointer,
11 keys (``u64``) and 11 entries (``Entry``: an ``Arc`` pointer, ``existence``,
``serial``: 24 B), the parent index and the length (``u16`` each, padded)."""
VERSION_BYTES = 16 + 112
"""``Arc<Version>``: the counts (16 B) and ``Version`` (``key``, ``lineage``, ``cls``: 24 B;
``label: Option<Arc<str>>``: 16; ``state: Arc``: 8; four ``f64`` times and rate: 32;
``class_probs: Arc<[f64]>`` and ``sources: Arc<[Name]>``: 16 each; 112 B)."""
FILTER_STATE_BYTES = 16 + 88
"""``Arc<FilterState>``: the counts (16 B) and ``FilterState`` (``modes``, ``size``: 16 B;
three ``Vec<f64>``: 72; 88 B); its heap: ``8 (M n + M n^2 + M)`` B."""


def core_version_bytes(state: Any) -> dict[str, Any]:
    """Bytes per stored version of the Rust engine, estimated (64-bit, ``core/src/mhf/
    state.rs``): the track table's entry (:data:`BTREE_LEAF` / 11 at full nodes, twice
    that at half-full ones: the mean of the two), ``Arc<Version>`` (:data:`VERSION_BYTES`),
    its ``Arc<FilterState>`` (:data:`FILTER_STATE_BYTES` and its ``M n + M n^2 + M``
    floats), its class probabilities (``Arc<[f64]>``: 16 + 8 K) and its sources
    (``Arc<[Name]>``: 16 + 16 S; the names themselves are shared), each version counted
    whole (versions may share a filter state: an upper bound), mimalloc's rounding to its
    size classes not counted. The sizes of each version (M, n, K, S) are read from the
    state (``semwm._core.State.versions``)."""
    core = state.core
    keys = core.entries()[0]
    entry = BTREE_LEAF / BTREE_CAPACITY * 1.5
    total = 0.0
    for _, (x, p, mu), _, (probs, sources, _) in core.versions(list(keys)):
        floats = np.size(x) + np.size(p) + np.size(mu)
        total += (
            entry + VERSION_BYTES + FILTER_STATE_BYTES + 8 * floats
            + 16 + 8 * len(probs) + 16 + 16 * len(sources)
        )  # fmt: skip
    count = len(keys)
    return {
        "versions": count,
        "bytes_per_version": total / count if count else None,
        "hypotheses": core.hypothesis_count,
        "clusters": core.cluster_count,
    }


def memory(
    directory: Path, engine: str, grid_n: int, scenario: tuple[str, float]
) -> list[dict[str, Any]]:
    """Bytes per stored version with ``engine`` after the static grid of ``grid_n`` and
    after ``scenario`` (name, duration); the grid's ``tracemalloc`` peak."""
    from semwm.mhf.core_engine import CoreState
    from semwm.sim.runner import scans
    from semwm.world import WorldModel

    rows = []
    measured = grid(grid_n, engine, directory, timed_frames=1)
    models = [(f"static grid N = {grid_n}", measured["model"], measured["peak_traced_mb"])]
    name, duration = scenario
    found, knowledge = _scenario(name, {"duration": duration})
    model = WorldModel(knowledge, engine=engine)
    tracemalloc.start()
    for scan in scans(found.detections):
        model.ingest(scan)
    peak = tracemalloc.get_traced_memory()[1] / 1e6
    tracemalloc.stop()
    models.append((f"{name} {duration:g} s", model, peak))
    for label, model, peak_mb in models:
        state = model._state  # the committed state (a benchmark's look inside)
        if isinstance(state, CoreState):
            sizes = core_version_bytes(state)
            how = "estimated (structs of core/src/mhf/state.rs)"
        else:
            sizes = python_version_bytes(state.tracks.values())
            sizes["hypotheses"] = state.hypothesis_count
            sizes["clusters"] = len(state.clusters)
            how = "measured (sys.getsizeof of Track, arrays, sources)"
        rows.append(
            {"workload": label, "engine": engine, "peak_traced_mb": peak_mb, "how": how, **sizes}
        )
    return rows


def _short(path: str) -> str:
    for marker in ("site-packages/", "/semwm/", "lib/python3"):
        if marker in path:
            tail = path.split(marker, 1)[1]
            return ("semwm/" + tail) if marker == "/semwm/" else tail
    return path


def profile(label: str, ingest_all: Callable[[], int]) -> dict[str, Any]:
    """A cProfile of ``ingest_all`` (which ingests, returning the detections): Python
    calls per detection, the share of the time in the core's methods, the top functions
    by own time."""
    prof = cProfile.Profile()
    prof.enable()
    detections = ingest_all()
    prof.disable()
    stats = pstats.Stats(prof, stream=io.StringIO())
    rows = []
    for (path, line, function), (_, calls, own, cumulative, _) in stats.stats.items():  # type: ignore[attr-defined]
        rows.append(
            {
                "function": f"{_short(path)}:{line}({function})",
                "calls": calls,
                "own_s": own,
                "cumulative_s": cumulative,
                "core": "semwm._core." in function,
            }
        )
    rows.sort(key=lambda r: -r["own_s"])
    total_own = sum(r["own_s"] for r in rows)
    core_own = sum(r["own_s"] for r in rows if r["core"])
    return {
        "workload": label,
        "detections": detections,
        "calls_per_detection": sum(r["calls"] for r in rows) / detections,
        "profiled_s": total_own,
        "core_share": core_own / total_own if total_own else None,
        "top_own_time": rows[:TOP],
    }


def rust_profiles(batch: Any) -> list[dict[str, Any]]:
    """cProfiles of the Rust engine's ``ingest``: RoboCup 2 s, and the batches of 1,000."""
    from semwm.knowledge.loader import load_knowledge
    from semwm.sim.runner import scans
    from semwm.world import WorldModel

    found, knowledge = _scenario("robocup", SCENARIOS["robocup"])
    robocup = list(scans(found.detections))
    WorldModel(knowledge, engine="rust")

    def robocup_ingest() -> int:
        model = WorldModel(knowledge, engine="rust")
        for scan in robocup:
            model.ingest(scan)
        return sum(len(s) for s in robocup)

    batch_knowledge = load_knowledge(batch.knowledge)

    def batch_ingest() -> int:
        model = WorldModel(batch_knowledge, reorder_window=0.5, engine="rust")
        for request in batch.requests:
            model.ingest(request)
        return int(batch.detections)

    return [profile("robocup 2 s", robocup_ingest), profile(batch.name, batch_ingest)]


def _quarter(t: float, end: float) -> int:
    """The quarter of a match ending at ``end`` that a scan at ``t`` falls in
    (``end q / 4 < t <= end (q + 1) / 4``; the first also holds ``t <= 0``)."""
    return min(QUARTERS - 1, max(0, math.ceil(QUARTERS * t / end) - 1)) if end > 0 else 0


def long_split(name: str, duration: float) -> list[dict[str, Any]]:
    """The long match again, both engines, ``WorldModel.ingest`` by stage in each quarter
    (``bench_http.model_timers``: µs per detection of validate, core, publish, the rest),
    and the versions and hypotheses stored after each scan (the quarter's mean): what
    grows over the match. Not timed for the table (the timers cost a few µs per scan)."""
    from bench_http import model_timers

    from api import stages as timing
    from semwm.mhf.core_engine import CoreState
    from semwm.sim.runner import scans
    from semwm.world import WorldModel

    found, knowledge = _scenario(name, {"duration": duration})
    all_scans = list(scans(found.detections))
    end = max(max(d.time for d in scan) for scan in all_scans)
    rows = []
    for engine in ENGINES:
        model = WorldModel(knowledge, engine=engine)
        seconds: list[dict[str, float]] = [{} for _ in range(QUARTERS)]
        detections = [0] * QUARTERS
        versions: list[list[int]] = [[] for _ in range(QUARTERS)]
        hypotheses: list[list[int]] = [[] for _ in range(QUARTERS)]
        with model_timers():
            for scan in all_scans:
                q = _quarter(max(d.time for d in scan), end)
                stages, token = timing.start()
                try:
                    with timing.stage("model"):
                        model.ingest(scan)
                finally:
                    timing.stop(token)
                for key, value in stages.finish().items():
                    seconds[q][key] = seconds[q].get(key, 0.0) + value
                detections[q] += len(scan)
                state = model._state  # a benchmark's look inside: the core's count as is
                versions[q].append(
                    state.core.track_count if isinstance(state, CoreState) else len(state.tracks)
                )
                hypotheses[q].append(model.hypothesis_count)
        rows.append(
            {
                "engine": engine,
                "quarters": [
                    {
                        "quarter": q + 1,
                        "detections": detections[q],
                        "us_per_detection": {
                            key: value / detections[q] * 1e6 for key, value in seconds[q].items()
                        },
                        "versions_mean": float(np.mean(versions[q])),
                        "hypotheses_mean": float(np.mean(hypotheses[q])),
                    }
                    for q in range(QUARTERS)
                    if detections[q]
                ],
            }
        )
    return rows


ROOM_ALONE_REPEATS = 10
"""Runs of the room's scans alone (:func:`room_alone`); the best is reported."""


def room_alone(name: str, repeats: int = ROOM_ALONE_REPEATS) -> list[dict[str, Any]]:
    """The room's CPU per detection of its scans alone, each engine, beside the table's
    figure (the runner, interleaved with the other trackers' runs): its scans ingested
    back to back into a fresh model of knowledge loaded once, one timer around them all,
    no query between; the best of ``repeats`` runs."""
    from semwm.sim.runner import scans
    from semwm.world import WorldModel

    found, knowledge = _scenario(name, SCENARIOS[name])
    all_scans = list(scans(found.detections))
    detections = sum(len(scan) for scan in all_scans)
    rows = []
    for engine in ENGINES:
        alone = []
        for _ in range(repeats):
            model = WorldModel(knowledge, engine=engine)
            started = time.process_time()
            for scan in all_scans:
                model.ingest(scan)
            alone.append((time.process_time() - started) / detections * 1e6)
        rows.append(
            {
                "engine": engine,
                "detections": detections,
                "scans": len(all_scans),
                "scans_alone_us_per_detection": min(alone),
                "repeats": repeats,
            }
        )
    return rows


def stage_split(directory: Path, batch: Any, team_seconds: float) -> list[dict[str, Any]]:
    """``WorldModel.ingest`` by stage, both engines, without a profiler
    (``bench_http.model_timers``): µs per detection of validate, core, publish and the
    rest, on RoboCup 2 s, the static grid of 1,000, the batches and the team stream (each
    with the reorder window of its row in the table: 0.5 s for the batches, else 0)."""
    from bench_http import Case, _grid_knowledge, in_process_stages

    from semwm.detection import Detection
    from semwm.knowledge.shipped import shipped_knowledge_path
    from semwm.sim.runner import scans
    from semwm.sim.scenarios import make_scenario

    found, _ = _scenario("robocup", SCENARIOS["robocup"])
    path, _ = _grid_knowledge(1000, directory)
    grid_scenario = make_scenario("grid", 0, n_objects=1000, duration=2.9)
    team = [[Detection.model_validate(d) for d in b] for b in team_batches(team_seconds)]
    cases = [
        Case("robocup 2 s", "scans", shipped_knowledge_path(found.knowledge_file),
             list(scans(found.detections))),
        Case("static grid N = 1,000", "scans", path, list(scans(grid_scenario.detections)),
             warmup=GRID_WARMUP),
        batch,
        Case("team stream", "team", shipped_knowledge_path("sim1.yaml"), team, warmup=150),
    ]  # fmt: skip
    rows = []
    for case in cases:
        window = 0.5 if case is batch else 0.0
        for engine in ENGINES:
            seconds = in_process_stages(case, engine, window)
            n = case.detections
            rows.append(
                {
                    "workload": case.name,
                    "engine": engine,
                    "detections": n,
                    "requests": len(case.timed),
                    "us_per_detection": {k: v / n * 1e6 for k, v in seconds.items()},
                }
            )
    return rows


# --------------------------------------------------------------------- the run


def run(quick: bool, repeats: int) -> dict[str, Any]:
    from bench_http import Server, ServerSpec, batch_case

    from semwm.client import Client

    long_name, long_duration = QUICK_LONG if quick else LONG
    grid_timed = QUICK_GRID_TIMED if quick else GRID_TIMED
    team_seconds = QUICK_TEAM_SECONDS if quick else TEAM_SECONDS
    at_start = machine_info()
    started, load = at_start["date"], at_start["load_average"]
    doc: dict[str, Any] = {
        "benchmark": "speed",
        "quick": quick,
        "repeats": repeats,
        "sizes": {
            "scenarios": SCENARIOS,
            "long": {"scenario": long_name, "duration": long_duration, "quarters": QUARTERS},
            "longer": {"durations": [] if quick else list(LONGER), "runs": 1},
            "grid": {
                "n": list(GRID_SIZES),
                "warmup_frames": GRID_WARMUP,
                "timed_frames": grid_timed,
                "traced_frames": GRID_TRACED,
            },
            "team": {"seconds": team_seconds, "warmup_batches": 150},
            "batches": {
                "n": BATCHES if not quick else QUICK_BATCHES,
                "size": 1000,
                "grid_objects": 100,
            },
        },
        "notes": [
            "cpu: time.process_time around WorldModel.ingest (or the peer's ingest); wall: "
            "the runner's perf_counter of the ingest calls (the measure bench_trackers gives "
            "every tracker).",
            "Runs interleaved: Python engine, Rust engine, Stone Soup JPDA, repeated; each "
            "figure is the best of the repeats (the run least disturbed by other load).",
            "Each scenario run (the room, RoboCup, the long match) starts after "
            "gc.collect(), every tracker's alike; the collector stays on during the run.",
            "Batches over HTTP: semwm serve --engine E (started once per engine, through "
            "bench_http.py --serve: its world model's parts timed), one keep-alive client, "
            "wall det/s at the client (its JSON included).",
        ],
    }
    with tempfile.TemporaryDirectory() as folder:
        directory = Path(folder)
        batch = batch_case(directory, QUICK_BATCHES if quick else BATCHES)
        servers = {e: Server(batch.knowledge, ServerSpec(e, e)) for e in ENGINES}
        clients = {e: Client(s.url, timeout=120) for e, s in servers.items()}
        measured: dict[str, dict[str, list[Any]]] = {e: {} for e in (*ENGINES, JPDA)}

        def keep(label: str, key: str, value: Any) -> None:
            measured[label].setdefault(key, []).append(value)

        try:
            for engine in ENGINES:  # warm-up: imports, the servers' first allocations
                batches_over_http(batch, servers[engine], clients[engine])
            steps = [(r, label) for r in range(repeats) for label in (*ENGINES, JPDA)]
            for _, label in tqdm(steps, desc="speed", unit="run"):
                for name, sizes in SCENARIOS.items():
                    keep(label, name, _timed_run(name, sizes, label))
                if label == JPDA:
                    continue
                for n in GRID_SIZES:
                    one = grid(n, label, directory, grid_timed)
                    one.pop("model")
                    keep(label, f"grid{n}", one)
                keep(label, "team", team_stream(team_seconds, engine=label))
                keep(label, "batch", batches_in_process(batch, label))
                keep(label, "batch_http", batches_over_http(batch, servers[label], clients[label]))
                keep(label, "long", _timed_run(long_name, {"duration": long_duration}, label))
        finally:
            for client in clients.values():
                client.close()
            for server in servers.values():
                server.stop()
        results: dict[str, dict[str, Any]] = {}
        for label, by_key in measured.items():
            best: dict[str, Any] = {}
            for key, runs in by_key.items():
                if key in SCENARIOS or key == "long":
                    best[key] = _best_run(runs)
                elif key.startswith("grid"):
                    best[key] = min(runs, key=lambda r: r["ms_per_frame"])
                elif key == "team":
                    best[key] = min(runs, key=lambda r: r["cpu_ms_per_batch"])
                else:
                    best[key] = max(
                        runs,
                        key=lambda r: r[
                            "wall_det_per_s" if key == "batch_http" else "cpu_det_per_s"
                        ],
                    )
                best[key]["repeats"] = len(runs)
            results[label] = best
        doc["results"] = results
        doc["raw"] = measured
        doc["longer"] = [
            {"engine": engine, "duration": duration,
             **_timed_run(long_name, {"duration": duration}, engine)}
            for duration in ([] if quick else LONGER)
            for engine in tqdm(ENGINES, desc=f"{long_name} {duration:g} s", unit="run")
        ]  # fmt: skip
        doc["room_alone"] = room_alone("sim2")
        with tqdm(total=4, desc="memory, stages, profiles", unit="step") as bar:
            doc["memory"] = [
                row for engine in ENGINES
                for row in memory(directory, engine, GRID_SIZES[-1], SCENARIOS_FOR_MEMORY)
            ]  # fmt: skip
            bar.update()
            doc["stage_split"] = stage_split(directory, batch, team_seconds)
            bar.update()
            doc["long_split"] = long_split(long_name, long_duration)
            bar.update()
            doc["profiles"] = rust_profiles(batch)
            bar.update()
    doc["rows"] = table(doc)
    machine = machine_info()
    doc["machine"] = {
        **machine, "started": started, "finished": machine["date"], "load_at_start": load,
    }  # fmt: skip
    return doc


# --------------------------------------------------------------------- report


def _value(results: dict[str, Any], label: str, key: str) -> float | None:
    """The figure of ``key`` in its row's unit."""
    found = results.get(label, {}).get(key)
    if found is None:
        return None
    if key in SCENARIOS or key == "long":
        return float(found["cpu_us_per_detection"])
    if key == "grid50":
        return float(found["ms_per_frame"])
    if key == "grid1000":
        return float(found["us_per_detection"])
    if key == "team":
        return float(found["cpu_ms_per_batch"])
    if key == "batch":
        return float(found["cpu_det_per_s"])
    return float(found["wall_det_per_s"])


TARGET_VALUES = {"sim2": 100.0, "robocup": 100.0, "grid50": 0.1, "grid1000": 3.0, "team": 0.1,
                 "batch": 500_000.0, "batch_http": 200_000.0}  # fmt: skip


def table(doc: dict[str, Any]) -> list[dict[str, Any]]:
    """Issue 29's rows: each engine's figure, JPDA's, the ratios, the target, met or not
    (the Rust engine's, the default)."""
    results = doc["results"]
    rows = []
    for row in ROWS:
        python = _value(results, "python", row.key)
        rust = _value(results, "rust", row.key)
        jpda = _value(results, JPDA, row.key)
        speedup = None
        if python and rust:
            speedup = rust / python if row.higher_is_better else python / rust
        jpda_ratio = jpda / rust if jpda and rust else None
        met: bool | None
        if row.key in ("sim2", "robocup"):
            met = None if jpda_ratio is None else jpda_ratio >= TARGET_VALUES[row.key]
        elif row.key == "long":
            quarters = results.get("rust", {}).get("long", {}).get("quarters_cpu_us_per_detection")
            met = None if not quarters or None in quarters else quarters[-1] <= FLAT * quarters[0]
        elif rust is None:
            met = None
        elif row.higher_is_better:
            met = rust >= TARGET_VALUES[row.key]
        else:
            met = rust <= TARGET_VALUES[row.key]
        rows.append(
            {
                "key": row.key, "measure": row.measure, "unit": row.unit, "python": python,
                "rust": rust, "jpda": jpda, "rust_speedup": speedup, "jpda_over_rust": jpda_ratio,
                "target": row.target, "met": met,
            }
        )  # fmt: skip
    return rows


def _sizes(sizes: dict[str, Any]) -> str:
    return "; ".join(
        f"{name} " + ", ".join(f"{k} {v}" for k, v in value.items())
        for name, value in sizes.items()
    )


def _met(met: bool | None) -> str:
    return "—" if met is None else ("met" if met else "**not met**")


def _load(m: dict[str, Any]) -> str:
    """The machine's other work during the run: its 1-minute load average at the start
    and at the end (2 CPUs: a load of 1 is this benchmark alone)."""
    start, end = m.get("load_at_start"), m.get("load_average")
    if start is None or end is None:
        return "load not recorded"
    return f"1-minute load average {start[0]:g} at the start and {end[0]:g} at the end"


def markdown(doc: dict[str, Any]) -> str:
    m = doc["machine"]
    results = doc["results"]
    lines = [
        "# Speed: the Python engine, the Rust engine and Stone Soup JPDA (issue 29)",
        "",
        f"Machine: {m['platform']}, {m['cpu_count']} CPUs ({m.get('processor') or '?'}), "
        f"{_load(m)}, Python {m['python']}; run {m['started']} to "
        f"{m['finished']}, commit {str(m.get('commit'))[:10]}; versions: "
        + ", ".join(f"{k} {v}" for k, v in m["versions"].items())
        + f". Best of {doc['repeats']} interleaved runs{' (quick)' if doc['quick'] else ''}; "
        f"sizes: {_sizes(doc['sizes'])}. " + " ".join(doc["notes"]),
        "",
        "## Issue 29's table",
        "",
        "Speed-up: the Python engine's figure over the Rust engine's (for det/s the "
        "other way round): how many times faster the Rust engine is. JPDA / Rust: Stone "
        "Soup JPDA's CPU per detection over the Rust engine's. Met: the Rust engine (the "
        "default) against the target.",
        "",
        "| measure | unit | Python engine | Rust engine | Stone Soup JPDA | Rust speed-up "
        "| JPDA / Rust | target | met |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for r in doc["rows"]:
        lines.append(
            f"| {r['measure']} | {r['unit']} | {fmt(r['python'])} | {fmt(r['rust'])} | "
            f"{fmt(r['jpda'])} | {fmt(r['rust_speedup'])}x | "
            f"{fmt(r['jpda_over_rust']) + 'x' if r['jpda_over_rust'] else '—'} | "
            f"{r['target']} | {_met(r['met'])} |"
        )
    long = doc["sizes"]["long"]
    lines += [
        "",
        f"## The long match ({long['scenario']} {long['duration']:g} s): CPU µs per "
        "detection by quarter",
        "",
        f"Each quarter of the match's time, the best of the repeats; flat: the last quarter "
        f"within {100 * (FLAT - 1):.0f} % of the first.",
        "",
        "| engine | detections | whole match | "
        + " | ".join(f"Q{q + 1}" for q in range(QUARTERS))
        + " | last / first | highest / lowest | GOSPA | ID sw |",
        "|---|---|---|" + "---|" * QUARTERS + "---|---|---|---|",
    ]
    for engine in ENGINES:
        s = results[engine]["long"]
        q = s["quarters_cpu_us_per_detection"]
        growth = q[-1] / q[0] if q[0] and q[-1] else None
        known = [v for v in q if v]
        spread = max(known) / min(known) if known else None
        lines.append(
            f"| {engine} | {s['detections']} | {fmt(s['cpu_us_per_detection'])} | "
            + " | ".join(fmt(v) for v in q)
            + f" | {fmt(growth)} | {fmt(spread)} | {fmt(s['gospa'])} | {s['id_switches']} |"
        )
    if doc.get("longer"):
        lines += [
            "",
            "The same match longer, one run per engine and length (not the best of "
            "repeats): whether the cost per detection grows with the match's length.",
            "",
            "| engine | match | detections | whole match | "
            + " | ".join(f"Q{q + 1}" for q in range(QUARTERS))
            + " | last / first |",
            "|---|---|---|---|" + "---|" * QUARTERS + "---|",
        ]
        for s in doc["longer"]:
            q = s["quarters_cpu_us_per_detection"]
            growth = q[-1] / q[0] if q[0] and q[-1] else None
            lines.append(
                f"| {s['engine']} | {s['duration']:g} s | {s['detections']} | "
                f"{fmt(s['cpu_us_per_detection'])} | "
                + " | ".join(fmt(v) for v in q)
                + f" | {fmt(growth)} |"
            )
    if doc.get("long_split"):
        lines += [
            "",
            "What grows: the same match once more per engine with `WorldModel.ingest` timed "
            "by stage (`bench_http.model_timers`, as below; a pass of its own, not the one "
            "above), µs per detection in each quarter, and the object versions and "
            "hypotheses stored after a scan (the quarter's mean). Core per version: the "
            "core's µs per detection over the versions stored, what a detection costs per "
            "version in play (a scan predicts, gates and weighs every version): flat when "
            "the cost follows the scene's load and not the match's age.",
            "",
            "| engine | quarter | validate | core | publish | rest | versions stored | "
            "hypotheses stored | core per version |",
            "|---|---|---|---|---|---|---|---|---|",
        ]
        for r in doc["long_split"]:
            for quarter in r["quarters"]:
                u = quarter["us_per_detection"]
                core, versions = u.get("core"), quarter["versions_mean"]
                per_version = core / versions if core is not None and versions else None
                lines.append(
                    f"| {r['engine']} | Q{quarter['quarter']} | {fmt(u.get('validate'))} | "
                    f"{fmt(core)} | {fmt(u.get('publish'))} | "
                    f"{fmt(u.get('model'))} | {fmt(versions)} | "
                    f"{fmt(quarter['hypotheses_mean'])} | {fmt(per_version)} |"
                )
    if doc.get("room_alone"):
        lines += [
            "",
            "## The room: its scans alone beside the table's figure",
            "",
            "CPU µs per detection of the room (sim2). Scans alone: its scans ingested back "
            "to back into a fresh model, the knowledge loaded once, one timer around them "
            "all, nothing between (the best of "
            f"{doc['room_alone'][0]['repeats']} runs, after the other sections). The "
            "table: the benchmark's runner, the figure the target is judged by (the "
            "knowledge loaded afresh for each run, each ingest timed with process_time, "
            "the world queried at each truth frame and kept, the runs interleaved with the "
            "other trackers', each after gc.collect()). The difference is what the "
            "runner's setting adds to the scans' own cost (benchmarks/README.md, "
            '"Issue 29\'s speed targets, as measured", splits it).',
            "",
            "| engine | detections | scans alone | the table |",
            "|---|---|---|---|",
        ]
        for r in doc["room_alone"]:
            table_figure = results[r["engine"]]["sim2"]["cpu_us_per_detection"]
            lines.append(
                f"| {r['engine']} | {r['detections']} | "
                f"{fmt(r['scans_alone_us_per_detection'])} | {fmt(table_figure)} |"
            )
    lines += [
        "",
        "## Per detection, side by side with Stone Soup JPDA",
        "",
        "| scenario | detections | tracker | CPU µs/det | wall µs/det | JPDA / it (CPU) | "
        "GOSPA | ID sw |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for name, sizes in SCENARIOS.items():
        jpda = results[JPDA][name]
        for label in (*ENGINES, JPDA):
            s = results[label][name]
            ratio = jpda["cpu_us_per_detection"] / s["cpu_us_per_detection"]
            lines.append(
                f"| {name} {sizes or ''} | {s['detections']} | {label} | "
                f"{fmt(s['cpu_us_per_detection'])} | {fmt(s['wall_us_per_detection'])} | "
                f"{fmt(ratio)} | {fmt(s['gospa'])} | {s['id_switches']} |"
            )
    lines += [
        "",
        "## Static grid, team stream and batches",
        "",
        "| workload | engine | CPU ms/frame or batch | CPU µs/det | det/s | objects | hypotheses |",
        "|---|---|---|---|---|---|---|",
    ]
    for engine in ENGINES:
        for n in GRID_SIZES:
            g = results[engine][f"grid{n}"]
            lines.append(
                f"| static grid N = {n} ({g['frames_timed']} frames after {GRID_WARMUP}) | "
                f"{engine} | {fmt(g['ms_per_frame'])} | {fmt(g['us_per_detection'])} | "
                f"{fmt(1e6 / g['us_per_detection'])} | {g['objects']} | {g['hypotheses']} |"
            )
    for engine in ENGINES:
        t = results[engine]["team"]
        lines.append(
            f"| team stream in process ({t['batches']} batches after 150) | {engine} | "
            f"{fmt(t['cpu_ms_per_batch'])} | {fmt(t['cpu_us_per_detection'])} | "
            f"{fmt(1e6 / t['cpu_us_per_detection'])} | {t['objects']} | {t['hypotheses']} |"
        )
    for engine in ENGINES:
        b = results[engine]["batch"]
        h = results[engine]["batch_http"]
        lines.append(
            f"| batches of 1,000 in process ({b['requests']} batches) | {engine} | "
            f"{fmt(b['cpu_us_per_detection'])} | "  # ms per 1,000: µs per detection"
            f"{fmt(b['cpu_us_per_detection'])} | {fmt(b['cpu_det_per_s'])} | — | — |"
        )
        lines.append(
            f"| batches of 1,000 over HTTP ({h['requests']} batches; wall at the client) | "
            f"{engine} | — | {fmt(1e6 / h['wall_det_per_s'])} | {fmt(h['wall_det_per_s'])} | "
            "— | — |"
        )
    lines += [
        "",
        "## Where the time goes: `WorldModel.ingest` by stage, without a profiler",
        "",
        "µs per detection (`bench_http.model_timers`): validate (`_read`: `parse`, `check` "
        "and each detection's range and region check; with the Rust engine a plain batch in "
        "one pass of the core's reader, `_read_plain`), core (`_process_scans`, or "
        "`_ingest_scan` for a batch of one scan: the MHF scan, the confidences, the reorder "
        "log; the Rust engine's scan runs in the core), publish (`_publish`: ids and the "
        "published world), the rest of `ingest` (grouping into scans, the time bounds).",
        "",
        "| workload | engine | validate | core | publish | rest | whole ingest |",
        "|---|---|---|---|---|---|---|",
    ]
    for r in doc["stage_split"]:
        u = r["us_per_detection"]
        whole = sum(u.values())
        lines.append(
            f"| {r['workload']} | {r['engine']} | {fmt(u.get('validate'))} | {fmt(u.get('core'))} "
            f"| {fmt(u.get('publish'))} | {fmt(u.get('model'))} | {fmt(whole)} |"
        )
    lines += [
        "",
        "## Memory",
        "",
        "Bytes per stored object version: the Python engine's `Track` with its arrays "
        "(measured: `sys.getsizeof` of the Track, its four arrays and its sources); the "
        "Rust engine's version in the core (estimated from the structs of "
        "`core/src/mhf/state.rs` on 64 bits and each stored version's sizes, read from "
        "`semwm._core.State.versions`: the track table's B-tree entry, `Arc<Version>` "
        f"{VERSION_BYTES} B, `Arc<FilterState>` {FILTER_STATE_BYTES} B and its "
        "`M n + M n² + M` floats, the class probabilities `16 + 8 K` B and the sources "
        "`16 + 16 S` B; shared names and filter states counted per version, mimalloc's "
        "rounding not counted). tracemalloc sees Python's allocations only: with the Rust "
        "engine, the glue's. Peak: over 3 frames after the grid's timed ones; over the "
        "whole run for the scenario.",
        "",
        "| workload | engine | stored versions | bytes per version | how | hypotheses | "
        "clusters | tracemalloc peak MB |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for r in doc["memory"]:
        lines.append(
            f"| {r['workload']} | {r['engine']} | {r['versions']} | "
            f"{fmt(r['bytes_per_version'])} | {r['how']} | {r['hypotheses']} | "
            f"{r['clusters']} | {fmt(r['peak_traced_mb'])} |"
        )
    for p in doc["profiles"]:
        lines += [
            "",
            f"## Where the time goes: the Rust engine's ingest under cProfile, {p['workload']}",
            "",
            f"{p['detections']} detections, {fmt(p['calls_per_detection'])} Python calls per "
            f"detection, {fmt(p['profiled_s'])} s under the profiler, "
            f"{fmt(100 * p['core_share'] if p['core_share'] is not None else None)} % of it in "
            "the core's methods (`semwm._core`; the profiler slows Python calls more than the "
            "core's, so the Python share is overstated).",
            "",
            "| function | calls | own s | cumulative s |",
            "|---|---|---|---|",
        ]
        for r in p["top_own_time"]:
            lines.append(
                f"| `{r['function']}` | {r['calls']} | {fmt(r['own_s'])} | "
                f"{fmt(r['cumulative_s'])} |"
            )
    return "\n".join(lines) + "\n"


def figure(doc: dict[str, Any], path: Path) -> None:
    """``doc``'s run drawn (``speed.png`` beside the results): CPU per detection of the
    three trackers on the room and RoboCup, log scale, with 100x JPDA marked; the long
    match's cost per detection by quarter with the Rust engine at each length; and the 8 s
    match's versions in play by quarter beside the core's cost per version in play."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    results = doc["results"]
    trackers = [
        ("python", "Python engine", "tab:blue"),
        ("rust", "Rust engine", "tab:orange"),
        (JPDA, "Stone Soup JPDA", "tab:gray"),
    ]
    fig, (bars, long, per_version) = plt.subplots(1, 3, figsize=(15, 4.6))
    cases = [("sim2", "the room (sim2)"), ("robocup", "RoboCup 2 s")]
    width = 0.26
    for k, (label, name, colour) in enumerate(trackers):
        values = [results[label][key]["cpu_us_per_detection"] for key, _ in cases]
        xs = [i + (k - 1) * width for i in range(len(cases))]
        bars.bar(xs, values, width, label=name, color=colour)
        for x, value in zip(xs, values, strict=True):
            text = f"{value:,.0f}" if value >= 100 else f"{value:.3g}"
            bars.text(x, value * 1.12, text, ha="center", fontsize=8)
    for i, (key, _) in enumerate(cases):
        target = results[JPDA][key]["cpu_us_per_detection"] / 100.0
        bars.hlines(
            target,
            i - 1.6 * width,
            i + 1.6 * width,
            colors="tab:red",
            linestyles="--",
            label="target: JPDA / 100" if i == 0 else None,
        )
    bars.set_yscale("log")
    highest = max(
        results[label][key]["cpu_us_per_detection"] for label, _, _ in trackers for key, _ in cases
    )
    bars.set_ylim(top=highest * 12)  # room for the legend above the bars
    bars.set_xticks(range(len(cases)), [name for _, name in cases])
    bars.set_xlim(-0.6, len(cases) - 0.1)
    bars.set_ylabel("CPU µs per detection (log scale)")
    bars.set_title("Per detection, side by side")
    bars.legend(fontsize=8, loc="upper left")

    quarters = [1, 2, 3, 4]
    long_name = doc["sizes"]["long"]["duration"]
    runs = [(long_name, results["rust"]["long"]["quarters_cpu_us_per_detection"])]
    runs += [
        (row["duration"], row["quarters_cpu_us_per_detection"])
        for row in doc.get("longer", [])
        if row["engine"] == "rust"
    ]
    for duration, values in runs:
        long.plot(quarters, values, marker="o", label=f"{duration:g} s match")
    long.set_xticks(quarters, [f"Q{q}" for q in quarters])
    long.set_ylim(bottom=0)
    long.set_ylabel("CPU µs per detection")
    long.set_title("RoboCup, the Rust engine, by quarter of the match")
    long.legend(fontsize=8)

    split = next((row for row in doc.get("long_split", []) if row["engine"] == "rust"), None)
    if split is not None:
        versions = [q["versions_mean"] for q in split["quarters"]]
        core = [q["us_per_detection"]["core"] for q in split["quarters"]]
        per_version.bar(quarters, versions, color="tab:green", alpha=0.5)
        per_version.set_ylabel("object versions stored (mean)", color="tab:green")
        per_version.set_xticks(quarters, [f"Q{q}" for q in quarters])
        cost = per_version.twinx()
        cost.plot(quarters, [c / v for c, v in zip(core, versions, strict=True)], "o-", color="k")
        cost.set_ylim(bottom=0)
        cost.set_ylabel("core µs per detection per version stored")
        per_version.set_title(f"{long_name:g} s match: the scene's load, the cost per version")
    machine = doc["machine"]
    started = machine["started"][:16].replace("T", " ")
    fig.suptitle(
        f"bench_speed, {started} UTC, {machine.get('cpu_count', '?')} cores, "
        f"best of {doc['repeats']} interleaved runs",
        fontsize=9,
    )
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)
    print(f"wrote {path}")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument(
        "--quick", action="store_true", help="shorter runs, one repeat (under 3 minutes)"
    )
    parser.add_argument(
        "--repeats",
        type=int,
        default=None,
        help="interleaved runs per measure, the best kept (default 3; 1 with --quick)",
    )
    add_output_arguments(parser)
    args = parser.parse_args(argv)
    repeats = args.repeats if args.repeats is not None else (1 if args.quick else 3)
    doc = run(args.quick, repeats)
    target = write_results(
        RESULTS, "speed", doc, markdown(doc), args.quick, update_results=args.update_results
    )
    figure(doc, target / ("speed_quick.png" if args.quick else "speed.png"))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
