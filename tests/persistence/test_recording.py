"""MCAP recordings and the replay/record/journal commands."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from fastapi.testclient import TestClient

from api.app import create_app
from api.settings import Settings
from semwm.cli import main
from semwm.knowledge.shipped import shipped_knowledge_path
from semwm.persistence.mcap_io import TOPICS, read_recording, recording_summary
from semwm.persistence.records import ReadReport

SIM1 = shipped_knowledge_path("sim1.yaml")


@pytest.fixture(scope="module")
def recording(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """``semwm record sim1 --out DIR`` (its world.jsonl in DIR, beside it here)."""
    path = tmp_path_factory.mktemp("rec") / "sim1.mcap"
    assert main(["record", "sim1", str(path), "--out", str(path.parent), "--no-progress"]) == 0
    return path


def test_record_writes_only_the_mcap_file_by_default(tmp_path: Path) -> None:
    path = tmp_path / "sim1.mcap"
    assert main(["record", "sim1", str(path), "--no-progress"]) == 0
    assert [p.name for p in tmp_path.iterdir()] == ["sim1.mcap"]
    assert recording_summary(path) == TOPICS


def test_record_then_replay_gives_the_same_world_jsonl(recording: Path, tmp_path: Path) -> None:
    assert main(["replay", str(recording), "--out", str(tmp_path / "rep"), "--no-progress"]) == 0
    recorded = (recording.parent / "world.jsonl").read_text()
    assert recorded and recorded == (tmp_path / "rep" / "world.jsonl").read_text()
    assert recording_summary(recording) == TOPICS  # channels and schemas, by the mcap reader
    from mcap.reader import make_reader

    with recording.open("rb") as handle:
        reader = make_reader(handle)
        schemas = {s.name: json.loads(s.data) for s in reader.get_summary().schemas.values()}
        worlds = [json.loads(m.data) for _, _, m in reader.iter_messages(topics=["/semwm/world"])]
    assert schemas["foxglove.SceneUpdate"]["properties"]["entities"]
    assert worlds == [json.loads(line) for line in recorded.splitlines()]
    metrics = json.loads((tmp_path / "rep" / "metrics.json").read_text())
    assert metrics["n_detections"] > 0 and metrics["refused_batches"] == 0


def test_a_recording_cut_short_replays_up_to_its_last_whole_message(
    recording: Path, tmp_path: Path
) -> None:
    data = recording.read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: len(data) // 2])
    assert main(["replay", str(cut), "--out", str(tmp_path / "rep"), "--no-progress"]) == 0
    metrics = json.loads((tmp_path / "rep" / "metrics.json").read_text())
    assert metrics["tail_problem"] and "ends early" in metrics["tail_problem"]
    assert metrics["batches"] > 0


def test_a_recording_cut_anywhere_reads_up_to_its_last_whole_message(
    recording: Path, tmp_path: Path
) -> None:
    """Power loss can cut the file at any byte: reading stops with a report, never raises."""
    data = recording.read_bytes()
    whole = len(list(read_recording(recording)))
    cut = tmp_path / "cut.mcap"
    for end in range(0, len(data), max(len(data) // 200, 1)):
        cut.write_bytes(data[:end])
        report = ReadReport()
        read = list(read_recording(cut, report))
        assert len(read) <= whole
        assert report.problem is not None, end


def test_serve_records_and_journals_what_it_acknowledges(tmp_path: Path) -> None:
    recording, data_dir = tmp_path / "serve.mcap", tmp_path / "data"
    settings = Settings(
        knowledge=SIM1, port=0, data_dir=data_dir, record=recording, allowed_hosts=("testserver",)
    )
    with TestClient(create_app(settings)) as client:
        for i in range(10):
            body = {"detections": [{"time": 0.1 * i, "class": "Cup", "position": [1.0, 1.0]}]}
            assert client.post("/detections", json=body).status_code == 200
        assert client.post("/reset").status_code == 200
        body = {"time": 5.0, "class": "CokeCan", "position": [2.0, 1.0]}
        assert client.post("/detections", json=body).status_code == 200
        assert client.post("/detections", json={"time": 5.0, "class": "X"}).status_code == 422
        state = client.get("/persistence").json()
    assert state["journal"]["last_seq"] == 2 + 10 + 1 + 1
    assert main(["replay", str(recording), "--out", str(tmp_path / "a"), "--no-progress"]) == 0
    assert main(["replay", str(data_dir), "--out", str(tmp_path / "b"), "--no-progress"]) == 0
    for out in ("a", "b"):
        metrics = json.loads((tmp_path / out / "metrics.json").read_text())
        assert (metrics["digest"], metrics["batches"], metrics["resets"]) == (
            state["digest"],
            11,
            1,
        )
    export = tmp_path / "journal.jsonl"
    assert main(["journal", "export", str(data_dir), str(export)]) == 0
    assert main(["replay", str(export), "--out", str(tmp_path / "c"), "--no-progress"]) == 0
    metrics = json.loads((tmp_path / "c" / "metrics.json").read_text())
    assert metrics["digest"] == state["digest"]


def test_replay_into_other_knowledge_counts_refused_batches(
    recording: Path, tmp_path: Path
) -> None:
    other = shipped_knowledge_path("sim2.yaml")  # has none of sim1's classes
    out = tmp_path / "rep"
    args = ["replay", str(recording), "--knowledge", str(other), "--out", str(out), "--no-progress"]
    assert main(args) == 0
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["batches"] == 0 and metrics["refused_batches"] > 0
    assert metrics["skipped_knowledge_changes"] == 1


def test_replay_of_a_missing_source_is_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["replay", str(tmp_path / "nope.mcap"), "--no-progress"]) == 2
    assert "nope.mcap" in capsys.readouterr().err
