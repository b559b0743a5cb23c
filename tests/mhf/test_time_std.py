"""A detection's time uncertainty widens its noise along the object's motion:
R' = R + time_std^2 v v^T (semwm.mhf.association)."""

from __future__ import annotations

import pytest

from semwm import WorldModel
from semwm.detection import DetectionError
from semwm.knowledge.loader import knowledge_from_text

KNOWLEDGE = """
world: {dimension: 2, region: [[-50, 50], [-50, 50]]}
classes:
- name: Car
  detection_frequency: 10
  new_frequency: 0.01
  filter: {type: kalman, model: {motion_model: first_order, system_noise: [[0.01, 0], [0, 0.01]]}}
  measurement_noise: [[0.0025, 0], [0, 0.0025]]
  initial_velocity_covariance: [[100, 0], [0, 100]]
detectors:
- {name: camera, clutter_frequency: 0.1}
"""


def objects_after_a_late_stamp(time_std: float | None) -> int:
    """A car driving at 10 m/s along x, seen at 10 Hz; the last detection's stamp is
    40 ms early (its position is 0.4 m ahead of where the stamp says). Returns the
    object versions stored after it: 1 if it updated the car, 2 if it started another."""
    wm = WorldModel(knowledge_from_text(KNOWLEDGE, "yaml"))
    for k in range(30):
        wm.ingest([{"time": k / 10, "class": "Car", "position": [k * 1.0, 0.0], "source": "a"}])
    last = {"time": 3.0, "class": "Car", "position": [30.4, 0.0], "source": "a"}
    if time_std is not None:
        last["time_std"] = time_std
    wm.ingest([last])
    return wm.track_count


def test_an_uncertain_stamp_of_a_moving_object_still_updates_it() -> None:
    assert objects_after_a_late_stamp(None) == 2  # 0.4 m off at 5 cm noise: a new object
    assert objects_after_a_late_stamp(0.05) == 1  # 10 m/s x 50 ms covers it
    assert objects_after_a_late_stamp(0.0) == 2


def test_time_std_must_be_a_small_non_negative_number() -> None:
    wm = WorldModel(knowledge_from_text(KNOWLEDGE, "yaml"))
    for bad in (-0.1, 1e6, float("nan")):
        with pytest.raises(DetectionError, match="time_std"):
            wm.ingest([{"time": 0.0, "class": "Car", "position": [0, 0], "time_std": bad}])
    assert wm.object_count == 0
