"""Paper 004: confidence with per-class thresholds, and negative information (a scan
that looked and did not see)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from semwm import WorldModel
from semwm.detection import DetectionError
from semwm.knowledge.loader import knowledge_from_text
from semwm.mhf.existence import missed

# The queries run to 3 s after the last detection: with the rate the 10 Hz scans are
# observed at (semwm.mhf.rates) the Box's existence would fall below
# removal_existence by then; this file tests confidence, at the classes' rates.
KNOWLEDGE = """
world: {dimension: 2, region: [[-10, 10], [-10, 10]], observed_detection_rates: false}
classes:
- name: Box
  detection_frequency: 5
  leave_frequency: 0.05
  filter: {type: kalman, model: {motion_model: zeroth_order, system_noise: [[0.001, 0], [0, 0.001]]}}
  measurement_noise: [[0.01, 0], [0, 0.01]]
  confidence_decay: 0.5
  looking_decay: 3.0
  suspicious_confidence: 0.6
  invalid_confidence: 0.3
- name: Crate
  is_a: [Box]
  suspicious_confidence: 0.9
  invalid_confidence: 0.8
- name: Post
  category: static
  detection_frequency: 5
  filter: {type: kalman, model: {motion_model: zeroth_order, system_noise: [[0.001, 0], [0, 0.001]]}}
  measurement_noise: [[0.01, 0], [0, 0.01]]
