"""Long run (issue 15 defect 5): objects keep appearing and leaving; does the service stay flat?

Run: ``python benchmarks/bench_longrun.py [--seconds 600] [--present 10] [--out FILE]``

A real ``semwm serve --knowledge knowledge/sim1.yaml`` in its own process on a
loopback port. A camera scans the table at 10 Hz of *simulated* time, posted one
scan per request as fast as the service answers (closed loop), so ``--seconds``
of simulated time take whatever wall time the service needs. ``--present`` objects
(cups and cans) are on the table at any time; each stays 10-30 s, then leaves and
a new one appears elsewhere (about 15 new objects a minute at the defaults). Each
object present is detected with probability 0.9 per scan (5 cm noise), plus
clutter at the knowledge's rate. Per simulated minute: objects published vs on the
table (and their mean excess, sampled every 5 s: objects that left are published
until their existence falls, so some excess is expected), stored hypotheses and
log10 of the joint count (``/health``, means of the 5 s samples), the server's
RSS (``/proc``), POST latency p50/p99. Flat means: the last minute's RSS, p50
latency and stored hypotheses within 1.5x of the second minute's (the first
includes start-up), and the mean excess of objects not growing (at most
max(2, 1.5x the second minute's)). Writes JSON to ``--out`` (default
``benchmarks/out/longrun.json``) and prints a table.
"""

from __future__ import annotations

import argparse
import json
import platform
import tempfile
import time
from pathlib import Path
from typing import Any

import httpx
import numpy as np
from bench_soak import launch, rss_mib
from tqdm import tqdm

ROOT = Path(__file__).resolve().parents[1]
REGION = ((0.2, 3.8), (0.2, 2.8))  # inside sim1.yaml's region [[0, 4], [0, 3]]
CLASSES = ("Cup", "CokeCan", "BeerCan")
SCAN_HZ = 10.0
P_DETECT = 0.9
NOISE = 0.05
CLUTTER_PER_SCAN = 0.05  # sim1.yaml camera clutter_frequency 0.5 Hz at 10 Hz


class Table:
    """Objects on the table: each stays 10-30 s, then a new one takes its place."""

    def __init__(self, present: int, rng: np.random.Generator) -> None:
        self.rng = rng
        self.objects = [self._new(0.0) for _ in range(present)]
        self.appeared = present

    def _new(self, t: float) -> dict[str, Any]:
        (x0, x1), (y0, y1) = REGION
        return {
            "class": str(self.rng.choice(CLASSES)),
            "xy": (float(self.rng.uniform(x0, x1)), float(self.rng.uniform(y0, y1))),
            "leaves": t + float(self.rng.uniform(10.0, 30.0)),
        }

    def scan(self, t: float) -> list[dict[str, Any]]:
        for i, obj in enumerate(self.objects):
            if obj["leaves"] <= t:
                self.objects[i] = self._new(t)
                self.appeared += 1
        batch = []
        for obj in self.objects:
            if self.rng.random() < P_DETECT:
                x, y = np.asarray(obj["xy"]) + self.rng.normal(0.0, NOISE, 2)
                batch.append({"class": obj["class"], "position": [float(x), float(y)]})
        if self.rng.random() < CLUTTER_PER_SCAN:
            (x0, x1), (y0, y1) = REGION
            xy = [float(self.rng.uniform(x0, x1)), float(self.rng.uniform(y0, y1))]
            batch.append({"class": str(self.rng.choice(CLASSES)), "position": xy})
        return [{"time": round(t, 6), "source": "cam", **d} for d in batch]


