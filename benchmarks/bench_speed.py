"""Speed of the in-process core (issue 10): a profile-driven report, before and after.

One command measures, in one run and on the same data:

* the current core (this checkout) and a baseline core (``--baseline REF``, default
  ``main``: the commit where this checkout left that ref, ``git merge-base REF HEAD``,
  exported to a temporary folder and imported in a subprocess in place of this
  checkout's ``semwm``), each on
  - sim2 and robocup (2 s), seed 0: CPU µs per detection of the ingest calls
    (``time.process_time``; the best of ``--repeats`` runs) and wall µs per detection
    as the runner reports it (``semwm.sim.runner.run_scenario``, the measure every
    tracker gets in ``bench_trackers.py``);
  - a cProfile of the robocup ingest calls: Python calls per detection and the top
    functions by own time;
  - the static grid (``bench_scaling.grid_size``) of N = 50, 100, 1000 objects: CPU ms per
    frame, µs per detection (best of the repeats), ``tracemalloc`` peak over 3 frames;
* Stone Soup JPDA on sim2 and robocup, timed the same two ways.

The runs of the scenarios are interleaved (baseline, current, JPDA, and again), so
that all three see the same load on a shared machine: compare the ratios, measured
side by side, rather than absolute times across days.

Writes ``speed.json`` and ``speed.md`` to ``benchmarks/out/`` (``benchmarks/results/``
with ``--update-results``).

    python benchmarks/bench_speed.py [--quick] [--baseline REF|none] [--update-results]
"""

from __future__ import annotations

import argparse
import cProfile
import io
import json
import os
import pstats
import subprocess
import sys
import tarfile
import tempfile
import time
import tracemalloc
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))

from baselines import RESULTS, add_output_arguments, fmt, machine_info, write_results

SCENARIOS: dict[str, dict[str, Any]] = {"sim2": {}, "robocup": {"duration": 2.0}}
LONG_SCENARIOS: dict[str, dict[str, Any]] = {"robocup": {"duration": 8.0}}
"""Measured for the semwm cores only: Stone Soup JPDA needs tens of CPU minutes for
RoboCup beyond a few seconds on this kind of machine, while semwm's cost per detection
grows as the hypotheses of a long match accumulate (the twin merging's share)."""
GRID_SIZES = (50, 100, 1000)
QUICK_GRID_SIZES = (50, 100)
TOP = 12
CHANGES = (
    "Near pairs at scale (`semwm/mhf/nearby.py`): above 4,096 pairs, gating a scan and "
    "grouping the lineages that are one object ask a k-d tree (scipy's cKDTree) for the "
    "pairs within a widened radius, then apply the exact bound, in the dense test's "
    "order (was a (D, T, d) and an (N, N, d) difference array per scan). Published "
    "objects are named tuples.",
    "Updates: one Kalman/IMM update per filter shape ``(M, n)`` for every gated pair of "
    "the scan (was one per class: the equations are the same for every class of one "
    "shape), the class posterior and published class of every pair in one call (was one "
    "per class).",
    "Twins (`semwm/mhf/similar.py`): the versions of every lineage with a twin candidate "
    "compared in one numpy expression per state shape (was one expression per lineage: 15 "
    "numpy calls each), over the pairs within one lineage only (was every pair of the "
    "batch); hypotheses holding the same objects merged with one boolean matrix per group "
    "(was a Python `all()` over every object for every pair of kept hypotheses: 4.1 M "
    "generator steps in 8 s of RoboCup).",
    "Reorder log: where a scan goes found by bisection, and not at all when it comes after "
    "the whole log (was a generator over the log per ingest).",
    "Ghost lineages (`semwm/mhf/rates.py`): the stream that started a lineage in any "
    "hypothesis sees it, and one with no detection but its first is seen by that stream "
    "while it scans within reach: a team's outliers go within a few scans instead of "
    "fading at the class's rate for seconds (stored versions of the team stream 40 -> 26; "
    "worlds change, quality over 20 seeds in `quality.md`).",
    "Rates and removal: the observed rate of an object computed once for all its versions; "
    "leave rates looked up per class with the relations only where a class has any; "
    "objects leaving (P_max, time unseen, existence, removed class) decided with arrays "
    "(was a Python loop per version); region bounds made once.",
    "Values: `Track` is a plain slots dataclass (a frozen one sets its 12 fields through "
    "`object.__setattr__`: 2.2 µs against 0.4 µs per version), `Hypothesis` and `Cluster` "
    "named tuples. World: stored positions of one-mode versions without a mixture, "
    "same-object pairs without `np.triu`.",
    "Zeroth-order Kalman filters predict as x- = x, P- = P + Q(dt) (the general "
    "equations' result with F = I, bit for bit, without their matrix products: 57 -> 9 µs "
    "for 10 static objects); new objects' initial covariances filled in place (was "
    "`np.broadcast_to` and a copy); `DetectionOptions` a named tuple; the time-uncertainty "
    "terms of gating built only when a detection has one; grouping the lineages that are "
    "one object stops when no two estimates are near each other.",
    "Twins, a cheap necessary bound first: two versions of a lineage are compared in full "
    "only when their first-mode states are within sqrt(merge_distance * trace(P)) (in a "
    "long match a lineage has up to 120 versions, 15,000 ordered pairs, one in eight "
    "within the bound); the detections' range check computes its chi-square quantile once.",
    "The garbage collector paused during `WorldModel.ingest` (`semwm/collector.py`): a scan "
    "allocates thousands of short-lived acyclic containers, and every hundredth young "
    "collection walked every live object of the process (about 20 % of a large grid's "
    "frame); predictions keep their per-track lists unmade until read (was four array "
    "views per track per scan).",
    "A scan's certain updates settled at once (`SettledUpdate`, `semwm/mhf/association.py`): "
    "a detection that gates one object no other detection gates, alone and certain in its "
    "cluster, in a scan without labels or appearance relations, whose 'new object or "
    "clutter' falls below eq. (3)'s floor, updates it without options or a new-object "
    "track (was one `DetectionOptions`, one unused new track and the per-detection "
    "certainty test for each). Worlds bit-identical (8 scenarios x 3 seeds). The same "
    "session moved the service's cost, not the core's: `semwm.client` parses answers with "
    "httptools, and synchronised scans keep their stamps (`bench_http`).",
)