detectors:
- {name: camera, clutter_frequency: 0.1, range: 5.0, field_of_view: 60}
- {name: teammate, clutter_frequency: 0.1, confidence: 0.55}
"""


def seen(objects: dict[str, tuple[str, tuple[float, float]]], until: float = 1.0) -> WorldModel:
    wm = WorldModel(knowledge_from_text(KNOWLEDGE, "yaml"))
    for t in np.arange(0.0, until + 1e-9, 0.1):
        wm.ingest(
            [
                {"time": float(t), "class": cls, "position": list(xy), "source": "me"}
                for cls, xy in objects.values()
            ]
        )
    return wm


def by_class(wm: WorldModel, time: float) -> dict[str, object]:
    return {o.cls: o for o in wm.world(time, min_existence=1e-6).objects}


def test_confidence_decays_through_the_three_states_with_the_class_thresholds() -> None:
    wm = seen({"a": ("Box", (1.0, 1.0)), "b": ("Crate", (-3.0, 3.0))})
    states: dict[str, list[str]] = {"Box": [], "Crate": []}
    for dt in (0.0, 0.3, 0.5, 1.0, 1.5, 2.0, 3.0):
        for cls, obj in by_class(wm, 1.0 + dt).items():
            assert obj.confidence is not None
            assert obj.confidence.value == pytest.approx(math.exp(-0.5 * dt))
            states[cls].append(obj.confidence.state)
    # Box: c < 0.6 after 1.02 s, < 0.3 after 2.41 s; Crate: < 0.9 after 0.21 s, < 0.8 after 0.45 s
    assert states["Box"] == ["valid"] * 4 + ["suspicious"] * 2 + ["invalid"]
    assert (
        states["Crate"]
        == ["valid", "suspicious", "invalid", "invalid", "invalid"] + ["invalid"] * 2
    )
    valid = wm.world(1.5, confidence="valid", min_existence=1e-6).objects
    assert [o.cls for o in valid] == ["Box"]
    both = wm.world(2.5, confidence=["suspicious", "invalid"], min_existence=1e-6).objects
    assert sorted(o.cls for o in both) == ["Box", "Crate"]
    with pytest.raises(ValueError, match="confidence state"):
        wm.world(confidence="dubious")


def test_a_detection_sets_the_confidence_of_its_detector() -> None:
    wm = seen({"a": ("Box", (1.0, 1.0))})
    wm.ingest({"time": 1.1, "class": "Box", "position": [1.0, 1.0], "detector": "teammate"})
    (obj,) = wm.world(1.1).objects
    assert obj.confidence is not None and obj.confidence.value == pytest.approx(0.55)
    assert obj.confidence.state == "suspicious"


SENSOR = {"pose": [0.0, 0.0, 0.0], "time": 1.5, "source": "me", "detector": "camera"}


def test_an_empty_scan_lowers_existence_inside_its_view_and_leaves_the_rest() -> None:
    objects = {"in": ("Box", (2.0, 0.5)), "out": ("Crate", (-2.0, 0.0))}
    looked, control = seen(objects), seen(objects)
    looked.ingest([], sensor=SENSOR)
    after, before = by_class(looked, 1.5), by_class(control, 1.5)
    assert after["Crate"].existence == pytest.approx(before["Crate"].existence, abs=1e-12)
    r = before["Box"].existence
    expected, _ = missed(np.array([r]), np.array([0.9]))
    assert after["Box"].existence == pytest.approx(float(expected[0]), rel=1e-6)
    assert after["Box"].existence < r - 0.01
    # confidence: faster decay (looking_decay) inside the view, the usual one outside
    assert after["Box"].confidence.value == pytest.approx(math.exp(-3.0 * 0.5))
    assert after["Crate"].confidence.value == pytest.approx(math.exp(-0.5 * 0.5))
    assert before["Box"].confidence.value == pytest.approx(math.exp(-0.5 * 0.5))


def test_repeated_empty_looks_remove_an_object_that_is_not_there() -> None:
    wm = seen({"in": ("Box", (2.0, 0.5))})
    for k in range(1, 8):
        wm.ingest([], sensor={**SENSOR, "time": 1.0 + 0.2 * k})
    assert wm.world(2.4).objects == ()


def test_looking_at_counts_an_object_outside_the_computed_view() -> None:
    objects = {"out": ("Box", (-2.0, 0.0))}
    flagged, control = seen(objects), seen(objects)
    (obj,) = flagged.world().objects
    flagged.ingest([], sensor={**SENSOR, "looking_at": [obj.id]})
    assert by_class(flagged, 1.5)["Box"].existence < by_class(control, 1.5)["Box"].existence
    with pytest.raises(DetectionError, match="no object with id 999"):
        flagged.ingest([], sensor={**SENSOR, "time": 1.6, "looking_at": [999]})


def test_a_scan_that_reports_an_object_in_view_does_not_count_against_it() -> None:
    objects = {"in": ("Box", (2.0, 0.5))}
    wm, control = seen(objects), seen(objects)
    det = {"time": 1.1, "class": "Box", "position": [2.0, 0.5], "source": "me"}
    wm.ingest([det], sensor={**SENSOR, "time": 1.1})
    control.ingest([det])
    assert by_class(wm, 1.1)["Box"].existence == pytest.approx(
        by_class(control, 1.1)["Box"].existence, abs=1e-12
    )


def test_an_empty_scan_needs_its_time_and_a_well_formed_pose() -> None:
    wm = seen({"in": ("Box", (2.0, 0.5))})
    with pytest.raises(DetectionError, match="time"):
        wm.ingest([], sensor={"pose": [0.0, 0.0, 0.0]})
    with pytest.raises(DetectionError, match="pose"):
        wm.ingest([], sensor={"pose": [0.0, 0.0], "time": 1.2})


def test_static_confidence_decays_with_the_observer_motion_not_time() -> None:
    wm = seen({"p": ("Post", (3.0, 3.0))})
    wm.ingest([], sensor={**SENSOR, "pose": [0.0, 0.0, math.pi], "time": 1.2})
    assert by_class(wm, 2.0)["Post"].confidence.value == pytest.approx(1.0)
    wm.ingest([], sensor={**SENSOR, "pose": [2.0, 0.0, math.pi], "time": 1.4})
    assert by_class(wm, 1.4)["Post"].confidence.value == pytest.approx(math.exp(-0.1 * 2.0))


def test_each_sources_looks_count_whoever_scans_at_the_same_time() -> None:
    wm = seen({"in": ("Box", (2.0, 0.5))})
    away = {**SENSOR, "pose": [0.0, 0.0, math.pi]}
    facing = {**SENSOR, "source": "other"}
    for t in (1.2, 1.4):
        wm.ingest([], sensor={**away, "time": t})  # "me" first, looking away
        wm.ingest([], sensor={**facing, "time": t})
    value = by_class(wm, 1.4)["Box"].confidence.value
    # base decay over 0.4 s; "other" looked for 0.2 s (its first scan has no interval)
    assert value == pytest.approx(math.exp(-0.5 * 0.4) * math.exp(-(3.0 - 0.5) * 0.2))
