"""Issue 30 case 2: a damaged store is detected, named and never taken for a new one.

Base: records committed into the write-ahead log and the files left as a kill -9
leaves them (the connection still open). SQLite alone could not tell: a WAL cut by
100 bytes lost 1 record, cut in half 130, filled with garbage all but the first 2,
and a deleted WAL or a database cut to 0 bytes gave an empty world (a deleted WAL
even ``"new": true``), each with ``cut: null`` and nothing logged above INFO.
"""

from __future__ import annotations

import logging
import os
import random
import shutil
from collections.abc import Callable
from pathlib import Path

import pytest
from fastapi.testclient import TestClient

from api.app import create_app
from api.settings import Settings
from semwm import load_knowledge
from semwm.knowledge.shipped import shipped_knowledge_path
from semwm.persistence import DurableWorld, StoreError
from semwm.persistence.journal import DATABASE, HEAD

SIM1 = shipped_knowledge_path("sim1.yaml")
KNOWLEDGE = load_knowledge(SIM1)
BATCHES = 40
SETUP = 2  # the config and knowledge records of a new directory


def _batch(step: int) -> list[dict[str, object]]:
    return [{"time": 0.1 * step, "class": "Cup", "position": [1.0 + 0.01 * step, 2.0]}]


def _killed(tmp_path: Path) -> Path:
    """A data directory as kill -9 leaves it: every batch committed into the WAL, which
    no checkpoint has moved into the database yet."""
    live = tmp_path / "live"
    world = DurableWorld.open(live, KNOWLEDGE, snapshot_every=10_000)
    for step in range(BATCHES):
        world.ingest(_batch(step))
    left = tmp_path / "left"
    left.mkdir()
    for name in (DATABASE, DATABASE + "-wal", HEAD):
        shutil.copyfile(live / name, left / name)  # while open: no checkpoint
    world.close()
    assert (left / (DATABASE + "-wal")).stat().st_size > 0
    return left


def _cut(by: int) -> Callable[[Path], None]:
    def damage(path: Path) -> None:
        wal = path / (DATABASE + "-wal")
        size = wal.stat().st_size
        os.truncate(wal, size - by if by > 0 else size // 2)

    return damage


def _garbage(path: Path) -> None:
    wal = path / (DATABASE + "-wal")
    wal.write_bytes(random.Random(7).randbytes(wal.stat().st_size))


def _delete_wal(path: Path) -> None:
    (path / (DATABASE + "-wal")).unlink()


def _empty_database(path: Path) -> None:
    os.truncate(path / DATABASE, 0)
    (path / (DATABASE + "-wal")).unlink()


DAMAGE = {
    "wal cut by 100 bytes": _cut(100),
    "wal cut in half": _cut(0),
    "wal filled with garbage": _garbage,
    "wal deleted": _delete_wal,
    "database emptied": _empty_database,
}


@pytest.mark.parametrize("how", list(DAMAGE))
def test_damage_is_detected_refused_or_truncated_and_never_new(
    tmp_path: Path, how: str, caplog: pytest.LogCaptureFixture
) -> None:
    data = _killed(tmp_path)
    DAMAGE[how](data)
    last = SETUP + BATCHES
    with pytest.raises(StoreError) as refused:
        DurableWorld.open(data, KNOWLEDGE, on_damage="refuse")
    message = str(refused.value)
    assert f"to {last} are lost" in message and "--on-damage truncate" in message
    caplog.clear()
    with caplog.at_level(logging.ERROR, logger="semwm.persistence"):
        world = DurableWorld.open(data, KNOWLEDGE, on_damage="truncate")
    try:
        recovery = world.recovery
        assert not recovery.new and recovery.damage
        survived = recovery.replayed  # no snapshot: every record left was replayed
        assert survived < last
        assert recovery.lost == [survived + 1, last]
        assert any(r.levelno == logging.ERROR for r in caplog.records)
        assert world.status()["recovery"]["lost"] == [survived + 1, last]
    finally:
        world.close()
    # what is left is the journal now: the next start is clean
    again = DurableWorld.open(data, KNOWLEDGE, on_damage="refuse")
    assert not again.recovery.damage and not again.recovery.new
    again.close()


def test_an_intact_store_after_kill_reports_nothing(tmp_path: Path) -> None:
    data = _killed(tmp_path)
    world = DurableWorld.open(data, KNOWLEDGE, on_damage="refuse")
    try:
        assert world.journal.last_seq() == SETUP + BATCHES
        assert world.recovery.damage == [] and world.recovery.lost is None
        assert not world.recovery.new and world.recovery.replayed == SETUP + BATCHES
    finally:
        world.close()


def test_a_gap_in_the_sequence_is_damage(tmp_path: Path) -> None:
    data = _killed(tmp_path)
    world = DurableWorld.open(data, KNOWLEDGE)
    world.journal._db.execute("DELETE FROM journal WHERE seq IN (10, 11)")
    world.close()
    with pytest.raises(StoreError, match="records 10 to 11 are missing"):
        DurableWorld.open(data, KNOWLEDGE, on_damage="refuse")


def test_the_service_refuses_to_start_or_shows_the_damage(tmp_path: Path) -> None:
    data = _killed(tmp_path)
    _cut(0)(data)
    refusing = Settings(knowledge=SIM1, data_dir=data, allowed_hosts=("testserver",))
    assert refusing.on_damage == "refuse"
    with pytest.raises(StoreError), TestClient(create_app(refusing)):
        pass
    settings = refusing.model_copy(update={"on_damage": "truncate"})
    with TestClient(create_app(settings)) as client:
        health = client.get("/health").json()
        assert health["store_damage"] and health["lost_records"][1] == SETUP + BATCHES
        metrics = client.get("/metrics").text
        assert "semwm_store_damaged 1.0" in metrics
        lost = health["lost_records"][1] - health["lost_records"][0] + 1
        assert f"semwm_store_lost_records {float(lost)}" in metrics
        recovery = client.get("/persistence").json()["journal"]["recovery"]
        assert recovery["lost"] == health["lost_records"] and not recovery["new"]
