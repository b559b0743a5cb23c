"""Benchmark of the HTTP service: 5 robots streaming detections to a real server.

Run: ``python benchmarks/bench_api.py [--knowledge knowledge/sim1.yaml] [--seconds 5]
[--update-results]``

The server runs as ``semwm serve`` in its own process (so clients and server do
not share an interpreter lock) on a free loopback port. For each request size
(1, 10 and 100 detections per request) two phases run, with a reset between:

* ``paced``: 5 robots each send one request per 1/30 s (30 Hz) for ``--seconds``;
  reports the achieved request rate and the latency (p50/p99) under that load;
* ``flood``: 5 robots send requests back to back; reports the throughput
  (detections/s) the service sustains and the latency.

Each robot reports its own static objects (one per detection of a request,
1 m apart) with 2 cm Gaussian noise, at its wall-clock time. Prints a table and
writes ``api.json`` and ``api.md`` (with the machine it ran on) to ``benchmarks/out/``
(``benchmarks/results/`` with ``--update-results``).
"""

from __future__ import annotations

import argparse
import datetime as dt
import os
import platform
import socket
import statistics
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any

import httpx
import numpy as np
from tqdm import tqdm

sys.path.insert(0, str(Path(__file__).resolve().parent))

from baselines import RESULTS, add_output_arguments, fmt, write_results

ROBOTS = 5
RATE_HZ = 30.0
SIZES = (1, 10, 100)
ROOT = Path(__file__).resolve().parents[1]


def free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        port: int = sock.getsockname()[1]
        return port


def start_server(knowledge: Path) -> tuple[subprocess.Popen[bytes], str]:
    port = free_port()
    command = [
        sys.executable, "-m", "semwm.cli", "serve", "--knowledge", str(knowledge),
        "--port", str(port), "--log-level", "warning", "--reorder-window", "1.0",
    ]  # fmt: skip
    process = subprocess.Popen(command, cwd=ROOT)
    url = f"http://127.0.0.1:{port}"
    deadline = time.monotonic() + 30
    while True:
        try:
            httpx.get(f"{url}/health", timeout=1).raise_for_status()
            return process, url
        except httpx.TransportError:
            if process.poll() is not None or time.monotonic() > deadline:
                process.kill()
                raise RuntimeError("semwm serve did not start") from None
            time.sleep(0.1)


