"""Sensor views (empty scans) and actions (kicks) are changes like batches: journaled
with ``--data-dir``, recorded to MCAP, and replayed to the same world (paper 004)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from semwm import WorldModel
from semwm.knowledge.loader import knowledge_from_text
from semwm.persistence import DurableWorld, Replayer, model_digest
from semwm.persistence.mcap_io import McapRecorder, read_recording
from semwm.persistence.records import Record, action_record, batch_record

KNOWLEDGE = knowledge_from_text(
    """
world: {dimension: 2, region: [[-10, 10], [-10, 10]]}
classes:
- name: Ball
  category: passive
  detection_frequency: 10
  filter: {type: kalman, model: {motion_model: first_order, system_noise: [[0.05, 0], [0, 0.05]]}}
  measurement_noise: [[0.0025, 0], [0, 0.0025]]
  initial_velocity_covariance: [[0.01, 0], [0, 0.01]]
- name: Box
  detection_frequency: 5
  filter: {type: kalman, model: {motion_model: zeroth_order, system_noise: [[0.001, 0], [0, 0.001]]}}
  measurement_noise: [[0.01, 0], [0, 0.01]]
detectors:
- {name: camera, clutter_frequency: 0.1, range: 5.0, field_of_view: 60}
""",
    "yaml",
)
SENSOR = {"pose": [0.0, 0.0, 0.0], "time": 1.2, "source": "me", "detector": "camera"}
KICK = {
    "time": 1.2,
    "type": "kick",
    "source": "me",
    "near": [0.0, 0.0],
    "direction": [0, 1],
    "speed": 2.0,
}


def play(world: DurableWorld | WorldModel) -> None:
    for t in np.arange(0.0, 1.0 + 1e-9, 0.1):
        batch = [
            {"time": float(t), "class": "Ball", "position": [0.0, 0.0], "source": "me"},
            {"time": float(t), "class": "Box", "position": [2.0, 0.5], "source": "me"},
        ]
        world.ingest(batch)
    world.ingest([], sensor=SENSOR)  # looked at the box, saw nothing
    world.act(KICK)
    world.ingest([{"time": 1.5, "class": "Ball", "position": [0.0, 0.3], "source": "me"}])


def test_views_and_actions_are_journaled_and_a_restart_publishes_the_same_world(
    tmp_path: Path,
) -> None:
    durable = DurableWorld.open(tmp_path, KNOWLEDGE, snapshot_every=10_000)
    play(durable)
    plain = WorldModel(KNOWLEDGE)
    play(plain)
    live = durable.digest()
    assert live == model_digest(plain)  # journaling changes nothing
    kinds = [r.kind for r in durable.records()]
    assert "action" in kinds
    assert any(r.kind == "batch" and isinstance(r.payload, dict) for r in durable.records())
    durable.close()

    reopened = DurableWorld.open(tmp_path, KNOWLEDGE)  # no snapshot: the journal replays
    assert reopened.digest() == live
    assert reopened.model.world() == plain.world()
    reopened.close()


class Changes:
    """Records the changes :func:`play` makes, as the service's hooks see them."""

    def __init__(self) -> None:
        self.records: list[Record] = []

    def ingest(self, batch: list[dict[str, Any]], sensor: dict[str, Any] | None = None) -> None:
        self.records.append(batch_record(batch, sensor))

    def act(self, action: dict[str, Any]) -> None:
        self.records.append(action_record(action))


def test_a_view_and_an_action_survive_an_mcap_recording(tmp_path: Path) -> None:
    changes = Changes()
    play(changes)  # type: ignore[arg-type]
    model = WorldModel(KNOWLEDGE)
    play(model)
    path = tmp_path / "run.mcap"
    recorder = McapRecorder.create(path, lambda: model)
    recorder.start(KNOWLEDGE, 0.0)
    for record in changes.records:
        recorder.write_change(record)
    recorder.close()
    read = [r for r in read_recording(path) if r.kind in ("batch", "action")]
    assert [(r.kind, r.payload) for r in read] == [(r.kind, r.payload) for r in changes.records]
    replayer = Replayer()
    for record in read_recording(path):
        replayer.apply(record)
    assert replayer.counts.actions == 1 and replayer.counts.refused_actions == 0
    assert replayer.model is not None and model_digest(replayer.model) == model_digest(model)