# --------------------------------------------------------------------- one core


def _scenario(name: str, sizes: dict[str, Any] | None = None) -> tuple[Any, Any]:
    from semwm.knowledge.loader import load_knowledge
    from semwm.knowledge.shipped import shipped_knowledge_path
    from semwm.sim.scenarios import make_scenario

    scenario = make_scenario(name, 0, **(SCENARIOS[name] if sizes is None else sizes))
    return scenario, load_knowledge(shipped_knowledge_path(scenario.knowledge_file))


class _CpuTimed:
    """A tracker whose ``ingest`` calls are timed in CPU seconds (``process_time``),
    optionally under a profiler; everything else is delegated."""

    def __init__(self, tracker: Any, profile: cProfile.Profile | None = None) -> None:
        self._tracker = tracker
        self._profile = profile
        self.cpu_s = 0.0

    def ingest(self, scan: Any) -> Any:
        if self._profile is not None:
            self._profile.enable()
        start = time.process_time()
        try:
            return self._tracker.ingest(scan)
        finally:
            self.cpu_s += time.process_time() - start
            if self._profile is not None:
                self._profile.disable()

    def __getattr__(self, name: str) -> Any:
        return getattr(self._tracker, name)


def _timed_run(
    name: str,
    tracker: str = "semwm",
    profile: cProfile.Profile | None = None,
    sizes: dict[str, Any] | None = None,
) -> dict[str, Any]:
    """One run of a tracker on a scenario (``sizes``: else :data:`SCENARIOS`'): CPU of
    its ingest calls, and the runner's wall."""
    from semwm.sim.runner import run_scenario
    from semwm.world import WorldModel

    scenario, knowledge = _scenario(name, sizes)
    if tracker == "semwm":
        WorldModel(knowledge)  # lazy imports outside the measured calls
        build: Any = WorldModel
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
    return {
        "detections": n,
        "cpu_us_per_detection": timed[0].cpu_s / n * 1e6,
        "wall_us_per_detection": result.metrics.time_per_detection["mean_s"] * 1e6,
        "gospa": result.metrics.gospa.total,
        "id_switches": result.metrics.id_switches,
    }


