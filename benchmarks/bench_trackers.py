"""semwm vs Stone Soup (GNN, JPDA) vs a FilterPy nearest-neighbour baseline.

Every tracker runs through :func:`semwm.sim.runner.run_scenario` (same scans, same
truth times, same :mod:`semwm.sim.metrics`); wall time per detection is the
runner's (ingest calls only, ``time.perf_counter``); peak memory is measured in a
separate run of seed 0 under ``tracemalloc`` (so that tracing does not distort the
timings). Writes ``trackers.json`` and ``trackers.md`` to ``benchmarks/out/``
(``benchmarks/results/`` with ``--update-results``).

    python benchmarks/bench_trackers.py [--quick] [--update-results]
"""

from __future__ import annotations

import argparse
import sys
import time
import tracemalloc
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from baselines import (
    RESULTS,
    FilterPyNN,
    StoneSoupTracker,
    TrackerTimeout,
    add_output_arguments,
    clutter_area,
    fmt,
    machine_info,
    tuning_from_knowledge,
    write_results,
)
from tqdm import tqdm

from semwm.knowledge.loader import load_knowledge
from semwm.knowledge.shipped import shipped_knowledge_path
from semwm.sim.runner import run_scenario
from semwm.sim.scenarios import make_scenario

TRACKERS = ("semwm", "stonesoup_gnn", "stonesoup_jpda", "filterpy_nn")
# scenario -> (sizes, scan rate of one source in Hz)
FULL: dict[str, tuple[dict[str, Any], float]] = {
    "sim1": ({}, 2.5),
    "sim2": ({}, 10.0),
    "robocup": ({"duration": 2.0}, 30.0),
}
QUICK: dict[str, tuple[dict[str, Any], float]] = {
    "sim1": ({"duration": 10.0}, 2.5),
    "sim2": ({}, 10.0),
    "robocup": ({"duration": 1.0}, 30.0),
}


def _factory(name: str, tuning: Any, time_limit: float) -> Callable[[Any], Any] | None:
    if name == "semwm":
        return None  # the runner's default: semwm.WorldModel
    if name == "stonesoup_gnn":
        return lambda k: StoneSoupTracker(tuning, "gnn", time_limit=time_limit)
    if name == "stonesoup_jpda":
        return lambda k: StoneSoupTracker(tuning, "jpda", time_limit=time_limit)
    if name == "filterpy_nn":
        return lambda k: FilterPyNN(tuning)
    raise ValueError(name)


def run_one(
    scenario: Any, knowledge: Any, tracker: str, tuning: Any, *, memory: bool, time_limit: float
) -> dict[str, Any]:
    factory = _factory(tracker, tuning, time_limit)
    if memory:
        tracemalloc.start()
    t0 = time.perf_counter()
    try:
        result = run_scenario(scenario, knowledge, progress=False, world_model_factory=factory)
    except TrackerTimeout as e:
        return {"status": "timeout", "error": str(e)}
    finally:
        peak = tracemalloc.get_traced_memory()[1] if memory else None
        if memory:
            tracemalloc.stop()
    elapsed = time.perf_counter() - t0
    m = result.metrics
    out: dict[str, Any] = {
        "status": "ok",
        "gospa": m.gospa.total,
        "gospa_localisation": m.gospa.localisation,
        "gospa_missed": m.gospa.missed,
        "gospa_false": m.gospa.false,
        "id_switches": m.id_switches,
        "time_per_detection_s": m.time_per_detection["mean_s"],
        "total_ingest_s": m.time_per_detection["total_ingest_s"],
        "run_s": elapsed,
        "n_detections": result.n_detections,
    }
    if memory:
        out["peak_memory_mb"] = peak / 1e6 if peak is not None else None
    return out


def _mean(rows: list[dict[str, Any]], key: str) -> float | None:
    vals = [r[key] for r in rows if r.get("status") == "ok" and r.get(key) is not None]
    return float(np.mean(vals)) if vals else None


