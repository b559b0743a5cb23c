"""Benchmark of the MQTT bridge: N robots at 30 Hz into one global model over a real Mosquitto.

Run: ``python benchmarks/bench_mqtt.py [--robots 20] [--rate 30] [--seconds 60]``
(needs ``pip install -e ".[mqtt]"`` and the Debian package ``mosquitto``; not in CI).

A private Mosquitto (persistence on) runs on a free loopback port; the global model
runs as ``semwm serve --knowledge knowledge/robocup.yaml --mqtt ...`` in its own
process. Each simulated robot (one paho client each, persistent session) publishes
one batch per 1/rate s on ``semwm/detections/<robot>``: its own pose (class
``Peer``, its name as label, detector ``self_localization``), stamped with the
shared monotonic clock. Half-way the broker is stopped (SIGTERM) and started again.

Reported:

* end-to-end latency p50/p99: a batch is published -> the first ``semwm/world``
  message in which the robot's object has ``last_seen`` at or after the batch's time;
* messages lost: batches the broker acknowledged (PUBACK) that the global model
  neither applied nor refused, from the bridge's counters on ``semwm/status``;
  refused (409, older than the reorder window) batches are counted apart;
* global model CPU: user + system time of the service process over the run, as a
  share of one core and per applied batch;
* the restart: how long the broker was down, and the latency around it.

Writes ``benchmarks/out/mqtt.{json,md}`` (``--update-results``: ``benchmarks/results/``).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

import httpx
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from baselines import RESULTS, add_output_arguments, fmt, machine_info, write_results

from api.mqtt_testing import PrivateBroker, free_port
from semwm.mqtt.client import MqttLink
from semwm.mqtt.protocol import Topics

ROOT = Path(__file__).resolve().parents[1]
TOPICS = Topics("semwm")


def cpu_seconds(pid: int) -> float:
    """User + system CPU time of process ``pid`` (Linux /proc)."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