def robot(
    url: str, index: int, size: int, seconds: float, paced: bool, t0: float, out: dict[str, Any]
) -> None:
    rng = np.random.default_rng(index)
    truth = np.array([[index * 10.0 + (k % 10), float(k // 10)] for k in range(size)])
    latencies: list[float] = []
    statuses: dict[int, int] = {}
    sent = 0
    period = 1.0 / RATE_HZ
    start = time.monotonic()
    with httpx.Client(base_url=url, timeout=60) as client:
        n = 0
        while time.monotonic() - start < seconds:
            if paced:
                wait = start + n * period - time.monotonic()
                if wait > 0:
                    time.sleep(wait)
            n += 1
            now = round(time.monotonic() - t0, 6)
            positions = truth + rng.normal(0.0, 0.02, truth.shape)
            detections = [
                {"time": now, "class": "Cup", "position": p.tolist(), "source": f"r{index}"}
                for p in positions
            ]
            body: Any = detections[0] if size == 1 else {"detections": detections}
            begin = time.perf_counter()
            response = client.post("/detections", json=body)
            latencies.append(time.perf_counter() - begin)
            statuses[response.status_code] = statuses.get(response.status_code, 0) + 1
            if response.status_code == 200:
                sent += response.json()["applied"]
    out[f"r{index}"] = {"latencies": latencies, "statuses": statuses, "applied": sent}


def phase(url: str, size: int, seconds: float, paced: bool) -> dict[str, Any]:
    httpx.post(f"{url}/reset").raise_for_status()
    results: dict[str, Any] = {}
    t0 = time.monotonic()
    threads = [
        threading.Thread(target=robot, args=(url, i, size, seconds, paced, t0, results))
        for i in range(ROBOTS)
    ]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    elapsed = time.monotonic() - t0
    latencies = sorted(x for r in results.values() for x in r["latencies"])
    statuses: dict[str, int] = {}
    for r in results.values():
        for code, count in r["statuses"].items():
            statuses[str(code)] = statuses.get(str(code), 0) + count
    applied = sum(r["applied"] for r in results.values())
    health = httpx.get(f"{url}/health").json()
    return {
        "mode": "paced" if paced else "flood",
        "detections_per_request": size,
        "seconds": round(elapsed, 3),
        "requests": len(latencies),
        "requests_per_s": round(len(latencies) / elapsed, 1),
        "target_requests_per_s": ROBOTS * RATE_HZ if paced else None,
        "detections_per_s": round(applied / elapsed, 1),
        "latency_p50_ms": round(1000 * statistics.median(latencies), 2),
        "latency_p99_ms": round(
            1000 * latencies[min(len(latencies) - 1, int(0.99 * len(latencies)))], 2
        ),
        "statuses": statuses,
        "objects_at_end": health["objects"],
        "hypotheses_at_end": health["hypotheses"],
    }


def machine() -> dict[str, Any]:
    commit = subprocess.run(
        ["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True, text=True
    ).stdout.strip()
    return {
        "platform": platform.platform(),
        "processor": platform.processor() or platform.machine(),
        "cpu_count": os.cpu_count(),
        "python": sys.version.split()[0],
        "date": dt.datetime.now(dt.UTC).isoformat(timespec="seconds"),
        "commit": commit,
    }


def markdown(doc: dict[str, Any]) -> str:
    """The results as a markdown table (``api.md``, benchmarks/README.md)."""
    m = doc["machine"]
    lines = [
        "# The HTTP service under load",
        "",
        f"{doc['robots']} robots, {doc['rate_hz']:g} Hz paced or as fast as possible, "
        f"`{doc['knowledge']}`; server and clients on the same machine: {m['platform']}, "
        f"{m['cpu_count']} CPUs ({m.get('processor') or '?'}), Python {m['python']}, "
        f"{m['date']}, commit {m.get('commit')}.",
        "",
        "| mode | detections / request | requests/s | target requests/s | detections/s | "
        "p50 ms | p99 ms | objects at end | statuses |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for r in doc["results"]:
        statuses = ", ".join(f"{code}: {count}" for code, count in r["statuses"].items())
        target = r["target_requests_per_s"] and round(r["target_requests_per_s"])
        lines.append(
            f"| {r['mode']} | {r['detections_per_request']} | {r['requests_per_s']:.0f} | "
            f"{fmt(target)} | {r['detections_per_s']:.0f} | "
            f"{r['latency_p50_ms']:.1f} | {r['latency_p99_ms']:.1f} | "
            f"{r['objects_at_end']} | {statuses} |"
        )
    lines.append("")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--knowledge", type=Path, default=ROOT / "knowledge" / "sim1.yaml")
    parser.add_argument("--seconds", type=float, default=5.0, help="length of each phase")
    add_output_arguments(parser)
    args = parser.parse_args(argv)
    process, url = start_server(args.knowledge)
    rows = []
    phases = [(size, paced) for size in SIZES for paced in (True, False)]
    try:
        for size, paced in tqdm(phases, desc="api phases", unit="phase"):
            rows.append(phase(url, size, args.seconds, paced))
    finally:
        process.terminate()
        process.wait(10)
    report = {
        "benchmark": "api",
        "robots": ROBOTS,
        "rate_hz": RATE_HZ,
        "knowledge": str(
            args.knowledge.relative_to(ROOT)
            if args.knowledge.is_absolute() and args.knowledge.is_relative_to(ROOT)
            else args.knowledge
        ),
        "machine": machine(),
        "results": rows,
    }
    write_results(
        RESULTS, "api", report, markdown(report), False, update_results=args.update_results
    )


if __name__ == "__main__":
    main()