def _best_grid(rows: tuple[dict[str, Any], ...]) -> dict[str, Any]:
    """The repeat of one grid size with the lowest CPU per frame."""
    done = [r for r in rows if r["ms_per_frame"] is not None]
    return min(done, key=lambda r: r["ms_per_frame"]) if done else rows[0]


def _best(runs: list[dict[str, Any]]) -> dict[str, Any]:
    return {
        "detections": runs[0]["detections"],
        "cpu_us_per_detection": min(r["cpu_us_per_detection"] for r in runs),
        "wall_us_per_detection": min(r["wall_us_per_detection"] for r in runs),
        "gospa": runs[0]["gospa"],
        "id_switches": runs[0]["id_switches"],
    }


def _profile(name: str) -> dict[str, Any]:
    profile = cProfile.Profile()
    run = _timed_run(name, "semwm", profile)
    stats = pstats.Stats(profile, stream=io.StringIO())
    rows = []
    for (path, line, function), (_, calls, own, cumulative, _) in stats.stats.items():  # type: ignore[attr-defined]
        rows.append(
            {
                "function": f"{_short(path)}:{line}({function})",
                "calls": calls,
                "own_s": own,
                "cumulative_s": cumulative,
            }
        )
    rows.sort(key=lambda r: -r["own_s"])
    total_calls = sum(r["calls"] for r in rows)
    total_own = sum(r["own_s"] for r in rows)
    return {
        "scenario": name,
        "detections": run["detections"],
        "calls_per_detection": total_calls / run["detections"],
        "profiled_s": total_own,
        "top_own_time": rows[:TOP],
    }


def _short(path: str) -> str:
    for marker in ("site-packages/", "/semwm/", "lib/python3"):
        if marker in path:
            tail = path.split(marker, 1)[1]
            return ("semwm/" + tail) if marker == "/semwm/" else tail
    return path


def _grid(n: int) -> dict[str, Any]:
    import bench_scaling

    frames_ok = bench_scaling.grid_size(n, size_limit=60.0, warmup=10, timed=10)
    return {
        "n": n,
        "status": frames_ok["status"],
        "ms_per_frame": frames_ok["steady_cpu_ms_per_frame"],
        "us_per_detection": frames_ok["steady_cpu_us_per_detection"],
        "peak_traced_mb": frames_ok["peak_traced_mb_steady_frames"],
        "hypotheses": frames_ok["hypotheses_last"],
        "objects": frames_ok["objects_last"],
    }


def team_stream(seconds: float = 6.0, warmup_batches: int = 150) -> dict[str, Any]:
    """The team's stream of ``bench_teamload`` in process: 5 robots x 10 detections x
    30 Hz on 20 shared objects (``sim1.yaml``), one ``ingest`` per robot's batch; CPU
    per batch after a warm-up (the mean of the timed batches)."""
    import numpy as np
    from bench_teamload import NOISE, OBJECTS, PER_BATCH, RATE_HZ, ROBOTS

    from semwm.knowledge.loader import load_knowledge
    from semwm.knowledge.shipped import shipped_knowledge_path
    from semwm.world import WorldModel

    world = WorldModel(load_knowledge(shipped_knowledge_path("sim1.yaml")))
    rngs = [np.random.default_rng(robot) for robot in range(ROBOTS)]
    seen = [[OBJECTS[(2 * r + k) % len(OBJECTS)] for k in range(PER_BATCH)] for r in range(ROBOTS)]
    batches = []
    for tick in range(int(seconds * RATE_HZ)):
        for r in range(ROBOTS):
            noise = rngs[r].normal(0.0, NOISE, size=(PER_BATCH, 2))
            batches.append(
                [
                    {"time": tick / RATE_HZ + r * 1e-3, "class": cls, "source": f"r{r}",
                     "position": [x + noise[k, 0], y + noise[k, 1]]}
                    for k, (cls, (x, y)) in enumerate(seen[r])
                ]
            )  # fmt: skip
    for batch in batches[:warmup_batches]:
        world.ingest(batch)
    timed = batches[warmup_batches:]
    start = time.process_time()
    for batch in timed:
        world.ingest(batch)
    cpu = time.process_time() - start
    return {
        "batches": len(timed),
        "detections_per_batch": PER_BATCH,
        "cpu_ms_per_batch": cpu / len(timed) * 1e3,
        "cpu_us_per_detection": cpu / (len(timed) * PER_BATCH) * 1e6,
        "objects": len(world.world().objects),
        "hypotheses": world.hypothesis_count,
        "offered_det_per_s": ROBOTS * PER_BATCH * RATE_HZ,
    }


