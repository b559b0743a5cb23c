"""The journal: any sequence of batches, resets and knowledge edits replays to the same
world; damaged records and torn tails are cut at the last good record; snapshots of
other code are rebuilt from the journal, never read."""

from __future__ import annotations

import contextlib
import io
import sqlite3
from pathlib import Path
from typing import Any

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from semwm import load_knowledge
from semwm.detection import DetectionError, OutOfOrderError
from semwm.knowledge import KnowledgeDocument, resolve
from semwm.knowledge.model import Knowledge
from semwm.knowledge.shipped import shipped_knowledge_path
from semwm.persistence import DurableWorld, Replayer, model_digest, read_jsonl
from semwm.persistence.journal import DATABASE
from semwm.persistence.records import ReadReport
from semwm.persistence.snapshot import Snapshot

KNOWLEDGE = load_knowledge(shipped_knowledge_path("sim1.yaml"))
CLASSES = ("CokeCan", "Can", "Cup", "BeerCan")


def edited(knowledge: Knowledge, frequency: float) -> Knowledge:
    """``knowledge`` with Cup's detection frequency changed (a class edit)."""
    document = knowledge.document
    classes = tuple(
        c.model_copy(update={"detection_frequency": frequency}) if c.name == "Cup" else c
        for c in document.classes
    )
    new = KnowledgeDocument.model_validate({**dict(document), "classes": classes})
    return resolve(new, knowledge.source)


detection = st.fixed_dictionaries(
    {
        "class": st.sampled_from(CLASSES),
        "position": st.tuples(st.floats(0.2, 3.8), st.floats(0.2, 2.8)),
        "source": st.sampled_from(["a", "b"]),
        "dt": st.sampled_from([0.0, 0.1, 0.3, -0.2]),
    }
)
operation = st.one_of(
    st.tuples(st.just("batch"), st.lists(detection, min_size=1, max_size=4)),
    st.tuples(st.just("bad"), st.just(None)),
    st.tuples(st.just("reset"), st.just(None)),
    st.tuples(st.just("edit"), st.sampled_from([0.5, 2.0, 4.0])),
)


def apply(world: DurableWorld, op: tuple[str, Any], clock: list[float]) -> None:
    kind, value = op
    if kind == "batch":
        clock[0] += 0.2
        batch = [
            {"time": round(clock[0] + d["dt"], 6), "class": d["class"],
             "position": list(d["position"]), "source": d["source"]}
            for d in value
        ]  # fmt: skip
        with contextlib.suppress(OutOfOrderError):
            world.ingest(batch)
    elif kind == "bad":
        with pytest.raises(DetectionError):
            world.ingest([{"time": clock[0], "class": "Cup", "position": [1.0]}])
    elif kind == "reset":
        world.reset()
    else:
        world.replace_knowledge(edited(world.model.knowledge, value))


def replay_all(world: DurableWorld) -> str:
    replayer = Replayer()
    for record in world.records():
        replayer.apply(record)
    assert replayer.model is not None
    return model_digest(replayer.model)


