"""The hold (``WorldModel(hold=...)``, ``semwm serve --hold``): CPU and quality with and
without it, configurations alternated in one run (best-of the rounds for CPU).

1. The team simulation (:mod:`semwm.sim.team_run`, as ``bench_team.py``): robocup,
   5 observers at 30 Hz, latency 20-150 ms, the flat receiver processing on arrival
   with a 0.2 s reorder window, model hold 0 / 0.05 / 0.1 / 0.15 s; and the same
   scenario without latency (every scan in order: the floor). Per configuration:
   receiver CPU (best of the rounds, mean over the seeds), GOSPA (c = 2) and id
   switches (means over the seeds), scans replayed, detections dropped as late.
2. The team's stream in process (``bench_teamload``'s layout: 5 robots x 10
   detections x 30 Hz on 20 shared objects, sim1.yaml, 1.0 s reorder window), each
   batch arriving ``±20 ms`` off its stamp, with a reader asking for the world at
   10 Hz: CPU per batch after a warm-up (reads included), scans replayed, objects
   published at the end against the 18 seen. In order without jitter as the floor.

    python benchmarks/bench_hold.py [--seeds 0 1 2] [--duration 5] [--rounds 2]
        [--holds 0 0.05 0.1 0.15] [--update-results]

Writes benchmarks/out/hold.{json,md}; with ``--update-results`` benchmarks/results/.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path
from typing import Any

import numpy as np
from baselines import fmt, machine_info, write_results
from bench_teamload import NOISE, OBJECTS, PER_BATCH, RATE_HZ, ROBOTS

from semwm.knowledge.loader import load_knowledge
from semwm.knowledge.shipped import shipped_knowledge_path
from semwm.sim.scenarios import make_scenario
from semwm.sim.team_run import Network, run_team
from semwm.world import WorldModel

HERE = Path(__file__).parent
LATENCY = (0.02, 0.15)
WINDOW = 0.2  # the team receiver's reorder window: largest latency + 50 ms
JITTER = 0.02
READER_HZ = 10.0


def team_sim(
    seeds: list[int], duration: float, holds: list[float], rounds: int
) -> list[dict[str, Any]]:
    knowledge = load_knowledge(shipped_knowledge_path("robocup.yaml"))
    configs: list[tuple[str, Network]] = [("in order (no latency)", Network())]
    configs += [(f"latency, hold {h:g} s", Network(0.0, LATENCY, hold=WINDOW, model_hold=h))
                for h in holds]  # fmt: skip
    scenarios = {seed: make_scenario("robocup", seed, duration=duration) for seed in seeds}
    cpu: dict[str, dict[int, list[float]]] = {name: {s: [] for s in seeds} for name, _ in configs}
    last: dict[str, dict[int, Any]] = {name: {} for name, _ in configs}
    for r in range(rounds):
        order = configs if r % 2 == 0 else configs[::-1]  # alternate
        for name, network in order:
            for seed in seeds:
                team = run_team(scenarios[seed], knowledge, levels=1, network=network, seed=seed)
                cpu[name][seed].append(team.cpu_global_s)
                last[name][seed] = team
                print(f"round {r} {name} seed {seed}: CPU {team.cpu_global_s:.2f} s, "
                      f"GOSPA {team.result.metrics.gospa.total:.4f}", flush=True)  # fmt: skip
    rows = []
    for name, network in configs:
        runs = [last[name][s] for s in seeds]
        rows.append(
            {
                "name": name,
                "model_hold": network.model_hold,
                "cpu_s": float(np.mean([min(cpu[name][s]) for s in seeds])),
                "cpu_s_per_seed": {str(s): min(cpu[name][s]) for s in seeds},
                "gospa": float(np.mean([t.result.metrics.gospa.total for t in runs])),
                "id_switches": float(np.mean([t.result.metrics.id_switches for t in runs])),
                "replayed_scans": float(np.mean([t.extra["replayed_scans"] for t in runs])),
                "late_dropped": float(np.mean([t.late for t in runs])),
            }
        )
    return rows


def _stream(seconds: float, jitter: float, seed: int = 0) -> list[list[dict[str, Any]]]:
    """The team's batches in order of arrival (stamp ± ``jitter``)."""
    rngs = [np.random.default_rng(robot) for robot in range(ROBOTS)]
    late = np.random.default_rng(100 + seed)
    seen = [[OBJECTS[(2 * r + k) % len(OBJECTS)] for k in range(PER_BATCH)] for r in range(ROBOTS)]
    arrivals: list[tuple[float, int, list[dict[str, Any]]]] = []
    for tick in range(int(seconds * RATE_HZ)):
        for r in range(ROBOTS):
            t = tick / RATE_HZ + r * 1e-3
            noise = rngs[r].normal(0.0, NOISE, size=(PER_BATCH, 2))
            batch = [
                {"time": t, "class": cls, "source": f"r{r}",
                 "position": [x + noise[k, 0], y + noise[k, 1]]}
                for k, (cls, (x, y)) in enumerate(seen[r])
            ]  # fmt: skip
            arrival = t + (float(late.uniform(-jitter, jitter)) if jitter else 0.0)
            arrivals.append((arrival, len(arrivals), batch))
    arrivals.sort(key=lambda a: (a[0], a[1]))
    return [b for _, _, b in arrivals]


