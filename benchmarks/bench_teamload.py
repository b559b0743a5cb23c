"""A team's load (issue 15 defect 6): 5 robots x 10 detections x 30 Hz on 20 shared objects.

Run: ``python benchmarks/bench_teamload.py [--seconds 60] [--hold S] [--order-tolerance S]
[--out FILE]``

A real ``semwm serve --knowledge knowledge/sim1.yaml`` in its own process on a
loopback port (:func:`bench_soak.launch`). Twenty static objects (cups and coke
cans on a 5 x 4 grid, 0.7 m apart); each of 5 robots sees 10 of them, overlapping
its neighbours' (robot i: objects 2i .. 2i + 9, mod 20), and posts one batch of
those 10 detections (5 cm noise, its own source, wall-clock stamps) every 1/30 s
on a fixed schedule: a robot that falls behind posts at once, so the run takes
longer than ``--seconds`` when the service cannot keep up. A reader asks for
``GET /world`` at 10 Hz. Reported: detections offered and processed per second,
how far behind schedule the robots ended, POST and GET latency p50/p99, errors,
the objects published at the end against the 18 that some robot sees, and the server
process's CPU per batch (real time needs at most 6.67 ms on one core). The issue's
target: keeps up in real time (processed = offered) with POST p99 < 50 ms.

The machine's moment: the same stream in process (``bench_speed.team_stream``, 3 s,
CPU per batch), measured just before and just after the HTTP run. On a shared machine
the same code runs up to 2-3x slower at busy moments; this figure says which moment a
run had (about 1.5-1.7 ms per batch on a quiet 2-core x86_64 box in 2026-11).
Writes JSON to ``--out`` (default ``benchmarks/out/teamload.json``).
"""

from __future__ import annotations

import argparse
import json
import platform
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

import httpx
import numpy as np
from bench_soak import cpu_seconds, launch

ROOT = Path(__file__).resolve().parents[1]
ROBOTS = 5
PER_BATCH = 10
RATE_HZ = 30.0
READER_HZ = 10.0
NOISE = 0.05
OBJECTS = [
    ("Cup" if (i + j) % 2 else "CokeCan", (0.6 + 0.7 * i, 0.45 + 0.7 * j))
    for i in range(5)
    for j in range(4)
]


def robot(index: int, url: str, seconds: float, out: dict[str, Any], start: float) -> None:
    rng = np.random.default_rng(index)
    seen = [OBJECTS[(2 * index + k) % len(OBJECTS)] for k in range(PER_BATCH)]
    period = 1.0 / RATE_HZ
    ticks = int(seconds * RATE_HZ)
    latencies: list[float] = []
    applied = errors = 0
    with httpx.Client(base_url=url, timeout=30) as client:
        for tick in range(ticks):
            delay = start + tick * period - time.monotonic()
            if delay > 0:
                time.sleep(delay)
            now = time.time()
            noise = rng.normal(0.0, NOISE, size=(PER_BATCH, 2))
            batch = [
                {"time": now, "class": cls, "source": f"r{index}",
                 "position": [x + noise[k, 0], y + noise[k, 1]]}
                for k, (cls, (x, y)) in enumerate(seen)
            ]  # fmt: skip
            sent = time.perf_counter()
            try:
                response = client.post("/detections", json={"detections": batch})
                if response.status_code == 200:
                    applied += response.json()["applied"]
                else:
                    errors += 1
            except httpx.TransportError:
                errors += 1
            latencies.append(time.perf_counter() - sent)
    out[f"r{index}"] = {
        "latencies": latencies,
        "applied": applied,
        "errors": errors,
        "behind_s": max(time.monotonic() - (start + ticks * period), 0.0),
    }


def reader(url: str, until: threading.Event, out: dict[str, Any]) -> None:
    latencies: list[float] = []
    with httpx.Client(base_url=url, timeout=30) as client:
        while not until.is_set():
            sent = time.perf_counter()
            client.get("/world")
            latencies.append(time.perf_counter() - sent)
            time.sleep(max(1.0 / READER_HZ - (time.perf_counter() - sent), 0.0))
    out["reader"] = latencies


def _metric(text: str, name: str) -> float | None:
    """A metric's value in Prometheus text (``None`` if absent)."""
    for line in text.splitlines():
        if line.startswith(name + " "):
            return float(line.split()[1])
    return None


def percentiles(values: list[float]) -> dict[str, float]:
    ms = np.asarray(values) * 1e3
    return {
        "p50": round(float(np.percentile(ms, 50)), 2),
        "p99": round(float(np.percentile(ms, 99)), 2),
    }