class Robot:
    """One simulated robot: publishes its pose at ``rate`` Hz and records what was acked."""

    def __init__(self, index: int, broker: Any, t0: float) -> None:
        self.name = f"r{index}"
        self.index = index
        self.t0 = t0
        self.lock = threading.Lock()
        self.sent: dict[int, tuple[float, float]] = {}  # mid -> (stamp, wall time published)
        self.acked: set[int] = set()
        self.stamps: list[tuple[float, float]] = []  # (stamp, wall) in publication order
        self.link = MqttLink(broker, f"bench-{self.name}", on_acknowledged=self._ack)

    def _ack(self, mid: int) -> None:
        with self.lock:
            self.acked.add(mid)

    def position(self, t: float) -> list[float]:
        x0, y0 = (self.index % 5) * 2.0 - 4.0, (self.index // 5) * 2.0 - 3.0
        return [x0 + 0.3 * math.cos(0.5 * t), y0 + 0.3 * math.sin(0.5 * t)]

    def run(self, rate: float, seconds: float) -> None:
        period = 1.0 / rate
        start = time.monotonic()
        k = 0
        while True:
            due = start + k * period
            if due - start >= seconds:
                return
            pause = due - time.monotonic()
            if pause > 0:
                time.sleep(pause)
            now = time.monotonic()
            stamp = round(now - self.t0, 6)
            body = {"time": stamp, "class": "Peer", "position": self.position(stamp),
                    "label": self.name, "detector": "self_localization"}  # fmt: skip
            info = self.link.publish(TOPICS.detections(self.name), json.dumps(body).encode())
            with self.lock:
                self.sent[info.mid] = (stamp, now)
                self.stamps.append((stamp, now))
            k += 1


class WorldWatcher:
    """Subscribes to the world and status; turns world messages into latency samples."""

    def __init__(self, broker: Any, robots: list[Robot]) -> None:
        self.robots = {r.name: r for r in robots}
        self.next = dict.fromkeys(self.robots, 0)  # per robot: index of the first unseen stamp
        self.samples: list[tuple[float, float]] = []  # (wall time published, latency s)
        self.status: dict[str, Any] = {}
        self.worlds = 0
        self.lock = threading.Lock()
        self.link = MqttLink(
            broker,
            "bench-watcher",
            subscriptions=[TOPICS.world, TOPICS.status],
            on_message=self._message,
        )

    def _message(self, topic: str, payload: bytes) -> None:
        now = time.monotonic()
        data = json.loads(payload)
        with self.lock:
            if topic == TOPICS.status:
                self.status = data
                return
            self.worlds += 1
            for obj in data["objects"]:
                robot = self.robots.get(obj.get("label") or "")
                if robot is None:
                    continue
                with robot.lock:
                    stamps = robot.stamps[self.next[robot.name] :]
                seen = 0
                for stamp, wall in stamps:
                    if stamp > obj["last_seen"] + 1e-9:
                        break
                    self.samples.append((wall, now - wall))
                    seen += 1
                self.next[robot.name] += seen


def start_service(
    broker_url: str, rate: float, reorder: float
) -> tuple[subprocess.Popen[bytes], str]:
    port = free_port()
    knowledge = ROOT / "knowledge" / "robocup.yaml"
    command = [
        sys.executable, "-m", "semwm.cli", "serve", "--knowledge", str(knowledge),
        "--port", str(port), "--log-level", "warning", "--reorder-window", str(reorder),
        "--mqtt", broker_url, "--mqtt-world-rate", str(rate),
    ]  # fmt: skip
    process = subprocess.Popen(command, cwd=ROOT)
    url = f"http://127.0.0.1:{port}"
    deadline = time.monotonic() + 60
    while True:
        try:
            if httpx.get(f"{url}/health", timeout=1).status_code == 200:
                return process, url
        except httpx.HTTPError:
            pass
        if process.poll() is not None or time.monotonic() > deadline:
            process.kill()
            raise RuntimeError("the service did not start")
        time.sleep(0.1)


def percentile(values: list[float], q: float) -> float | None:
    return float(np.percentile(values, q)) if values else None


def summary(values: list[float]) -> dict[str, float | None]:
    return {
        "p50": percentile(values, 50),
        "p99": percentile(values, 99),
        "max": max(values) if values else None,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--robots", type=int, default=20)
    parser.add_argument("--rate", type=float, default=30.0, help="batches/s per robot")
    parser.add_argument("--seconds", type=float, default=60.0)
    parser.add_argument("--world-rate", type=float, default=30.0, help="--mqtt-world-rate")
    parser.add_argument("--reorder-window", type=float, default=5.0)
    parser.add_argument(
        "--drain-timeout", type=float, default=600.0,
        help="longest wait for the service to work off its backlog (s)",
    )  # fmt: skip
    parser.add_argument("--no-restart", action="store_true", help="keep the broker up")
    add_output_arguments(parser)
    args = parser.parse_args()

    with tempfile.TemporaryDirectory() as tmp:
        broker = PrivateBroker(Path(tmp))
        broker.start()
        service, _ = start_service(broker.url, args.world_rate, args.reorder_window)
        try:
            result = run(args, broker, service.pid)
        finally:
            service.terminate()
            service.wait(30)
            broker.stop()
    doc = {"benchmark": "mqtt", "machine": machine_info(), "settings": vars(args), "result": result}
    write_results(RESULTS, "mqtt", doc, markdown(doc), False, update_results=args.update_results)


def run(args: argparse.Namespace, broker: PrivateBroker, pid: int) -> dict[str, Any]:
    t0 = time.monotonic()
    robots = [Robot(i, broker.broker, t0) for i in range(args.robots)]
    watcher = WorldWatcher(broker.broker, robots)
    for link in [watcher.link, *(r.link for r in robots)]:
        link.start()
    for link in [watcher.link, *(r.link for r in robots)]:
        if not link.wait_connected(30):
            raise RuntimeError(f"{link.client_id} could not connect")
    cpu_start, wall_start = cpu_seconds(pid), time.monotonic()
    threads = [threading.Thread(target=r.run, args=(args.rate, args.seconds)) for r in robots]
    for thread in threads:
        thread.start()
    restart: dict[str, Any] = {}
    if not args.no_restart:
        time.sleep(args.seconds / 2)
        down = time.monotonic()
        broker.stop()
        broker.start()
        up = time.monotonic()
        restart = {"at_s": round(down - wall_start, 2), "down_s": round(up - down, 3)}
    for thread in threads:
        thread.join()
    published = sum(len(r.sent) for r in robots)
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and not all(set(r.sent) <= r.acked for r in robots):
        time.sleep(0.1)
    acked = {r.name: len(r.acked & set(r.sent)) for r in robots}
    # wait (bounded) for the global model to account for every acknowledged batch
    deadline = time.monotonic() + args.drain_timeout
    while time.monotonic() < deadline:
        with watcher.lock:
            sources = watcher.status.get("sources", {})
        done = all(
            sources.get(n, {}).get("batches", 0) + sources.get(n, {}).get("refused", 0) >= a
            for n, a in acked.items()
        )
        if done:
            break
        time.sleep(0.2)
    wall = time.monotonic() - wall_start
    drained_s = round(wall - args.seconds, 2)
    cpu = cpu_seconds(pid) - cpu_start
    time.sleep(0.5)
    with watcher.lock:
        status = dict(watcher.status)
        samples = list(watcher.samples)
        worlds = watcher.worlds
    for link in [watcher.link, *(r.link for r in robots)]:
        link.stop()
    sources = status.get("sources", {})
    applied = sum(s.get("batches", 0) for s in sources.values())
    refused = sum(s.get("refused", 0) for s in sources.values())
    accounted = {
        n: sources.get(n, {}).get("batches", 0) + sources.get(n, {}).get("refused", 0)
        for n in acked
    }
    lost = sum(max(0, a - accounted[n]) for n, a in acked.items())
    latencies = [lat * 1000 for _, lat in samples]
    result: dict[str, Any] = {
        "robots": args.robots,
        "rate_hz": args.rate,
        "seconds": args.seconds,
        "published": published,
        "acknowledged": sum(acked.values()),
        "applied": applied,
        "refused": refused,
        "refused_by_status": status.get("refused_by_status", {}),
        "duplicates_skipped": status.get("duplicates", 0),
        "lost": lost,
        "world_messages": worlds,
        "latency_samples": len(latencies),
        "latency_ms": summary(latencies),
        "service_cpu_s": round(cpu, 2),
        "service_wall_s": round(wall, 2),
        "service_cpu_share": round(cpu / wall, 3),
        "service_cpu_ms_per_batch": round(1000 * cpu / applied, 3) if applied else None,
        "restart": restart,
        "backlog_drained_s_after_publishing": drained_s,
    }
    if restart:
        at = wall_start + restart["at_s"]
        calm = [lat * 1000 for w, lat in samples if w < at - 2 or w > at + 10]
        around = [lat * 1000 for w, lat in samples if at - 2 <= w <= at + 10]
        result["latency_ms_away_from_restart"] = summary(calm)
        result["latency_ms_restart_window"] = summary(around)
    return result


def markdown(doc: dict[str, Any]) -> str:
    r = doc["result"]
    m = doc["machine"]
    restart = r["restart"]
    restarted = "none"
    if restart:
        restarted = f"down {fmt(restart['down_s'])} s at {fmt(restart['at_s'])} s"
    lines = [
        "## MQTT: robots -> Mosquitto -> one global model",
        "",
        f"Backlog worked off {fmt(r['backlog_drained_s_after_publishing'])} s after the robots "
        f"stopped publishing; {r['world_messages']} world messages received.",
        "",
        f"Machine: {m['platform']}, {m['cpu_count']} CPUs, Python {m['python']}, {m['date']}; "
        f"broker, service and robots on the same CPUs.",
        "",
        "| robots x Hz | s | published | acked | applied | refused | lost | p50 ms | p99 ms "
        "| service CPU (cores) | CPU ms/batch | restart |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
        f"| {r['robots']} x {fmt(r['rate_hz'])} | {fmt(r['seconds'])} | {r['published']} "
        f"| {r['acknowledged']} | {r['applied']} | {r['refused']} | {r['lost']} "
        f"| {fmt(r['latency_ms']['p50'])} | {fmt(r['latency_ms']['p99'])} "
        f"| {fmt(r['service_cpu_share'])} | {fmt(r['service_cpu_ms_per_batch'])} "
        f"| {restarted} |",
        "",
    ]  # fmt: skip
    if r["restart"]:
        away, near = r["latency_ms_away_from_restart"], r["latency_ms_restart_window"]
        lines += [
            f"Latency away from the restart: p50 {fmt(away['p50'])} ms, "
            f"p99 {fmt(away['p99'])} ms; from 2 s before to 10 s after it: "
            f"p50 {fmt(near['p50'])} ms, p99 {fmt(near['p99'])} ms, max {fmt(near['max'])} ms.",
            "",
        ]
    return "\n".join(lines)


if __name__ == "__main__":
    main()