def measure_core(part: str, grid_sizes: tuple[int, ...]) -> dict[str, Any]:
    """One part (``scenarios``: one run of each; ``profile``; ``grid``) measured of the
    ``semwm`` this interpreter imports."""
    import semwm

    result: dict[str, Any] = {"semwm_path": str(Path(semwm.__file__).resolve().parent)}
    if part == "scenarios":
        result["scenarios"] = {name: _timed_run(name) for name in SCENARIOS}
        result["long"] = {
            name: _timed_run(name, sizes=sizes) for name, sizes in LONG_SCENARIOS.items()
        }
        result["team_stream"] = team_stream()
    elif part == "profile":
        result["profile"] = _profile("robocup")
    else:
        result["grid"] = [_grid(n) for n in grid_sizes]
    return result


# --------------------------------------------------------------------- peers, driver


def _core_in_subprocess(source: Path, part: str, grid_sizes: tuple[int, ...]) -> dict[str, Any]:
    """:func:`measure_core` with ``source`` (a checkout's root) first on the path."""
    with tempfile.NamedTemporaryFile(suffix=".json", delete=False) as handle:
        target = Path(handle.name)
    env = {**os.environ, "PYTHONPATH": str(source)}
    subprocess.run(
        [
            sys.executable,
            str(Path(__file__).resolve()),
            "--measure-core",
            str(target),
            "--part",
            part,
            "--grid",
            *map(str, grid_sizes),
        ],
        check=True,
        env=env,
    )
    result: dict[str, Any] = json.loads(target.read_text())
    target.unlink()
    return result


def _export(ref: str, folder: Path) -> str:
    """The tree of the commit where this checkout left ``ref`` (``git merge-base ref HEAD``)
    into ``folder``; returns that commit."""
    root = Path(__file__).resolve().parents[1]
    commit = subprocess.run(
        ["git", "merge-base", ref, "HEAD"], capture_output=True, text=True, check=True, cwd=root
    ).stdout.strip()
    archive = subprocess.run(
        ["git", "archive", "--format=tar", commit], capture_output=True, check=True, cwd=root
    ).stdout
    with tarfile.open(fileobj=io.BytesIO(archive)) as tar:
        tar.extractall(folder, filter="data")
    return commit


