"""Scaling of semwm: a static grid of N objects, all detected every frame at 10 Hz,
and the hypothesis budget on robocup.

Grid (``make_scenario("grid", n_objects=N)``, knowledge ``grid.yaml`` with its
``world.region`` set to the scenario's region so that it covers every object):
each 10 Hz frame is one scan, fed to ``semwm.WorldModel.ingest``. CPU time per
frame is ``time.process_time`` around the ingest call; the steady state is the
mean over the frames after ``WARMUP`` frames. Each size stops when its CPU time
exceeds ``--size-limit`` (default 60 s) and is then recorded as ``timeout`` with
the frames it got through. Recorded per frame: CPU ms, hypotheses, objects of the
best hypothesis (vs N). Memory: ``tracemalloc`` peak over ``MEM_FRAMES`` extra
frames after the timed ones (allocations made during those frames), and the
process' ``ru_maxrss`` high-water mark after the size (sizes run in increasing
order, so it is cumulative).

Hypothesis budget: robocup (seed 0) with ``world.max_hypotheses`` = 1, 10, 100,
1000: GOSPA, ID switches and wall time per detection (``run_scenario``).

Writes ``scaling.json`` and ``scaling.md`` to ``benchmarks/out/`` (``benchmarks/results/``
with ``--update-results``).

    python benchmarks/bench_scaling.py [--quick]
"""

from __future__ import annotations

import argparse
import resource
import sys
import time
import tracemalloc
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from baselines import RESULTS, add_output_arguments, fmt, machine_info, write_results
from tqdm import tqdm

from semwm.knowledge.loader import load_knowledge
from semwm.knowledge.model import Knowledge
from semwm.knowledge.shipped import shipped_knowledge_path
from semwm.sim.runner import run_scenario, scans
from semwm.sim.scenarios import make_scenario
from semwm.world import WorldModel

SIZES = (10, 30, 50, 100, 200, 500)
WARMUP = 20
TIMED = 30
MEM_FRAMES = 3
BUDGETS = (1, 10, 100, 1000)


def _with_world(knowledge: Knowledge, **update: Any) -> Knowledge:
    world = knowledge.world.model_copy(update=update)
    return knowledge.model_copy(update={"world": world})


def grid_size(n: int, *, size_limit: float, warmup: int, timed: int) -> dict[str, Any]:
    frames_total = warmup + timed + MEM_FRAMES
    scenario = make_scenario("grid", 0, n_objects=n, duration=(frames_total - 1) / 10.0)
    base = load_knowledge(shipped_knowledge_path(scenario.knowledge_file))
    knowledge = _with_world(base, region=tuple(tuple(r) for r in scenario.region))
    model = WorldModel(knowledge, reorder_window=0.0)
    all_scans = list(scans(scenario.detections))
    cpu_ms: list[float] = []
    hyps: list[int] = []
    objects: list[int] = []
    used = 0.0
    status = "ok"
    peak_mb = None
    for k, scan in enumerate(all_scans):
        traced = k >= warmup + timed
        if traced and k == warmup + timed:
            tracemalloc.start()
        t0 = time.process_time()
        model.ingest(scan)
        dt = time.process_time() - t0
        used += dt
        cpu_ms.append(dt * 1e3)
        hyps.append(model.hypothesis_count)
        objects.append(model.object_count)
        if used > size_limit:
            status = "timeout"
            break
    if tracemalloc.is_tracing():
        peak_mb = tracemalloc.get_traced_memory()[1] / 1e6
        tracemalloc.stop()
    steady = cpu_ms[warmup : warmup + timed]
    first_full = next((i for i, o in enumerate(objects) if o >= n), None)
    out: dict[str, Any] = {
        "n": n,
        "status": status,
        "frames_done": len(cpu_ms),
        "frames_planned": len(all_scans),
        "cpu_s_used": used,
        "steady_cpu_ms_per_frame": float(np.mean(steady)) if len(steady) == timed else None,
        "steady_cpu_us_per_detection": float(np.mean(steady)) * 1e3 / n
        if len(steady) == timed
        else None,
        "warmup_cpu_ms_total": float(np.sum(cpu_ms[:warmup])),
        "max_cpu_ms_per_frame": float(np.max(cpu_ms)) if cpu_ms else None,
        "hypotheses_last": hyps[-1] if hyps else None,
        "hypotheses_max": max(hyps) if hyps else None,
        "max_hypotheses_cap": knowledge.world.max_hypotheses,
        "objects_last": objects[-1] if objects else None,
        "objects_found_frame": first_full,
        "peak_traced_mb_steady_frames": peak_mb,
        "ru_maxrss_mb_after": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0,
        "per_frame": {
            "cpu_ms": [round(v, 3) for v in cpu_ms],
            "hypotheses": hyps,
            "objects": objects,
        },
    }
    return out


def budget(n_hyp: int, *, duration: float) -> dict[str, Any]:
    scenario = make_scenario("robocup", 0, duration=duration)
    base = load_knowledge(shipped_knowledge_path(scenario.knowledge_file))
    knowledge = _with_world(base, max_hypotheses=n_hyp)
    t0 = time.perf_counter()
    result = run_scenario(scenario, knowledge, progress=False)
    m = result.metrics
    return {
        "max_hypotheses": n_hyp,
        "duration_s": duration,
        "n_detections": result.n_detections,
        "gospa": m.gospa.total,
        "gospa_localisation": m.gospa.localisation,
        "gospa_missed": m.gospa.missed,
        "gospa_false": m.gospa.false,
        "id_switches": m.id_switches,
        "time_per_detection_s": m.time_per_detection["mean_s"],
        "run_s": time.perf_counter() - t0,
    }


