"""The real server (uvicorn on a free loopback port) driven over HTTP by concurrent clients."""

from __future__ import annotations

import os
import socket
import subprocess
import sys
import threading
import time
from collections import Counter
from pathlib import Path
from typing import Any

import httpx
import pytest

from api.settings import Settings
from api.testing import running_server

ROBOTS = 5
SCANS = 30
STEP = 0.01  # s between ticks of the shared clock


class Clock:
    """The simulated time every client takes its detection times from."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._tick = 0

    def next(self) -> float:
        with self._lock:
            self._tick += 1
            return round(self._tick * STEP, 6)


def robot_scan(robot: int, t: float) -> list[dict[str, Any]]:
    """Robot ``robot`` sees itself (moving along y) and its cup at (robot, 5)."""
    source = f"r{robot}"
    return [
        {"time": t, "class": "Robot", "position": [robot * 2.0, 0.1 * t], "label": source,
         "source": source},
        {"time": t, "class": "Cup", "position": [robot * 2.0, 5.0], "source": source},
    ]  # fmt: skip


def test_concurrent_clients_are_serialised_and_every_ack_is_reflected(
    knowledge_file: Path,
) -> None:
    settings = Settings(knowledge=knowledge_file, port=0, reorder_window=2.0)
    clock = Clock()
    statuses: Counter[int] = Counter()
    applied: Counter[int] = Counter()
    problems: list[str] = []
    done = threading.Event()
    lock = threading.Lock()

    def record(response: httpx.Response) -> None:
        with lock:
            statuses[response.status_code] += 1

    def robot(url: str, index: int) -> None:
        with httpx.Client(base_url=url, timeout=30) as client:
            for scan in range(SCANS):
                t = clock.next()
                detections = robot_scan(index, t)
                if scan % 7 == 3:  # an invalid batch: refused whole
                    bad = [*detections, {"time": t, "class": "Cup", "position": [1.0]}]
                    response = client.post("/detections", json={"detections": bad})
                    record(response)
                    if response.status_code != 422:
                        problems.append(f"invalid batch answered {response.status_code}")
                    continue
                response = client.post("/detections", json={"detections": detections})
                record(response)
                if response.status_code != 200:
                    problems.append(f"robot {index}: {response.status_code} {response.text}")
                    continue
                with lock:
                    applied[index] += response.json()["applied"]
                health = client.get("/health")
                record(health)
                if health.json()["time"] < t:
                    problems.append(f"acknowledged time {t} not reflected: {health.json()}")

    def reader(url: str) -> None:
        last = -1.0
        with httpx.Client(base_url=url, timeout=30) as client:
            while not done.is_set():
                for path in ("/world", "/hypotheses", "/health"):
                    response = client.get(path)
                    record(response)
                world = client.get("/world").json()
                if world["time"] is not None:
                    if world["time"] < last:
                        problems.append(f"world time went back: {world['time']} < {last}")
                    last = world["time"]
                    stale = [o for o in world["objects"] if o["last_seen"] > world["time"]]
                    if stale:
                        problems.append(f"objects seen after the world time: {stale}")

    with running_server(settings) as url:
        assert url.startswith("http://127.0.0.1:")
        threads = [threading.Thread(target=robot, args=(url, i)) for i in range(ROBOTS)]
        watcher = threading.Thread(target=reader, args=(url,))
        watcher.start()
        for thread in threads:
            thread.start()
        for thread in threads:
            thread.join()
        done.set()
        watcher.join()
        world = httpx.get(f"{url}/world").json()
        health = httpx.get(f"{url}/health").json()

    assert problems == []
    assert not [code for code in statuses if code >= 500]
    valid_scans = SCANS - len([s for s in range(SCANS) if s % 7 == 3])
    assert applied == {i: 2 * valid_scans for i in range(ROBOTS)}
    assert health["time"] == pytest.approx(clock.next() - STEP)
    labels = {o["label"] for o in world["objects"] if o["class"] == "Robot"}
    assert labels == {f"r{i}" for i in range(ROBOTS)}
    cups = sorted(round(o["position"][0]) for o in world["objects"] if o["class"] == "Cup")
    assert cups == [2 * i for i in range(ROBOTS)]


def free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        port: int = sock.getsockname()[1]
        return port


def test_semwm_serve_command(knowledge_file: Path) -> None:
    port = free_port()
    env = {**os.environ, "SEMWM_MAX_BATCH": "3", "SEMWM_KNOWLEDGE": str(knowledge_file)}
    command = [sys.executable, "-m", "semwm.cli", "serve", "--port", str(port)]
    process = subprocess.Popen(
        command, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True
    )
    url = f"http://127.0.0.1:{port}"
    try:
        deadline = time.monotonic() + 20
        while True:
            assert process.poll() is None, process.communicate()[0]
            try:
                health = httpx.get(f"{url}/health", timeout=1)
                break
            except httpx.TransportError:
                assert time.monotonic() < deadline, "semwm serve did not start"
                time.sleep(0.1)
        assert health.json()["knowledge"] == knowledge_file.name
        batch = [{"time": 1.0, "class": "Cup", "position": [1.0, 1.0]}] * 4
        too_big = httpx.post(f"{url}/detections", json={"detections": batch})
        assert too_big.status_code == 422  # SEMWM_MAX_BATCH=3 took effect
        ok = httpx.post(f"{url}/detections", json={"detections": batch[:3]})
        assert ok.json() == {"applied": 3, "time": 1.0, "ignored": 0, "ignored_detections": []}
        assert httpx.get(f"{url}/docs").status_code == 200
    finally:
        process.terminate()
        process.wait(10)


def test_semwm_serve_without_knowledge_fails_clearly(tmp_path: Path) -> None:
    env = {k: v for k, v in os.environ.items() if not k.startswith("SEMWM_")}
    missing = tmp_path / "nope.yaml"
    command = [sys.executable, "-m", "semwm.cli", "serve", "--knowledge", str(missing)]
    result = subprocess.run(command, env=env, capture_output=True, text=True, timeout=30)
    assert result.returncode == 2
    assert result.stderr.strip().endswith("nope.yaml: no such file")