def run(seconds: float, present: int, seed: int) -> dict[str, Any]:
    rng = np.random.default_rng(seed)
    table = Table(present, rng)
    minutes: list[dict[str, Any]] = []
    with tempfile.TemporaryDirectory() as tmp:
        process, url = launch([], Path(tmp) / "server.log")
        try:
            with httpx.Client(base_url=url, timeout=60) as client:
                latencies: list[float] = []
                excess: list[int] = []  # objects published - on the table, every 5 s
                stored: list[int] = []  # stored hypotheses, every 5 s
                joint: list[float] = []  # log10 of the joint hypotheses, every 5 s
                errors = 0
                wall = time.monotonic()
                scans = int(seconds * SCAN_HZ)
                for k in tqdm(range(1, scans + 1), desc="long run", unit="scan"):
                    t = k / SCAN_HZ
                    batch = table.scan(t)
                    if batch:
                        sent = time.perf_counter()
                        response = client.post("/detections", json={"detections": batch})
                        latencies.append(time.perf_counter() - sent)
                        errors += response.status_code != 200
                    if k % int(5 * SCAN_HZ) == 0:
                        world = client.get("/world").json()
                        excess.append(len(world["objects"]) - len(table.objects))
                        health = client.get("/health").json()
                        stored.append(health["hypotheses"])
                        joint.append(health["hypotheses_log10_joint"])
                    if k % int(60 * SCAN_HZ) == 0 or k == scans:
                        world = client.get("/world").json()
                        lat = np.asarray(latencies) * 1e3
                        minutes.append(
                            {
                                "sim_s": round(t, 1),
                                "wall_s": round(time.monotonic() - wall, 1),
                                "objects_published": len(world["objects"]),
                                "objects_on_table": len(table.objects),
                                "mean_excess": round(float(np.mean(excess)), 2) if excess else 0.0,
                                "appeared_so_far": table.appeared,
                                "stored_hypotheses": round(float(np.mean(stored or [0])), 1),
                                "log10_joint": round(float(np.mean(joint or [0])), 2),
                                "rss_mib": round(rss_mib(process.pid), 1),
                                "p50_ms": round(float(np.percentile(lat, 50)), 2),
                                "p99_ms": round(float(np.percentile(lat, 99)), 2),
                                "errors": errors,
                            }
                        )
                        latencies, excess, stored, joint, errors = [], [], [], [], 0
        finally:
            process.terminate()
            process.wait(10)
    base = minutes[1] if len(minutes) > 2 else minutes[0]
    last = minutes[-1]

    def ratio(key: str) -> float:
        return float(last[key]) / max(float(base[key]), 1e-9)

    flat = {
        "rss_last_over_second_minute": round(ratio("rss_mib"), 3),
        "p50_last_over_second_minute": round(ratio("p50_ms"), 3),
        "hypotheses_last_over_second_minute": round(ratio("stored_hypotheses"), 3),
        "excess_second_minute": base["mean_excess"],
        "excess_last_minute": last["mean_excess"],
    }
    flat["flat"] = (
        flat["rss_last_over_second_minute"] <= 1.5
        and flat["p50_last_over_second_minute"] <= 1.5
        and flat["hypotheses_last_over_second_minute"] <= 1.5
        and last["mean_excess"] <= max(2.0, 1.5 * base["mean_excess"])
    )
    return {
        "benchmark": "longrun",
        "machine": f"{platform.platform()}, {platform.processor() or platform.machine()}",
        "python": platform.python_version(),
        "sizes": {"sim_seconds": seconds, "present": present, "scan_hz": SCAN_HZ, "seed": seed},
        "minutes": minutes,
        "verdict": flat,
        "errors": sum(m["errors"] for m in minutes),
    }


def table_text(result: dict[str, Any]) -> str:
    keys = [
        "sim_s", "wall_s", "objects_published", "objects_on_table", "mean_excess",
        "appeared_so_far",
        "stored_hypotheses", "log10_joint", "rss_mib", "p50_ms", "p99_ms", "errors",
    ]  # fmt: skip
    lines = [" | ".join(keys), " | ".join("---" for _ in keys)]
    lines += [" | ".join(str(m[k]) for k in keys) for m in result["minutes"]]
    return "\n".join(lines) + f"\n\nverdict: {json.dumps(result['verdict'])}"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seconds", type=float, default=600.0, help="simulated seconds")
    parser.add_argument("--present", type=int, default=10, help="objects on the table at once")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "out" / "longrun.json")
    args = parser.parse_args()
    result = run(args.seconds, args.present, args.seed)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(result, indent=2) + "\n")
    print(table_text(result))
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
