"""Metrics against hand-computed values."""

from __future__ import annotations

import math

import pytest

from semwm.sim.metrics import Point, compute_metrics, count_id_switches, gospa_frame


def pt(id_: str, x: float, y: float, cls: str = "Cup") -> Point:
    return Point(id_, cls, (x, y))


def test_gospa_one_pair_within_cutoff_is_the_distance() -> None:
    frame = gospa_frame([pt("a", 0, 0)], [pt("1", 0.3, 0.4)], c=2.0, p=1.0)
    assert frame.total == pytest.approx(0.5)
    assert frame.localisation == pytest.approx(0.5)
    assert (frame.missed, frame.false) == (0.0, 0.0)
    assert frame.assignment == ((0, 0),)


def test_gospa_missed_object_costs_half_c_to_the_p() -> None:
    frame = gospa_frame([pt("a", 0, 0)], [], c=2.0, p=1.0)
    assert frame.total == pytest.approx(1.0)
    assert frame.missed == pytest.approx(1.0) and frame.n_missed == 1
    frame = gospa_frame([], [pt("1", 0, 0)], c=3.0, p=2.0)
    # (c^p / 2)^(1/p) = sqrt(4.5)
    assert frame.total == pytest.approx(math.sqrt(4.5))
    assert frame.false == pytest.approx(4.5) and frame.n_false == 1


def test_gospa_pair_beyond_cutoff_is_one_missed_and_one_false() -> None:
    frame = gospa_frame([pt("a", 0, 0)], [pt("1", 5, 0)], c=2.0, p=2.0)
    assert frame.assignment == ()
    assert frame.total == pytest.approx(math.sqrt(2.0 + 2.0))
    assert (frame.n_missed, frame.n_false) == (1, 1)


def test_gospa_picks_the_optimal_assignment_p2() -> None:
    truth = [pt("a", 0, 0), pt("b", 1, 0)]
    est = [pt("1", 1.1, 0), pt("2", 0.2, 0), pt("3", 10, 10)]
    frame = gospa_frame(truth, est, c=1.0, p=2.0)
    assert sorted(frame.assignment) == [(0, 1), (1, 0)]
    assert frame.localisation == pytest.approx(0.04 + 0.01)
    assert frame.total == pytest.approx(math.sqrt(0.05 + 0.5))


def test_gospa_empty_frames_are_zero() -> None:
    assert gospa_frame([], [], c=1.0).total == 0.0


def test_id_switches_on_a_crafted_sequence() -> None:
    frames = [
        {"a": 1, "b": 2},
        {"a": 1, "b": 2},
        {"a": 2, "b": 1},  # swap: two switches
        {"b": 1},  # a unassigned (occluded)
        {"a": 2, "b": 1},  # a back on its last estimate: no switch
        {"a": 7, "b": 1},  # a re-created under a new id: one switch
    ]
    assert count_id_switches(frames) == 3


def test_compute_metrics_averages_and_counts() -> None:
    truth = [[pt("a", 0, 0, "CokeCan")], [pt("a", 0, 0, "CokeCan")], [pt("a", 0, 0, "CokeCan")]]
    est = [
        [pt("1", 0.5, 0, "CokeCan")],
        [pt("1", 0.5, 0, "Can"), pt("2", 5, 5, "Cup")],
        [pt("3", 0, 0.5, "Cup")],
    ]
    taxonomy = {("CokeCan", "Can"), ("Can", "CokeCan")}

    def compatible(a: str, b: str) -> bool:
        return a == b or (a, b) in taxonomy

    m = compute_metrics(truth, est, c=2.0, p=1.0, compatible=compatible)
    # frame 1: 0.5; frame 2: 0.5 + 1 false; frame 3: 0.5
    assert m.gospa.total == pytest.approx((0.5 + 1.5 + 0.5) / 3)
    assert m.gospa.localisation == pytest.approx(0.5)
    assert m.gospa.false == pytest.approx(1 / 3)
    assert m.gospa.missed == 0.0
    assert m.false_objects.total == 1 and m.false_objects.mean == pytest.approx(1 / 3)
    assert m.missed_objects.total == 0
    assert m.id_switches == 1
    assert m.class_accuracy.n_assigned == 3
    assert m.class_accuracy.exact == pytest.approx(1 / 3)
    assert m.class_accuracy.compatible == pytest.approx(2 / 3)


def test_compute_metrics_rejects_unpaired_frames() -> None:
    with pytest.raises(ValueError, match="one estimate frame per truth frame"):
        compute_metrics([[]], [], c=1.0)