def run(quick: bool = False, size_limit: float = 60.0) -> dict[str, Any]:
    sizes = SIZES
    warmup, timed = (10, 10) if quick else (WARMUP, TIMED)
    doc: dict[str, Any] = {
        "benchmark": "scaling",
        "quick": quick,
        "machine": machine_info(),
        "grid": {
            "rate_hz": 10.0,
            "warmup_frames": warmup,
            "timed_frames": timed,
            "size_limit_cpu_s": size_limit,
            "knowledge": "grid.yaml (world.region := scenario region)",
            "sizes": [],
        },
        "budget": {"scenario": "robocup", "seed": 0, "runs": []},
    }
    bar = tqdm(total=len(sizes) + len(BUDGETS), desc="scaling", unit="run")
    for n in sizes:
        row = grid_size(n, size_limit=size_limit, warmup=warmup, timed=timed)
        doc["grid"]["sizes"].append(row)
        brief = {k: v for k, v in row.items() if k != "per_frame"}
        bar.update()
        tqdm.write(f"grid N={n}: {brief}")
    steady = [
        (r["n"], r["steady_cpu_ms_per_frame"])
        for r in doc["grid"]["sizes"]
        if r["steady_cpu_ms_per_frame"] is not None
    ]
    if len(steady) >= 2:
        ns, ts = np.log([s[0] for s in steady]), np.log([max(s[1], 1e-9) for s in steady])
        doc["grid"]["loglog_slope"] = float(np.polyfit(ns, ts, 1)[0])
    duration = 0.5 if quick else 1.0
    for n_hyp in BUDGETS:
        row = budget(n_hyp, duration=duration)
        doc["budget"]["runs"].append(row)
        bar.update()
        tqdm.write(f"budget {n_hyp}: {row}")
    bar.close()
    return doc


def markdown(doc: dict[str, Any]) -> str:
    m = doc["machine"]
    g = doc["grid"]
    lines = [
        "# semwm scaling",
        "",
        f"Machine: {m['platform']}, {m['cpu_count']} CPUs, Python {m['python']}, {m['date']}, "
        f"commit {m.get('commit')}; versions: "
        + ", ".join(f"{k} {v}" for k, v in m["versions"].items()),
        "",
        f"## Static grid, all N detected every frame at {g['rate_hz']:g} Hz"
        f"{' (quick)' if doc['quick'] else ''}",
        "",
        f"Steady state = mean CPU (process_time) over {g['timed_frames']} frames after "
        f"{g['warmup_frames']} warm-up frames; limit {g['size_limit_cpu_s']:g} CPU s per size.",
        "",
        "| N | status | frames | CPU ms/frame | CPU µs/det | warm-up CPU ms | max ms/frame | "
        "hyps (last/max/cap) | objects (last) | all found at frame | traced peak MB | "
        "maxrss MB |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in g["sizes"]:
        lines.append(
            f"| {r['n']} | {r['status']} | {r['frames_done']}/{r['frames_planned']} | "
            f"{fmt(r['steady_cpu_ms_per_frame'])} | {fmt(r['steady_cpu_us_per_detection'])} | "
            f"{fmt(r['warmup_cpu_ms_total'])} | {fmt(r['max_cpu_ms_per_frame'])} | "
            f"{r['hypotheses_last']}/{r['hypotheses_max']}/{r['max_hypotheses_cap']} | "
            f"{r['objects_last']} | {fmt(r['objects_found_frame'])} | "
            f"{fmt(r['peak_traced_mb_steady_frames'])} | {fmt(r['ru_maxrss_mb_after'])} |"
        )
    if "loglog_slope" in g:
        lines += [
            "",
            f"Log-log slope of steady CPU/frame vs N: {g['loglog_slope']:.2f} (1 = linear).",
        ]
    b = doc["budget"]
    lines += [
        "",
        f"## Hypothesis budget: {b['scenario']} seed {b['seed']}",
        "",
        "| max_hypotheses | duration s | GOSPA | loc | missed | false | ID sw | µs/det (wall) |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for r in b["runs"]:
        lines.append(
            f"| {r['max_hypotheses']} | {r['duration_s']} | {fmt(r['gospa'])} | "
            f"{fmt(r['gospa_localisation'])} | {fmt(r['gospa_missed'])} | "
            f"{fmt(r['gospa_false'])} | {r['id_switches']} | "
            f"{fmt(r['time_per_detection_s'] * 1e6)} |"
        )
    lines.append("")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> dict[str, Any]:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--size-limit", type=float, default=60.0)
    add_output_arguments(parser)
    args = parser.parse_args(argv)
    doc = run(quick=args.quick, size_limit=args.size_limit)
    write_results(
        RESULTS, "scaling", doc, markdown(doc), args.quick, update_results=args.update_results
    )
    return doc


if __name__ == "__main__":
    main()
