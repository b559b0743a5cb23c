"""Soak benchmark (not in CI): 5 robots x 30 Hz against ``semwm serve --data-dir`` for a long time.

Run: ``python benchmarks/bench_soak.py [--seconds 3600] [--sync always|batch]
[--out benchmarks/results/soak.json]``

The server runs as ``semwm serve --data-dir TMP`` in its own process on a loopback
port it picks itself (``--port 0``). Five robots each post one batch (their own
pose and two static objects, 2 cm noise) every 1/30 s. Reported per minute and in
total: p50/p99 ingest latency, errors (any non-200 or transport failure), the
server's RSS (from /proc) at start and end, the journal's size on disk, records
in the database, snapshots and compactions (archives). The JSON goes to ``--out``
(default: an untracked ``runs/`` file).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import re
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

import httpx
import numpy as np

ROBOTS = 5
RATE_HZ = 30.0
ROOT = Path(__file__).resolve().parents[1]
_LISTENING = re.compile(r"Uvicorn running on (http://127\.0\.0\.1:\d+)")


def rss_mib(pid: int) -> float:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024
    return float("nan")


def cpu_seconds(pid: int) -> float:
    """CPU time (user + system, s) process ``pid`` has used so far, from ``/proc``."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def start_server(data_dir: Path, sync: str, log: Path) -> tuple[subprocess.Popen[bytes], str]:
    return launch(
        ["--data-dir", str(data_dir), "--sync", sync, "--reorder-window", "1.0",
         "--compact-every", "20000"],
        log,
    )  # fmt: skip


def launch(options: list[str], log: Path) -> tuple[subprocess.Popen[bytes], str]:
    """``semwm serve --knowledge knowledge/sim1.yaml --port 0 OPTIONS`` in its own process;
    its output goes to ``log``, where the URL it listens on is read."""
    command = [
        sys.executable, "-m", "semwm.cli", "serve", "--knowledge", "knowledge/sim1.yaml",
        "--port", "0", "--log-level", "info", *options,
    ]  # fmt: skip
    with log.open("w") as out:
        process = subprocess.Popen(command, cwd=ROOT, stdout=out, stderr=subprocess.STDOUT)
    deadline = time.monotonic() + 60
    while True:
        found = _LISTENING.search(log.read_text())
        if found:
            return process, found.group(1)
        if process.poll() is not None or time.monotonic() > deadline:
            process.kill()
            raise SystemExit(f"server did not start:\n{log.read_text()}")
        time.sleep(0.1)


def robot(index: int, url: str, until: float, out: list[tuple[float, float, bool]]) -> None:
    rng = np.random.default_rng(index)
    period = 1.0 / RATE_HZ
    start = time.monotonic()
    tick = 0
    with httpx.Client(base_url=url, timeout=10) as client:
        while time.monotonic() < until:
            t = start + tick * period
            tick += 1
            delay = t - time.monotonic()
            if delay > 0:
                time.sleep(delay)
            now = time.time()
            noise = rng.normal(0.0, 0.02, size=(3, 2))
            y = 0.5 + (now % 20.0) * 0.1
            batch = [
                {"time": now, "class": "Cup", "source": f"r{index}", "label": f"r{index}",
                 "position": [0.5 + 0.6 * index + noise[0, 0], y + noise[0, 1]]},
                {"time": now, "class": "CokeCan", "source": f"r{index}",
                 "position": [0.4 + 0.6 * index + noise[1, 0], 2.5 + noise[1, 1]]},
                {"time": now, "class": "Table", "source": f"r{index}",
                 "position": [0.6 + 0.6 * index + noise[2, 0], 0.3 + noise[2, 1]]},
            ]  # fmt: skip
            sent = time.perf_counter()
            try:
                ok = client.post("/detections", json={"detections": batch}).status_code == 200
            except httpx.TransportError:
                ok = False
            out.append((time.monotonic(), time.perf_counter() - sent, ok))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seconds", type=float, default=3600.0)
    parser.add_argument("--sync", choices=["always", "batch"], default="always")
    parser.add_argument("--out", type=Path, default=ROOT / "runs" / "soak.json")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        data_dir = Path(tmp) / "data"
        process, url = start_server(data_dir, args.sync, Path(tmp) / "server.log")
        rss_start = rss_mib(process.pid)
        samples: list[tuple[float, float, bool]] = []
        begin = time.monotonic()
        until = begin + args.seconds
        threads = [
            threading.Thread(target=robot, args=(i, url, until, samples)) for i in range(ROBOTS)
        ]
        for thread in threads:
            thread.start()
        minutes: list[dict[str, Any]] = []
        while any(t.is_alive() for t in threads):
            time.sleep(min(60.0, max(until - time.monotonic(), 0.1)))
            journal = httpx.get(f"{url}/persistence", timeout=30).json()["journal"]
            minutes.append(
                {"t_s": round(time.monotonic() - begin, 1), "rss_mib": rss_mib(process.pid),
                 "journal_bytes": journal["bytes"], "records": journal["last_seq"],
                 "records_in_database": journal["records_in_database"],
                 "archives": journal["archives"]}
            )  # fmt: skip
            print(json.dumps(minutes[-1]), flush=True)
        rss_end = rss_mib(process.pid)
        process.terminate()
        process.wait(30)
    latencies = np.array([s[1] for s in samples]) * 1e3
    errors = sum(1 for s in samples if not s[2])
    result = {
        "machine": {"platform": platform.platform(), "python": platform.python_version()},
        "seconds": args.seconds,
        "sync": args.sync,
        "requests": len(samples),
        "requests_per_s": len(samples) / args.seconds,
        "errors": errors,
        "latency_ms": {
            "p50": float(np.percentile(latencies, 50)),
            "p99": float(np.percentile(latencies, 99)),
            "max": float(latencies.max()),
        },
        "rss_mib": {"start": rss_start, "end": rss_end},
        "journal": minutes[-1] if minutes else None,
        "per_minute": minutes,
    }
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(result, indent=2) + "\n")
    print(json.dumps({k: v for k, v in result.items() if k != "per_minute"}, indent=2))


if __name__ == "__main__":
    main()
