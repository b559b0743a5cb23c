"""A synced source's sensor view (paper 004) is placed on the service clock like its
detections (paper 003): the same stamp, the same placed time."""

from __future__ import annotations

from api.service import WorldService
from semwm import WorldModel
from semwm.clock import Exchange
from semwm.knowledge.loader import knowledge_from_text

KNOWLEDGE = """
world: {dimension: 2, region: [[-10, 10], [-10, 10]]}
classes:
- name: Box
  detection_frequency: 5
  filter: {type: kalman, model: {motion_model: zeroth_order, system_noise: [[0.001, 0], [0, 0.001]]}}
  measurement_noise: [[0.01, 0], [0, 0.01]]
detectors:
- {name: camera, clutter_frequency: 0.1, range: 5.0, field_of_view: 60}
"""
OFFSET = 100.0  # the robot's clock is 100 s behind the service's


def test_a_synced_sources_sensor_time_is_placed_with_its_detections() -> None:
    service = WorldService(WorldModel(knowledge_from_text(KNOWLEDGE, "yaml")), clock=lambda: 106.0)
    t1 = 5.0
    service.sources.sync("me", Exchange(t1, t1 + OFFSET + 0.01, t1 + OFFSET + 0.011, t1 + 0.021))
    box = {"class": "Box", "position": [2.0, 0.5], "source": "me"}
    sensor = {"pose": [0.0, 0.0, 0.0], "source": "me", "detector": "camera"}
    seen = service.ingest([{**box, "time": 5.5}], batch=True, sensor={**sensor, "time": 5.5})
    assert seen.value.time is not None and abs(seen.value.time - 105.5) < 1e-9
    before = service.model.world(min_existence=1e-9).objects[0].existence
    empty = service.ingest([], batch=True, sensor={**sensor, "time": 5.7})
    assert empty.value.time is not None and abs(empty.value.time - 105.7) < 1e-9
    assert service.model.world(min_existence=1e-9).objects[0].existence < before
