"""Metrics against hand-computed values."""

from __future__ import annotations

import math

import pytest

from semwm.sim.metrics import (
    Point,
    compute_metrics,
    count_id_switches,
    gospa_frame,
    unobserved_floor,
)


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


def test_unobserved_floor_counts_objects_until_a_report_comes_near() -> None:
    """An object is missed (c/2) in every frame before the first report within c/2 of
    it; one never reported is missed in every frame; reports compare with the truth
    frame nearest in time."""
    a = Point("a", "Cup", (0.0, 0.0))
    b = Point("b", "Cup", (5.0, 0.0))
    frames = [(0.0, [a, b]), (1.0, [a, b]), (2.0, [a, b]), (3.0, [a, b])]
    reports = [
        (1.1, (0.4, 0.3)),  # 0.5 m from a (c/2 = 0.5): a is observed from frame 2 on
        (0.0, (5.0, 0.9)),  # 0.9 m from b: too far, b is never observed
    ]
    # a missed in frames 0 and 1, b in all four: (2 + 4) / 4 frames x c/2
    assert unobserved_floor(frames, reports, c=1.0) == pytest.approx(0.5 * 6 / 4)
    assert unobserved_floor(frames, [(0.0, (0.0, 0.0)), (0.0, (5.0, 0.0))], c=1.0) == 0.0
    assert unobserved_floor(frames, [], c=2.0, p=2.0) == pytest.approx(2.0 * 2)
    with pytest.raises(ValueError, match="c > 0"):
        unobserved_floor(frames, reports, c=0.0)


def test_unobserved_floor_is_a_floor_of_a_trackers_gospa_on_a_scenario() -> None:
    """On generated RoboCup data (seeds 0-3, 1 s) semwm's missed part of GOSPA is never
    below the floor, and the floor is a real share of it (robots nobody has seen)."""
    from semwm.knowledge.loader import load_knowledge
    from semwm.knowledge.shipped import shipped_knowledge_path
    from semwm.sim.runner import run_scenario, truth_points
    from semwm.sim.scenarios import make_scenario

    knowledge = load_knowledge(shipped_knowledge_path("robocup.yaml"))
    floors = []
    for seed in range(4):
        scenario = make_scenario("robocup", seed, duration=1.0)
        floor = unobserved_floor(
            [(f.time, truth_points(f)) for f in scenario.truth],
            [(d.time, d.position) for d in scenario.detections],
            c=float(scenario.metadata["gospa_c"]),
        )
        result = run_scenario(scenario, knowledge, progress=False)
        assert floor <= result.metrics.gospa.missed <= result.metrics.gospa.total
        floors.append(floor)
    assert sum(floors) > 0.0