def run(quick: bool, baseline: str, repeats: int) -> dict[str, Any]:
    grid_sizes = QUICK_GRID_SIZES if quick else GRID_SIZES
    root = Path(__file__).resolve().parents[1]
    doc: dict[str, Any] = {
        "benchmark": "speed",
        "quick": quick,
        "machine": machine_info(),
        "repeats": repeats,
        "changes": list(CHANGES),
        "scenarios": {name: sizes for name, sizes in SCENARIOS.items()},
        "long_scenarios": {name: sizes for name, sizes in LONG_SCENARIOS.items()},
        "notes": [
            "cpu: time.process_time around WorldModel.ingest; wall: the runner's perf_counter "
            "of the ingest calls (the measure bench_trackers gives every tracker); best of "
            "the repeats.",
            "Runs interleaved: baseline core, current core, Stone Soup JPDA, repeated; each "
            "figure is the best of the repeats (the run least disturbed by other load).",
            "grid: bench_scaling.grid_size with 10 warm-up and 10 timed frames; peak: "
            "tracemalloc over 3 frames after the timed ones.",
        ],
    }
    cores = {"current": root}
    with tempfile.TemporaryDirectory() as folder:
        if baseline != "none":
            commit = _export(baseline, Path(folder))
            cores["baseline"] = Path(folder)
            doc["baseline"] = {"ref": baseline, "commit": commit}
        doc["current"] = {}
        # repeats interleaved (baseline, JPDA, current), so that all three see the same load
        runs: dict[str, list[dict[str, Any]]] = {}
        streams: dict[str, list[dict[str, Any]]] = {label: [] for label in cores}
        longs: dict[str, list[dict[str, Any]]] = {label: [] for label in cores}
        grids: dict[str, list[list[dict[str, Any]]]] = {label: [] for label in cores}
        for repeat in range(repeats):
            for label in [*cores, "stonesoup_jpda"]:
                print(f"run {repeat + 1}/{repeats}: {label} ...", flush=True)
                if label == "stonesoup_jpda":
                    one = {name: _timed_run(name, label) for name in SCENARIOS}
                else:
                    measured = _core_in_subprocess(cores[label], "scenarios", grid_sizes)
                    one = measured["scenarios"]
                    streams[label].append(measured["team_stream"])
                    longs[label].append(measured["long"])
                    grids[label].append(
                        _core_in_subprocess(cores[label], "grid", grid_sizes)["grid"]
                    )
                for name, values in one.items():
                    runs.setdefault(f"{label}/{name}", []).append(values)
        doc["stonesoup_jpda"] = {name: _best(runs[f"stonesoup_jpda/{name}"]) for name in SCENARIOS}
        for label, source in cores.items():
            doc[label]["scenarios"] = {name: _best(runs[f"{label}/{name}"]) for name in SCENARIOS}
            doc[label]["grid"] = [_best_grid(rows) for rows in zip(*grids[label], strict=True)]
            doc[label]["team_stream"] = min(streams[label], key=lambda r: r["cpu_ms_per_batch"])
            doc[label]["long"] = {
                name: _best([one[name] for one in longs[label]]) for name in LONG_SCENARIOS
            }
            print(f"{label}: profile ...", flush=True)
            measured = _core_in_subprocess(source, "profile", grid_sizes)
            doc[label]["profile"] = measured["profile"]
            doc[label]["semwm_path"] = measured["semwm_path"]
    return doc


# --------------------------------------------------------------------- report


def _ratio(a: float | None, b: float | None) -> float | None:
    return a / b if a is not None and b else None


