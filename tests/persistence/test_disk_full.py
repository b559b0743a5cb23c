"""Issue 30 case 1: a write is acknowledged if and only if it is durable and applied.

On a 2 MiB tmpfs with ``--snapshot-every 10`` the batch record used to be committed,
the snapshot commit then failed, the world was rolled back and the client got 500 -
but the record stayed in the journal (15 of 15 answered 500 were kept), and a restart
gave a different world. Now the record, the snapshot due with it and the change in
memory commit together or not at all; a full disk answers 507 with ``Retry-After``,
reads are served, ``/ready`` is 503, and writes resume by themselves.

Two ways to fill the disk: a fault hook that raises SQLite's own "database or disk is
full" at each step (always runs), and a real 2 MiB tmpfs (runs where the test may
mount one: as root with CAP_SYS_ADMIN; skipped elsewhere, saying so).
"""

from __future__ import annotations

import contextlib
import os
import sqlite3
import subprocess
import uuid
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import httpx
import pytest
from fastapi.testclient import TestClient

from api.app import create_app
from api.settings import Settings
from api.testing import running_server
from semwm import load_knowledge
from semwm.knowledge.shipped import shipped_knowledge_path
from semwm.persistence import DurableWorld, WriteFailed, model_digest

SIM1 = shipped_knowledge_path("sim1.yaml")


def batch(step: int, size: int = 3) -> dict[str, Any]:
    t = 0.1 * step
    return {
        "detections": [
            {"time": t, "class": "Cup", "position": [1.0 + i, 2.0], "source": "r1"}
            for i in range(size)
        ]
    }


def _full(step: str) -> Any:
    def fault(at: str) -> None:
        if at in (step, "probe"):
            raise sqlite3.OperationalError("database or disk is full")

    return fault


@contextlib.contextmanager
def _client(data_dir: Path, snapshot_every: int = 3) -> Iterator[TestClient]:
    settings = Settings(
        knowledge=SIM1,
        data_dir=data_dir,
        snapshot_every=snapshot_every,
        allowed_hosts=("testserver",),
    )
    with TestClient(create_app(settings)) as client:
        yield client


def _reopen_digest(data_dir: Path) -> tuple[str, int]:
    world = DurableWorld.open(data_dir, load_knowledge(SIM1))
    try:
        batches = sum(1 for r in world.records() if r.kind == "batch")
        return model_digest(world.model), batches
    finally:
        world.close()


@pytest.mark.parametrize("step", ["append", "snapshot", "commit"])
def test_a_full_disk_refuses_the_write_keeps_nothing_and_resumes(tmp_path: Path, step: str) -> None:
    data_dir = tmp_path / "data"
    with _client(data_dir, snapshot_every=1) as client:  # each write snapshots too
        acknowledged = 0
        for i in range(2):
            assert client.post("/detections", json=batch(i)).status_code == 200
            acknowledged += 1
        before = client.get("/persistence").json()
        world = client.get("/world").json()
        journal = client.app.state.durable.journal  # type: ignore[attr-defined]
        journal.fault = _full(step)
        for i in range(2, 5):
            refused = client.post("/detections", json=batch(i))
            assert refused.status_code == 507, refused.text
            assert int(refused.headers["retry-after"]) >= 1
            assert "disk is full" in refused.json()["detail"]
        reset = client.post("/reset")
        assert reset.status_code == 507 and "retry-after" in reset.headers
        # nothing refused was kept, reads are served, /ready says why it is not ready
        after = client.get("/persistence").json()
        assert after["digest"] == before["digest"]
        assert after["journal"]["last_seq"] == before["journal"]["last_seq"]
        assert after["journal"]["write_failures"] == 4
        assert client.get("/world").json() == world
        ready = client.get("/ready")
        assert ready.status_code == 503 and "full" in " ".join(ready.json()["reasons"])
        # space returns: /ready sees it by itself, and the next write goes through
        journal.fault = None
        assert client.get("/ready").status_code == 200
        for i in range(5, 9):
            assert client.post("/detections", json=batch(i)).status_code == 200
            acknowledged += 1
        served = client.get("/persistence").json()["digest"]
    digest, batches = _reopen_digest(data_dir)
    assert (digest, batches) == (served, acknowledged)


