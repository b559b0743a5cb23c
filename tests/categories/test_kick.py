"""Paper 004 IV-B: a kick spawns kicked / not-kicked hypotheses that later detections
resolve."""

from __future__ import annotations

import numpy as np
import pytest

from semwm import WorldModel
from semwm.detection import DetectionError, OutOfOrderError
from semwm.knowledge.loader import knowledge_from_text

KNOWLEDGE = """
world: {dimension: 2, region: [[-10, 10], [-10, 10]]}
classes:
- name: Ball
  category: passive
  detection_frequency: 10
  filter: {type: kalman, model: {motion_model: first_order, system_noise: [[0.05, 0], [0, 0.05]]}}
  measurement_noise: [[0.0025, 0], [0, 0.0025]]
  initial_velocity_covariance: [[0.01, 0], [0, 0.01]]
  velocity_decay: 0.3
- name: Post
  category: static
  detection_frequency: 10
  filter: {type: kalman, model: {motion_model: zeroth_order, system_noise: [[0.001, 0], [0, 0.001]]}}
  measurement_noise: [[0.0025, 0], [0, 0.0025]]
detectors: [{name: camera, clutter_frequency: 0.5}]
"""
ALPHA = 0.3


def resting_ball() -> WorldModel:
    wm = WorldModel(knowledge_from_text(KNOWLEDGE, "yaml"))
    for t in np.arange(0.0, 1.0 + 1e-9, 0.1):
        wm.ingest(
            [
                {"time": float(t), "class": "Ball", "position": [0.0, 0.0]},
                {"time": float(t), "class": "Post", "position": [3.0, 0.0]},
            ]
        )
    return wm


def balls(wm: WorldModel, time: float | None = None) -> list[object]:
    return list(wm.world(time, cls="Ball").objects)


KICK = {"time": 1.0, "type": "kick", "source": "me", "near": [0.1, 0.0], "direction": [0, 3]}


def test_a_kick_followed_by_the_ball_along_its_direction_keeps_one_moving_ball() -> None:
    wm = resting_ball()
    (ball,) = balls(wm)
    assert wm.act({**KICK, "speed": 2.0}) == [ball.id]
    assert len(wm.hypotheses(10)) == 2  # kicked (0.8) and not kicked (0.2)
    (predicted,) = balls(wm, 1.5)  # the kicked branch is the more likely: it rolls
    assert predicted.id == ball.id
    assert predicted.position[1] == pytest.approx(2.0 * 0.5 - ALPHA * 0.25 / 2, abs=1e-6)
    for t in np.arange(1.1, 2.0 + 1e-9, 0.1):
        tau = float(t) - 1.0
        wm.ingest(
            {"time": float(t), "class": "Ball", "position": [0.0, 2 * tau - ALPHA * tau**2 / 2]}
        )
    (moving,) = balls(wm)
    assert moving.id == ball.id
    assert moving.velocity == pytest.approx([0.0, 2.0 - ALPHA * 1.0], abs=0.15)
    assert moving.position == pytest.approx([0.0, 2.0 - ALPHA / 2], abs=0.05)
    assert len(wm.hypotheses(10)) == 1  # the not-kicked branch is gone


def test_a_kick_followed_by_the_ball_staying_keeps_it_still() -> None:
    wm = resting_ball()
    (ball,) = balls(wm)
    wm.act({**KICK, "object": ball.id, "near": None, "speed": 2.0})
    for t in np.arange(1.1, 2.0 + 1e-9, 0.1):
        wm.ingest({"time": float(t), "class": "Ball", "position": [0.0, 0.0]})
    (still,) = balls(wm)
    assert still.id == ball.id
    assert still.velocity is not None and np.linalg.norm(still.velocity) < 0.05
    assert still.position == pytest.approx([0.0, 0.0], abs=0.02)
    assert len(balls(wm, 2.0)) == 1


def test_a_kick_needs_a_passive_object_and_a_current_time() -> None:
    wm = resting_ball()
    post = next(o for o in wm.world().objects if o.cls == "Post")
    with pytest.raises(DetectionError, match="not a passive object"):
        wm.act({**KICK, "object": post.id, "near": None, "speed": 1.0})
    with pytest.raises(DetectionError, match="no passive object within"):
        wm.act({**KICK, "near": [5.0, 5.0], "speed": 1.0})
    with pytest.raises(DetectionError, match="direction"):
        wm.act({**KICK, "direction": [0.0, 0.0], "speed": 1.0})
    with pytest.raises(OutOfOrderError):
        wm.act({**KICK, "time": 0.5, "speed": 1.0})