def markdown(doc: dict[str, Any]) -> str:
    m = doc["machine"]
    current, jpda = doc["current"], doc["stonesoup_jpda"]
    base = doc.get("baseline")
    lines = [
        "# Speed of the core: before and after (issue 10)",
        "",
        f"Machine: {m['platform']}, {m['cpu_count']} CPUs ({m.get('processor') or '?'}), "
        f"Python {m['python']}, {m['date']}; versions: "
        + ", ".join(f"{k} {v}" for k, v in m["versions"].items()),
        "",
        f"Current: commit {str(m.get('commit'))[:10]}"
        + (f"; baseline: {base['ref']} ({base['commit'][:10]})" if base else "")
        + f"; best of {doc['repeats']} runs{' (quick)' if doc['quick'] else ''}. "
        + " ".join(doc["notes"]),
        "",
        "## What changed",
        "",
        *[f"* {change}" for change in doc.get("changes", CHANGES)],
        "",
        "## Per detection, side by side with Stone Soup JPDA",
        "",
        "| scenario | detections | core | semwm CPU µs/det | JPDA CPU µs/det "
        "| JPDA / semwm (CPU) | semwm wall µs/det | JPDA wall µs/det | JPDA / semwm (wall) "
        "| GOSPA | ID sw |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for name, sizes in doc["scenarios"].items():
        cores = [("baseline", base)] if base else []
        cores.append(("current", current))
        j = jpda[name]
        for label, core in cores:
            s = core["scenarios"][name]
            lines.append(
                f"| {name} {sizes or ''} | {s['detections']} | {label} | "
                f"{fmt(s['cpu_us_per_detection'])} | {fmt(j['cpu_us_per_detection'])} | "
                f"{fmt(_ratio(j['cpu_us_per_detection'], s['cpu_us_per_detection']))} | "
                f"{fmt(s['wall_us_per_detection'])} | {fmt(j['wall_us_per_detection'])} | "
                f"{fmt(_ratio(j['wall_us_per_detection'], s['wall_us_per_detection']))} | "
                f"{fmt(s['gospa'])} | {s['id_switches']} |"
            )
    longs = [
        (label, core["long"])
        for label, core in ([("baseline", base)] if base else []) + [("current", current)]
        if core.get("long")
    ]
    if longs:
        lines += [
            "",
            "## A longer match, semwm only",
            "",
            "Stone Soup JPDA is not run here: it needs tens of CPU minutes for RoboCup beyond "
            "a few seconds. semwm's cost per detection grows over a match as hypotheses "
            "accumulate; this row shows that growth and what the core changes do to it.",
            "",
            "| scenario | detections | core | semwm CPU µs/det | semwm wall µs/det | GOSPA "
            "| ID sw |",
            "|---|---|---|---|---|---|---|",
        ]
        for name, sizes in doc.get("long_scenarios", {}).items():
            for label, runs_ in longs:
                s = runs_[name]
                lines.append(
                    f"| {name} {sizes} | {s['detections']} | {label} | "
                    f"{fmt(s['cpu_us_per_detection'])} | {fmt(s['wall_us_per_detection'])} | "
                    f"{fmt(s['gospa'])} | {s['id_switches']} |"
                )
    lines += [
        "",
        "## Static grid (all N objects detected every frame, 10 Hz)",
        "",
        "| N | core | CPU ms/frame | µs/det | peak MB | hypotheses | objects | status |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for row, g in enumerate(current["grid"]):
        cores = [("baseline", base["grid"][row])] if base else []
        cores.append(("current", g))
        for label, c in cores:
            lines.append(
                f"| {c['n']} | {label} | {fmt(c['ms_per_frame'])} | "
                f"{fmt(c['us_per_detection'])} | {fmt(c['peak_traced_mb'])} | "
                f"{c['hypotheses']} | {c['objects']} | {c['status']} |"
            )
    streams = [
        (label, core["team_stream"])
        for label, core in ([("baseline", base)] if base else []) + [("current", current)]
        if core.get("team_stream") is not None
    ]
    lines += (
        []
        if not streams
        else [
            "",
            "## A team's stream in process (issue 15's load without HTTP)",
            "",
            "5 robots x 10 detections x 30 Hz on 20 shared objects (`sim1.yaml`, "
            "`bench_teamload`'s layout), one `ingest` per robot's batch, 6 s; CPU after 150 "
            "warm-up batches. Real time needs at most 6.67 ms per batch on one core.",
            "",
            "| core | batches | CPU ms/batch | µs/det | det/s one core sustains | objects | "
            "hypotheses |",
            "|---|---|---|---|---|---|---|",
        ]
    )
    for label, t in streams:
        lines.append(
            f"| {label} | {t['batches']} | {fmt(t['cpu_ms_per_batch'])} | "
            f"{fmt(t['cpu_us_per_detection'])} | {fmt(1e6 / t['cpu_us_per_detection'])} | "
            f"{t['objects']} | {t['hypotheses']} |"
        )
    for label, core in ([("baseline", base)] if base else []) + [("current", current)]:
        p = core["profile"]
        lines += [
            "",
            f"## Where the time goes: {label} core, cProfile of {p['scenario']} ingest",
            "",
            f"{p['detections']} detections, {fmt(p['calls_per_detection'])} Python calls per "
            f"detection, {fmt(p['profiled_s'])} s under the profiler.",
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


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true", help="grid N = 50, 100 only")
    parser.add_argument(
        "--baseline",
        default="main",
        help="git ref of the core to compare with, or 'none' (default: main)",
    )
    parser.add_argument("--repeats", type=int, default=3, help="runs per measure (best kept)")
    parser.add_argument("--measure-core", type=Path, help=argparse.SUPPRESS)
    parser.add_argument("--part", default="scenarios", help=argparse.SUPPRESS)
    parser.add_argument(
        "--grid", type=int, nargs="*", default=list(GRID_SIZES), help=argparse.SUPPRESS
    )
    add_output_arguments(parser)
    args = parser.parse_args(argv)
    if args.measure_core is not None:
        tracemalloc.stop()
        result = measure_core(args.part, tuple(args.grid))
        args.measure_core.write_text(json.dumps(result, indent=2) + "\n")
        return 0
    doc = run(args.quick, args.baseline, args.repeats)
    write_results(
        RESULTS, "speed", doc, markdown(doc), args.quick, update_results=args.update_results
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