@settings(
    max_examples=25, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(ops=st.lists(operation, max_size=25), snapshot_every=st.sampled_from([1, 3, 50]))
def test_any_sequence_replays_to_the_same_world(
    tmp_path_factory: pytest.TempPathFactory, ops: list[tuple[str, Any]], snapshot_every: int
) -> None:
    data_dir = tmp_path_factory.mktemp("data")
    world = DurableWorld.open(
        data_dir, KNOWLEDGE, reorder_window=0.5, snapshot_every=snapshot_every, compact_every=4
    )
    clock = [0.0]
    for op in ops:
        apply(world, op, clock)
    live = world.digest()
    assert replay_all(world) == live, "from-scratch replay of the journal"
    exported = io.StringIO()
    world.export_jsonl(exported)
    exported.seek(0)
    replayer = Replayer()
    for record in read_jsonl(exported):
        replayer.apply(record)
    assert replayer.model is not None and model_digest(replayer.model) == live, "JSON Lines"
    world.close()
    reopened = DurableWorld.open(data_dir, KNOWLEDGE, reorder_window=0.5)
    assert reopened.digest() == live, "snapshot + tail"
    assert reopened.model.world() == world.model.world()
    reopened.close()


def fill(data_dir: Path, n: int = 12, **options: Any) -> DurableWorld:
    world = DurableWorld.open(data_dir, KNOWLEDGE, **options)
    for i in range(n):
        world.ingest([{"time": 0.1 * i, "class": "Cup", "position": [1.0, 1.0 + 0.01 * i]}])
    return world


def test_a_damaged_record_is_cut_with_everything_after_it(tmp_path: Path) -> None:
    world = fill(tmp_path, snapshot_every=1000)
    world.close()
    with sqlite3.connect(tmp_path / DATABASE) as db:  # bit rot in record 8 (a batch)
        db.execute("UPDATE journal SET payload = replace(payload, '1.0', '9.0') WHERE seq = 8")
    reopened = DurableWorld.open(tmp_path, KNOWLEDGE)
    recovery = reopened.recovery
    assert recovery.cut is not None and "record 8" in recovery.cut and "checksum" in recovery.cut
    assert recovery.cut_records == 14 - 8 + 1  # 2 setup records + 12 batches, cut from 8
    expected = fill(tmp_path / "ref", n=8 - 3)  # records 3..7 are the first 5 batches
    assert reopened.digest() == expected.digest()
    assert reopened.journal.last_seq() == 7


def test_a_snapshot_of_other_code_is_rebuilt_from_the_journal(tmp_path: Path) -> None:
    world = fill(tmp_path, snapshot_every=5)
    digest = world.digest()
    world.close()
    with sqlite3.connect(tmp_path / DATABASE) as db:
        db.execute("UPDATE snapshots SET code = 'older-code'")
    reopened = DurableWorld.open(tmp_path, KNOWLEDGE)
    assert reopened.recovery.snapshot_seq is None
    assert (
        reopened.recovery.skipped_snapshots
        and "older-code" in reopened.recovery.skipped_snapshots[0]
    )
    assert reopened.digest() == digest


def test_an_unreadable_snapshot_state_is_rebuilt_not_misread(tmp_path: Path) -> None:
    world = fill(tmp_path, snapshot_every=5)
    digest = world.digest()
    snapshot = world.journal.snapshots()[0]
    world.journal.save_snapshot(
        Snapshot(snapshot.seq, snapshot.format, snapshot.code, snapshot.knowledge, b"garbage")
    )
    world.close()
    reopened = DurableWorld.open(tmp_path, KNOWLEDGE)
    assert reopened.recovery.skipped_snapshots
    assert reopened.digest() == digest


def test_compaction_archives_and_the_world_still_rebuilds(tmp_path: Path) -> None:
    world = fill(tmp_path, n=30, snapshot_every=10, compact_every=5)
    digest = world.digest()
    assert world.journal.archives(), "compaction wrote archives"
    assert world.journal.count() <= 15
    assert [r.seq for r in world.records()] == list(range(1, 33)), "nothing dropped"
    world.close()
    with sqlite3.connect(tmp_path / DATABASE) as db:
        db.execute("DELETE FROM snapshots")  # as if every snapshot were from older code
    reopened = DurableWorld.open(tmp_path, KNOWLEDGE)
    assert reopened.digest() == digest


def test_a_new_knowledge_file_on_restart_is_applied_as_a_journaled_change(tmp_path: Path) -> None:
    fill(tmp_path).close()
    other = edited(KNOWLEDGE, 3.0)
    reopened = DurableWorld.open(tmp_path, other)
    assert reopened.recovery.knowledge_changed
    assert reopened.model.knowledge.document == other.document
    assert replay_all(reopened) == reopened.digest()


def test_a_refused_batch_leaves_journal_and_world_unchanged(tmp_path: Path) -> None:
    world = fill(tmp_path, n=3)
    before, seq = world.digest(), world.journal.last_seq()
    with pytest.raises(DetectionError):
        world.ingest([{"time": 1.0, "class": "Nope", "position": [1.0, 1.0]}])
    assert (world.digest(), world.journal.last_seq()) == (before, seq)


def test_json_lines_torn_last_line_is_reported_and_cut(tmp_path: Path) -> None:
    world = fill(tmp_path / "data", n=4)
    path = tmp_path / "export.jsonl"
    with path.open("w") as handle:
        world.export_jsonl(handle)
    text = path.read_text()
    path.write_text(text[: len(text) - 25])  # power loss mid-line
    report = ReadReport()
    records = list(read_jsonl(path, report))
    assert [r.seq for r in records] == [1, 2, 3, 4, 5]
    assert report.problem is not None and f"{path}:6: torn last line" in report.problem
    lines = text.splitlines(keepends=True)
    lines[2] = lines[2].replace('"Cup"', '"Cap"')  # damaged, but whole
    path.write_text("".join(lines))
    report = ReadReport()
    assert [r.seq for r in read_jsonl(path, report)] == [1, 2]
    assert report.problem is not None and ":3: checksum mismatch" in report.problem