def run(
    quick: bool = False,
    seeds: tuple[int, ...] = (0, 1, 2),
    time_limit: float = 120.0,
    trackers: tuple[str, ...] = TRACKERS,
) -> dict[str, Any]:
    config = QUICK if quick else FULL
    doc: dict[str, Any] = {
        "benchmark": "trackers",
        "quick": quick,
        "machine": machine_info(),
        "seeds": list(seeds),
        "scenarios": {},
        "notes": [
            "Every tracker is fed the same scans by semwm.sim.runner.run_scenario and scored "
            "by semwm.sim.metrics (GOSPA alpha=2, p=1, c = scenario's gospa_c).",
            "time_per_detection_s: wall time (perf_counter) of the ingest calls / detections.",
            "peak_memory_mb: tracemalloc peak of a separate seed-0 run (Python allocations).",
            "Peers are class-agnostic; an estimate's class is that of its last detection.",
            "Peers use a constant-velocity model for every scenario (also static sim1).",
        ],
    }
    bar = tqdm(total=len(config) * len(trackers) * len(seeds), desc="trackers", unit="run")
    for name, (sizes, rate) in config.items():
        scenario0 = make_scenario(name, 0, **sizes)
        knowledge = load_knowledge(shipped_knowledge_path(scenario0.knowledge_file))
        tuning = tuning_from_knowledge(knowledge, scan_rate=rate, area=clutter_area(scenario0))
        entry: dict[str, Any] = {
            "sizes": sizes,
            "knowledge": scenario0.knowledge_file,
            "association_model": knowledge.world.association_model,
            "max_hypotheses": knowledge.world.max_hypotheses,
            "gospa_c": scenario0.metadata.get("gospa_c"),
            "peer_tuning": tuning.to_dict(),
            "runs": {},
            "summary": {},
        }
        for tracker in trackers:
            rows = []
            for seed in seeds:
                scenario = make_scenario(name, seed, **sizes)
                row = run_one(
                    scenario, knowledge, tracker, tuning, memory=False, time_limit=time_limit
                )
                row["seed"] = seed
                rows.append(row)
                bar.update()
                tqdm.write(f"{name:8s} {tracker:15s} seed {seed}: {row}")
            mem = run_one(
                scenario0, knowledge, tracker, tuning, memory=True, time_limit=time_limit * 2
            )
            entry["runs"][tracker] = rows
            entry["summary"][tracker] = {
                "gospa": _mean(rows, "gospa"),
                "gospa_localisation": _mean(rows, "gospa_localisation"),
                "gospa_missed": _mean(rows, "gospa_missed"),
                "gospa_false": _mean(rows, "gospa_false"),
                "id_switches": _mean(rows, "id_switches"),
                "time_per_detection_s": _mean(rows, "time_per_detection_s"),
                "peak_memory_mb": mem.get("peak_memory_mb"),
                "n_ok": sum(r.get("status") == "ok" for r in rows),
            }
        s = entry["summary"]
        ratios: dict[str, Any] = {}
        for peer in trackers:
            if peer == "semwm" or "semwm" not in s:
                continue
            r: dict[str, Any] = {}
            for key in ("gospa", "time_per_detection_s", "peak_memory_mb"):
                a, b = s["semwm"].get(key), s[peer].get(key)
                r[key] = a / b if a is not None and b else None
            ratios[peer] = r
        entry["ratios_semwm_over_peer"] = ratios
        doc["scenarios"][name] = entry
    bar.close()
    return doc


def markdown(doc: dict[str, Any]) -> str:
    m = doc["machine"]
    lines = [
        "# Tracker comparison: semwm vs Stone Soup vs FilterPy NN",
        "",
        f"Machine: {m['platform']}, {m['cpu_count']} CPUs ({m.get('processor') or '?'}), "
        f"Python {m['python']}, {m['date']}; versions: "
        + ", ".join(f"{k} {v}" for k, v in m["versions"].items()),
        "",
        f"Seeds {doc['seeds']}{' (quick)' if doc['quick'] else ''}; means over seeds; "
        "memory from a seed-0 run under tracemalloc. Ratios are semwm / peer "
        "(< 1: semwm lower).",
        "",
    ]
    for name, e in doc["scenarios"].items():
        lines += [
            f"## {name} (sizes {e['sizes'] or 'default'}, {e['knowledge']}, "
            f"association_model={e['association_model']}, GOSPA c={e['gospa_c']})",
            "",
            "| tracker | GOSPA | loc | missed | false | ID sw | µs/det | peak MB | runs ok |",
            "|---|---|---|---|---|---|---|---|---|",
        ]
        for tracker, s in e["summary"].items():
            tpd = s["time_per_detection_s"]
            lines.append(
                f"| {tracker} | {fmt(s['gospa'])} | {fmt(s['gospa_localisation'])} | "
                f"{fmt(s['gospa_missed'])} | {fmt(s['gospa_false'])} | "
                f"{fmt(s['id_switches'])} | {fmt(tpd * 1e6 if tpd else None)} | "
                f"{fmt(s['peak_memory_mb'])} | {s['n_ok']}/{len(doc['seeds'])} |"
            )
        lines += ["", "| semwm / peer | GOSPA | time/det | memory |", "|---|---|---|---|"]
        for peer, r in e["ratios_semwm_over_peer"].items():
            lines.append(
                f"| {peer} | {fmt(r['gospa'])} | {fmt(r['time_per_detection_s'])} | "
                f"{fmt(r['peak_memory_mb'])} |"
            )
        t = e["peer_tuning"]
        lines += [
            "",
            f"Peer tuning: q={t['q']} (CV), R per class {t['measurement_noise']}, "
            f"detector R {t['detector_noise']}, initial velocity variance "
            f"{t['initial_velocity_variance']}, gate {t['gate_mahalanobis']} (Mahalanobis), "
            f"min_points {t['min_points']}, tentative max age {t['tentative_max_age_s']} s, "
            f"delete at trace(P_pos) > {2 * t['max_position_variance']} or "
            f"{t['max_time_without_update']} s without update; JPDA P_D {t['prob_detect']}, "
            f"P_G {t['prob_gate']}, clutter density {t['clutter_spatial_density']:.3g} /m²/scan.",
            "",
        ]
    lines += ["Notes:", ""] + [f"- {n}" for n in doc["notes"]] + [""]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> dict[str, Any]:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--quick", action="store_true")
    parser.add_argument(
        "--time-limit",
        type=float,
        default=120.0,
        help="per peer run, wall seconds, before 'timeout'",
    )
    add_output_arguments(parser)
    args = parser.parse_args(argv)
    doc = run(quick=args.quick, time_limit=args.time_limit)
    write_results(
        RESULTS, "trackers", doc, markdown(doc), args.quick, update_results=args.update_results
    )
    return doc


if __name__ == "__main__":
    main()