def _stream_once(
    batches: list[list[dict[str, Any]]], hold: float, warmup: int
) -> tuple[float, WorldModel]:
    world = WorldModel(load_knowledge(shipped_knowledge_path("sim1.yaml")),
                       reorder_window=1.0, hold=hold)  # fmt: skip
    every = int(ROBOTS * RATE_HZ / READER_HZ)  # a read per this many batches
    cpu = 0.0
    for i, batch in enumerate(batches):
        start = time.process_time()
        world.ingest(batch)
        if i % every == every - 1:
            world.world()
        if i >= warmup:
            cpu += time.process_time() - start
    return cpu / (len(batches) - warmup), world


def team_stream(
    seconds: float, holds: list[float], rounds: int, warmup: int = 150
) -> list[dict[str, Any]]:
    configs = [("in order, no jitter", 0.0, 0.0)]
    configs += [(f"±{JITTER * 1e3:g} ms jitter, hold {h:g} s", JITTER, h) for h in holds]
    streams = {j: _stream(seconds, j) for j in {c[1] for c in configs}}
    best: dict[str, float] = {}
    final: dict[str, WorldModel] = {}
    for r in range(rounds):
        for name, jitter, hold in configs if r % 2 == 0 else configs[::-1]:
            cpu, world = _stream_once(streams[jitter], hold, warmup)
            best[name] = min(best.get(name, np.inf), cpu)
            final[name] = world
            print(f"round {r} {name}: {cpu * 1e3:.2f} ms/batch", flush=True)
    seen = len({(2 * r + k) % len(OBJECTS) for r in range(ROBOTS) for k in range(PER_BATCH)})
    return [
        {
            "name": name,
            "jitter_s": jitter,
            "model_hold": hold,
            "cpu_ms_per_batch": best[name] * 1e3,
            "cpu_us_per_detection": best[name] * 1e6 / PER_BATCH,
            "offered_batches_per_s": ROBOTS * RATE_HZ,
            "cpu_share_of_real_time": best[name] * ROBOTS * RATE_HZ,
            "replayed_scans": final[name].replayed_scans,
            "objects_published": len(final[name].world().objects),
            "objects_seen": seen,
        }
        for name, jitter, hold in configs
    ]


def markdown(doc: dict[str, Any]) -> str:
    s = doc["settings"]
    lines = [
        f"# The hold: robocup team simulation ({s['duration']:g} s, seeds {s['seeds']}, latency "
        f"{LATENCY[0] * 1e3:g}-{LATENCY[1] * 1e3:g} ms, reorder window {WINDOW:g} s) and the "
        f"team stream in process (±{JITTER * 1e3:g} ms, reads at {READER_HZ:g} Hz)",
        "",
        f"Machine: {doc['machine']['platform']}, {doc['machine']['cpu_count']} CPUs (shared), "
        f"Python {doc['machine']['python']}, {doc['machine']['date']}. CPU: best of "
        f"{s['rounds']} alternated rounds.",
        "",
        "| team simulation, flat | receiver CPU s | vs hold 0 | GOSPA | ID switches "
        "| scans replayed | late dropped |",
        "|---|---|---|---|---|---|---|",
    ]
    base = next(r for r in doc["team_sim"] if r["name"].startswith("latency, hold 0 "))
    for r in doc["team_sim"]:
        lines.append(
            f"| {r['name']} | {fmt(r['cpu_s'])} | {fmt(r['cpu_s'] / base['cpu_s'])} | "
            f"{fmt(r['gospa'], 4)} | {fmt(r['id_switches'])} | {fmt(r['replayed_scans'])} | "
            f"{fmt(r['late_dropped'])} |"
        )
    lines += [
        "",
        "| team stream, 5 x 10 det x 30 Hz | CPU ms/batch | vs hold 0 | share of real time "
        "| scans replayed | objects published / seen |",
        "|---|---|---|---|---|---|",
    ]
    base = next(r for r in doc["team_stream"] if r["model_hold"] == 0 and r["jitter_s"] > 0)
    for r in doc["team_stream"]:
        lines.append(
            f"| {r['name']} | {fmt(r['cpu_ms_per_batch'])} | "
            f"{fmt(r['cpu_ms_per_batch'] / base['cpu_ms_per_batch'])} | "
            f"{fmt(r['cpu_share_of_real_time'])} | {r['replayed_scans']} | "
            f"{r['objects_published']} / {r['objects_seen']} |"
        )
    return "\n".join(lines) + "\n"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    parser.add_argument("--duration", type=float, default=5.0)
    parser.add_argument("--rounds", type=int, default=2)
    parser.add_argument("--stream-seconds", type=float, default=6.0)
    parser.add_argument("--holds", type=float, nargs="+", default=[0.0, 0.05, 0.1, 0.15])
    parser.add_argument("--update-results", action="store_true",
                        help="write benchmarks/results/ instead of benchmarks/out/")  # fmt: skip
    args = parser.parse_args()
    doc = {
        "benchmark": "hold",
        "settings": {"seeds": args.seeds, "duration": args.duration, "rounds": args.rounds,
                     "stream_seconds": args.stream_seconds, "holds": args.holds},
        "machine": machine_info(),
        "team_stream": team_stream(args.stream_seconds, args.holds, args.rounds),
        "team_sim": team_sim(args.seeds, args.duration, args.holds, args.rounds),
    }  # fmt: skip
    write_results(HERE / "results", "hold", doc, markdown(doc), quick=False,
                  update_results=args.update_results)  # fmt: skip


if __name__ == "__main__":
    main()