def run(seconds: float, hold: float = 0.0, order_tolerance: float | None = None) -> dict[str, Any]:
    from bench_speed import team_stream

    before = team_stream(seconds=3.0)["cpu_ms_per_batch"]
    with tempfile.TemporaryDirectory() as tmp:
        options = ["--reorder-window", "1.0", "--hold", str(hold)]
        if order_tolerance is not None:
            options += ["--order-tolerance", str(order_tolerance)]
        process, url = launch(options, Path(tmp) / "server.log")
        try:
            results: dict[str, Any] = {}
            done = threading.Event()
            start = time.monotonic() + 0.5
            robots = [
                threading.Thread(target=robot, args=(i, url, seconds, results, start))
                for i in range(ROBOTS)
            ]
            watcher = threading.Thread(target=reader, args=(url, done, results))
            cpu_before = cpu_seconds(process.pid)
            watcher.start()
            for thread in robots:
                thread.start()
            for thread in robots:
                thread.join()
            done.set()
            watcher.join()
            wall = time.monotonic() - start
            server_cpu = cpu_seconds(process.pid) - cpu_before
            world = httpx.get(f"{url}/world", timeout=30).json()
            metrics = httpx.get(f"{url}/metrics", timeout=30).text
        finally:
            process.terminate()
            process.wait(10)
    after = team_stream(seconds=3.0)["cpu_ms_per_batch"]
    posts = [v for r in range(ROBOTS) for v in results[f"r{r}"]["latencies"]]
    applied = sum(results[f"r{r}"]["applied"] for r in range(ROBOTS))
    offered = ROBOTS * PER_BATCH * RATE_HZ
    processed = applied / wall
    post = percentiles(posts)
    return {
        "benchmark": "teamload",
        "machine": f"{platform.platform()}, {platform.processor() or platform.machine()}",
        "python": platform.python_version(),
        "sizes": {
            "robots": ROBOTS,
            "per_batch": PER_BATCH,
            "rate_hz": RATE_HZ,
            "objects": len(OBJECTS),
            "seconds": seconds,
            "hold": hold,
            "order_tolerance": "default" if order_tolerance is None else order_tolerance,
        },
        "offered_det_per_s": offered,
        "processed_det_per_s": round(processed, 1),
        "wall_s": round(wall, 1),
        "behind_schedule_s": round(max(results[f"r{r}"]["behind_s"] for r in range(ROBOTS)), 2),
        "post_ms": post,
        "get_world_ms": percentiles(results["reader"]),
        "errors": sum(results[f"r{r}"]["errors"] for r in range(ROBOTS)),
        "replayed_scans": _metric(metrics, "semwm_replayed_scans"),
        "arrival_order_scans": _metric(metrics, "semwm_arrival_order_scans"),
        # the world model's part of an accepted batch, under the lock (the rest: HTTP)
        "apply_ms_mean": _mean_ms(metrics, "semwm_ingest_apply_seconds"),
        "server_ms_mean": _mean_ms(metrics, "semwm_ingest_latency_seconds"),
        # the server process's CPU per batch applied (every thread): steadier than
        # throughput on a busy machine; real time needs 1/150 s of it at most
        "server_cpu_ms_per_batch": round(1000.0 * server_cpu / max(applied / PER_BATCH, 1), 2),
        "objects_published": len(world["objects"]),
        "objects_seen": len(
            {(2 * r + k) % len(OBJECTS) for r in range(ROBOTS) for k in range(PER_BATCH)}
        ),
        # the machine's moment: the stream in process, CPU ms per batch, before and after
        "in_process_ms_per_batch": [round(before, 2), round(after, 2)],
        "target_met": bool(processed >= 0.98 * offered and post["p99"] < 50.0),
    }


def _mean_ms(metrics: str, histogram: str) -> float:
    """Mean (ms) of a Prometheus histogram in ``metrics``: its _sum over its _count."""
    count = _metric(metrics, f"{histogram}_count")
    total = _metric(metrics, f"{histogram}_sum")
    return round(1000.0 * total / count, 2) if count and total is not None else 0.0


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seconds", type=float, default=60.0)
    parser.add_argument("--hold", type=float, default=0.0, help="semwm serve --hold (s)")
    parser.add_argument(
        "--order-tolerance", type=float, help="semwm serve --order-tolerance (s; default: its own)"
    )
    parser.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "out" / "teamload.json")
    args = parser.parse_args()
    result = run(args.seconds, args.hold, args.order_tolerance)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(result, indent=2) + "\n")
    print(json.dumps({k: v for k, v in result.items() if k != "machine"}, indent=2))
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
