"""kill -9 of the real server with --data-dir: every acknowledged batch survives, and the
restarted server publishes exactly the world the journal's records rebuild."""

from __future__ import annotations

import os
import random
import re
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import httpx
import pytest

from semwm.knowledge.shipped import shipped_knowledge_path
from semwm.persistence import Replayer, model_digest
from semwm.persistence.journal import DATABASE, Journal
from semwm.sources import DEFAULT_ORDER_TOLERANCE

SOURCES = 3
KILL_ROUNDS = 3
_LISTENING = re.compile(r"Uvicorn running on (http://127\.0\.0\.1:\d+)")


_STARTED: list[subprocess.Popen[bytes]] = []


@pytest.fixture(autouse=True)
def _no_server_left() -> Iterator[None]:
    """A failed assertion leaves no server running after its test."""
    yield
    while _STARTED:
        process = _STARTED.pop()
        if process.poll() is None:
            process.kill()
            process.wait(10)


class Server:
    """``semwm serve --port 0 --data-dir DIR`` in a subprocess (so it can be SIGKILLed)."""

    def __init__(self, data_dir: Path, log: Path, *options: str) -> None:
        knowledge = shipped_knowledge_path("sim1.yaml")
        command = [
            sys.executable, "-m", "semwm.cli", "serve", "--knowledge", str(knowledge),
            "--port", "0", "--data-dir", str(data_dir), "--reorder-window", "1.0",
            "--snapshot-every", "25", "--compact-every", "40", "--log-level", "info",
            *options,
        ]  # fmt: skip
        self.log = log
        with log.open("w") as out:
            self.process = subprocess.Popen(command, stdout=out, stderr=subprocess.STDOUT)
        _STARTED.append(self.process)
        deadline = time.monotonic() + 30
        while True:
            found = _LISTENING.search(log.read_text())
            if found:
                self.url = found.group(1)
                return
            if self.process.poll() is not None or time.monotonic() > deadline:
                self.process.kill()
                pytest.fail(f"the server did not start:\n{log.read_text()}")
            time.sleep(0.05)

    def kill(self) -> None:
        os.kill(self.process.pid, signal.SIGKILL)
        self.process.wait(10)

    def state(self) -> dict[str, Any]:
        response = httpx.get(f"{self.url}/persistence", timeout=10)
        response.raise_for_status()
        return dict(response.json())


def stream(url: str, source: int, start: float, stop: threading.Event, acked: list[Any]) -> None:
    """Post one detection batch per tick until ``stop``; keep the acknowledged ones."""
    rng = random.Random(source)
    t = start
    with httpx.Client(base_url=url, timeout=10) as client:
        for _ in range(400):  # bounded: the kill comes long before
            if stop.is_set():
                return
            t = round(t + 0.05, 6)
            batch = [
                {"time": t, "class": "Cup", "source": f"s{source}",
                 "position": [0.5 + source + rng.gauss(0, 0.02), 1.0 + rng.gauss(0, 0.02)]},
            ]  # fmt: skip
            try:
                response = client.post("/detections", json={"detections": batch})
            except httpx.TransportError:
                return  # the server died: this batch was not acknowledged
            if response.status_code == 200:
                acked.append(batch)


def offline(data_dir: Path) -> tuple[list[Any], str]:
    """The batches of the journal and the digest of a from-scratch replay of it."""
    journal = Journal(data_dir, "batch")
    try:
        archived = int(journal.meta("archived_through") or 0)
        records = [*journal.archived_records(), *journal.records(after=archived)]
    finally:
        journal.close()
    replayer = Replayer()
    for record in records:
        replayer.apply(record)
    assert replayer.model is not None
    return [r.payload for r in records if r.kind == "batch"], model_digest(replayer.model)


