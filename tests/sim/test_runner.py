"""The runner: scan grouping, world queries at truth times, timing and files."""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path

import pytest

from semwm.cli import main
from semwm.detection import Detection
from semwm.knowledge.loader import load_knowledge
from semwm.knowledge.model import Knowledge
from semwm.knowledge.shipped import shipped_knowledge_path
from semwm.sim.runner import run_scenario, scans, write_run
from semwm.sim.scenarios import make_scenario
from semwm.world_types import WorldObject, WorldState


class Oracle:
    """Reports the detections of the latest scan as the world (ids by order)."""

    def __init__(self, knowledge: Knowledge) -> None:
        self.latest: list[Detection] = []
        self.calls: list[list[Detection]] = []

    def ingest(self, detections: Sequence[Detection]) -> None:
        self.latest = list(detections)
        self.calls.append(self.latest)

    def world(self, time: float | None = None) -> WorldState:
        objects = tuple(
            WorldObject(
                i,
                d.cls,
                None,
                d.position,
                None,
                ((1.0, 0.0), (0.0, 1.0)),
                1.0,
                d.time,
                d.time,
                None,
            )
            for i, d in enumerate(self.latest)
        )
        return WorldState(time, objects)


def test_scans_group_by_time_and_source() -> None:
    dets = [
        Detection(time=0.0, cls="Robot", position=(0.0, 0.0), source="a"),
        Detection(time=0.0, cls="Robot", position=(1.0, 0.0), source="a"),
        Detection(time=0.0, cls="Robot", position=(2.0, 0.0), source="b"),
        Detection(time=0.1, cls="Robot", position=(0.0, 0.0), source="a"),
    ]
    assert [len(s) for s in scans(dets)] == [2, 1, 1]


def test_run_feeds_every_scan_before_its_truth_time_and_writes_the_files(tmp_path: Path) -> None:
    scenario = make_scenario("grid", 1, n_objects=4, duration=1.0)
    knowledge = load_knowledge(shipped_knowledge_path(scenario.knowledge_file))
    models: list[Oracle] = []

    def factory(k: Knowledge) -> Oracle:
        models.append(Oracle(k))
        return models[-1]

    result = run_scenario(scenario, knowledge, progress=False, world_model_factory=factory)
    assert sum(len(c) for c in models[0].calls) == len(scenario.detections) == 44
    assert len(result.worlds) == len(scenario.truth) == 11
    # every grid object is detected in every frame: the oracle world is the truth plus noise
    assert result.metrics.missed_objects.total == 0 and result.metrics.false_objects.total == 0
    assert result.metrics.gospa.localisation == pytest.approx(result.metrics.gospa.total)
    assert 0.0 < result.metrics.gospa.total < 4 * 0.2
    assert result.metrics.time_per_detection["mean_s"] > 0.0
    out = write_run(result, tmp_path / "run")
    names = {p.name for p in out.iterdir()}
    assert names == {"detections.jsonl", "truth.jsonl", "world.jsonl", "metrics.json", "plot.png"}
    world_lines = (out / "world.jsonl").read_text().splitlines()
    assert len(world_lines) == 11
    assert json.loads(world_lines[0])["objects"][0]["class"] == "Thing"
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["seed"] == 1 and metrics["n_detections"] == 44
    assert set(metrics["gospa"]) == {"c", "p", "alpha", "total", "localisation", "missed", "false"}


def test_semwm_simulate_end_to_end(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "sim1"
    status = main(
        ["simulate", "sim1", "--seed", "2", "--duration", "4", "--out", str(out), "--no-progress"]
    )
    assert status == 0
    printed = capsys.readouterr().out
    assert "GOSPA" in printed and "ID switches" in printed and "time per detection" in printed
    assert json.loads((out / "metrics.json").read_text())["seed"] == 2