def test_a_snapshot_that_cannot_be_written_does_not_keep_its_record(tmp_path: Path) -> None:
    """The issue's sequence in process: the snapshot step fails after the record was
    appended; the record goes with it."""
    world = DurableWorld.open(tmp_path / "data", load_knowledge(SIM1), snapshot_every=1)
    try:
        world.ingest(batch(0)["detections"])
        seq = world.journal.last_seq()
        assert [s.seq for s in world.journal.snapshots()] == [seq]
        digest = model_digest(world.model)
        world.journal.fault = _full("snapshot")
        with pytest.raises(WriteFailed) as failed:
            world.ingest(batch(1)["detections"])
        assert failed.value.full
        assert world.journal.last_seq() == seq
        assert [s.seq for s in world.journal.snapshots()] == [seq]
        assert model_digest(world.model) == digest
        world.journal.fault = None
        world.ingest(batch(1)["detections"])
        assert world.journal.last_seq() == seq + 1
        assert [s.seq for s in world.journal.snapshots()] == [seq + 1, seq]
    finally:
        world.close()


# -- a real full disk ---------------------------------------------------------------------------


@contextlib.contextmanager
def _tmpfs(size: str) -> Iterator[Path]:
    where = Path("/tmp") / f"semwm-tmpfs-{uuid.uuid4().hex[:8]}"
    where.mkdir()
    try:
        mounted = (
            os.geteuid() == 0
            and subprocess.run(
                ["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", str(where)],
                capture_output=True,
                timeout=10,
            ).returncode
            == 0
        )
    except (OSError, subprocess.SubprocessError):
        mounted = False
    if not mounted:
        where.rmdir()
        pytest.skip("cannot mount a tmpfs here (needs root); the fault-hook tests cover it")
    try:
        yield where
    finally:
        subprocess.run(["umount", "-l", str(where)], capture_output=True, timeout=10)
        with contextlib.suppress(OSError):
            where.rmdir()


@pytest.mark.slow
def test_a_real_full_tmpfs_acknowledges_exactly_what_it_keeps() -> None:
    with _tmpfs("2m") as disk:
        data_dir = disk / "data"
        filler = disk / "filler"
        settings = Settings(knowledge=SIM1, data_dir=data_dir, snapshot_every=10, port=0)
        acknowledged: list[int] = []
        refused: list[int] = []
        with running_server(settings) as url, httpx.Client(base_url=url, timeout=10) as http:
            assert http.post("/detections", json=batch(0, 10)).status_code == 200
            acknowledged.append(0)
            # fill the disk but for a little room
            free = os.statvfs(disk).f_bavail * os.statvfs(disk).f_frsize
            filler.write_bytes(b"\0" * max(0, free - 96 * 1024))
            step = 1
            while len(refused) < 5 and step < 2000:
                answer = http.post("/detections", json=batch(step, 10))
                assert answer.status_code in (200, 507), answer.text
                (acknowledged if answer.status_code == 200 else refused).append(step)
                if answer.status_code == 507:
                    assert "retry-after" in answer.headers
                step += 1
            assert len(refused) == 5, "the disk never filled"
            assert http.get("/world").status_code == 200
            assert http.get("/ready").status_code == 503
            served_full = http.get("/persistence").json()["digest"]
            filler.unlink()  # space returns
            assert http.get("/ready").status_code == 200
            for extra in range(step, step + 12):  # past the next snapshot
                assert http.post("/detections", json=batch(extra, 10)).status_code == 200
                acknowledged.append(extra)
            served = http.get("/persistence").json()["digest"]
            assert served != served_full
        digest, batches = _reopen_digest(data_dir)
        assert batches == len(acknowledged)
        assert digest == served