def test_sigkill_at_random_moments_loses_no_acknowledged_batch(tmp_path: Path) -> None:
    seed = random.randrange(10**6)
    rng = random.Random(seed)
    data_dir = tmp_path / "data"
    acked: list[Any] = []
    start = 0.0
    server = Server(data_dir, tmp_path / "server0.log")
    for round_ in range(KILL_ROUNDS):
        stop = threading.Event()
        threads = [
            threading.Thread(target=stream, args=(server.url, s, start, stop, acked))
            for s in range(SOURCES)
        ]
        for thread in threads:
            thread.start()
        seen: tuple[int, str] | None = None
        deadline = time.monotonic() + rng.uniform(0.5, 2.0)
        while time.monotonic() < deadline:
            state = server.state()
            seen = (state["journal"]["last_seq"], state["digest"])
            time.sleep(0.05)
        server.kill()  # mid-stream, at a random moment
        stop.set()
        for thread in threads:
            thread.join(15)
        server = Server(data_dir, tmp_path / f"server{round_ + 1}.log")
        restored = server.state()
        batches, digest = offline(data_dir)
        where = f"seed {seed}, round {round_}"
        missing = [b for b in acked if not any(_same_batch(b, j) for j in batches)]
        assert not missing, f"{where}: {len(missing)} acknowledged batches lost"
        assert restored["digest"] == digest, f"{where}: restored world differs from the journal"
        assert restored["journal"]["recovery"]["cut"] is None, where
        assert seen is not None
        # The world published at a polled moment is the one its records rebuild.
        seq, published = seen
        assert _digest_through(data_dir, seq) == published, where
        start = max(d["time"] for b in batches for d in b) + 1.0 if batches else start
    assert acked, "no batch was acknowledged at all"
    assert restored["journal"]["archives"] >= 1, "compaction never ran"
    server.kill()


def _same_batch(sent: list[dict[str, Any]], journaled: list[dict[str, Any]]) -> bool:
    """The journal holds the batch as applied: a scan placed in arrival order has its time
    moved forward by at most the service's order tolerance, nothing else differs."""
    if len(sent) != len(journaled):
        return False
    for a, b in zip(sent, journaled, strict=True):
        if {k: v for k, v in a.items() if k != "time"} != {
            k: v for k, v in b.items() if k != "time"
        }:
            return False
        if not 0.0 <= b["time"] - a["time"] <= DEFAULT_ORDER_TOLERANCE:
            return False
    return True


def _digest_through(data_dir: Path, seq: int) -> str:
    journal = Journal(data_dir, "batch")
    replayer = Replayer()
    try:
        archived = int(journal.meta("archived_through") or 0)
        for record in [*journal.archived_records(), *journal.records(after=archived)]:
            if record.seq > seq:
                break
            replayer.apply(record)
    finally:
        journal.close()
    assert replayer.model is not None
    return model_digest(replayer.model)


def test_truncated_write_ahead_log_is_cut_at_the_last_whole_commit(tmp_path: Path) -> None:
    data_dir = tmp_path / "data"
    server = Server(data_dir, tmp_path / "a.log")
    with httpx.Client(base_url=server.url, timeout=10) as client:
        for i in range(30):
            batch = [{"time": 0.1 * i, "class": "Cup", "position": [1.0, 1.0], "source": "a"}]
            assert client.post("/detections", json={"detections": batch}).status_code == 200
    server.kill()
    wal = data_dir / (DATABASE + "-wal")
    size = wal.stat().st_size
    assert size > 1000, "the commits should still be in the write-ahead log"
    with wal.open("r+b") as handle:  # power loss mid-write: the last frames are torn
        handle.truncate(size - 700)
    # acknowledged records are gone: the service says so and, by default, does not start
    refused = subprocess.run(
        [sys.executable, "-m", "semwm.cli", "serve", "--knowledge",
         str(shipped_knowledge_path("sim1.yaml")), "--port", "0", "--data-dir", str(data_dir)],
        capture_output=True, text=True, timeout=60,
    )  # fmt: skip
    assert refused.returncode != 0 and "are lost" in refused.stderr + refused.stdout
    server = Server(data_dir, tmp_path / "b.log", "--on-damage", "truncate")
    state = server.state()
    batches, digest = offline(data_dir)
    assert state["digest"] == digest
    assert 0 < len(batches) < 30, "SQLite keeps the whole commits before the torn frame"
    times = [b[0]["time"] for b in batches]
    assert times == [0.1 * i for i in range(len(batches))], "a prefix, in order"
    recovery = state["journal"]["recovery"]
    assert recovery["lost"] == [2 + len(batches) + 1, 2 + 30] and not recovery["new"]
    server.kill()
