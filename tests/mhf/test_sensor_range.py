"""Paper 000 C2 (a detector's range) with noisy positions: an object at the edge of
view is neither lost nor pulled towards the sensor (issue 9, RoboCup misses)."""

from __future__ import annotations

import numpy as np

from semwm import WorldModel
from semwm.detection import Detection
from semwm.knowledge.loader import load_knowledge
from semwm.knowledge.shipped import shipped_knowledge_path
from semwm.validation import out_of_range

ROBOCUP = load_knowledge(shipped_knowledge_path("robocup.yaml"))
R = np.diag([0.09, 0.09])  # omnivision, sigma 0.3 m


def seen_at(x: float, t: float = 0.0) -> Detection:
    return Detection(
        time=t,
        cls="Robot",
        position=(x, 0.0),
        source="peer1",
        detector="omnivision",
        sensor_position=(0.0, 0.0),
    )


def test_the_range_bounds_the_object_and_the_noise_of_its_report_is_allowed_for() -> None:
    # range 5 m; the gate (0.9999, one-dimensional: 3.89 sigma) adds 1.17 m for R
    assert not out_of_range(seen_at(5.2), ROBOCUP, R)
    assert not out_of_range(seen_at(6.1), ROBOCUP, R)
    assert out_of_range(seen_at(6.3), ROBOCUP, R)
    # without the detection's noise the cut stays at the range itself
    assert out_of_range(seen_at(5.2), ROBOCUP)
    assert not out_of_range(seen_at(4.9), ROBOCUP)


def test_an_object_at_the_edge_of_view_is_not_pulled_towards_the_sensor() -> None:
    # A robot stands 4.9 m from a peer that reports it at 30 Hz with 0.3 m noise.
    # About 37% of its reports land beyond 5 m; dropping them (the cut at the range
    # itself) biased the estimate 0.18 m towards the sensor (the truncated normal's
    # mean) in every RoboCup run, and lost robots that cross the edge.
    rng = np.random.default_rng(3)
    wm = WorldModel(ROBOCUP, reorder_window=0.0)
    for k in range(90):
        x = 4.9 + rng.normal(0.0, 0.3)
        y = rng.normal(0.0, 0.3)
        wm.ingest([seen_at(x, k / 30).model_copy(update={"position": (x, y)})])
    robots = wm.world().objects
    assert len(robots) == 1
    assert abs(robots[0].position[0] - 4.9) < 0.1, robots[0].position
