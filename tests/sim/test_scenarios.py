"""Scenario generators: deterministic per seed, right sizes, occlusions and labels."""

from __future__ import annotations

import numpy as np
import pytest

from semwm.knowledge.loader import load_knowledge
from semwm.knowledge.shipped import shipped_knowledge_path
from semwm.sim.scenarios import SIM2_FALSE_PAIR, make_scenario, robocup, sim1, sim2


@pytest.mark.parametrize("name", ["sim1", "sim2", "robocup", "grid"])
def test_same_seed_same_scenario_other_seed_other(name: str) -> None:
    sizes = {"duration": 1.0} if name == "robocup" else {}
    a = make_scenario(name, 3, **sizes)
    b = make_scenario(name, 3, **sizes)
    c = make_scenario(name, 4, **sizes)
    assert a.detections == b.detections and a.truth == b.truth
    assert a.detections != c.detections


@pytest.mark.parametrize("name", ["sim1", "sim2", "robocup", "grid"])
def test_detections_sorted_and_use_the_knowledge_names(name: str) -> None:
    sizes = {"duration": 1.0} if name == "robocup" else {}
    scenario = make_scenario(name, 0, **sizes)
    times = [d.time for d in scenario.detections]
    assert times == sorted(times)
    knowledge = load_knowledge(shipped_knowledge_path(scenario.knowledge_file))
    assert {d.cls for d in scenario.detections} <= set(knowledge.classes)
    assert {d.detector for d in scenario.detections} <= set(knowledge.detectors)
    for frame in scenario.truth:
        assert {o.cls for o in frame.objects} <= set(knowledge.classes)
    for d in scenario.detections:
        for value, (low, high) in zip(d.position, scenario.region, strict=True):
            assert low - 1.0 <= value <= high + 1.0


def test_unknown_scenario_names_the_known_ones() -> None:
    with pytest.raises(ValueError, match="known scenarios: sim1, sim2, robocup, grid"):
        make_scenario("sim9")


def test_sim1_labels_rates_and_scans() -> None:
    s = sim1(np.random.default_rng(0), duration=200.0)
    n_frames = len(s.truth)
    assert {d.source for d in s.detections} == {"camera"}
    assert len(s.truth[0].objects) == 5
    by_truth: dict[str, int] = {}
    generic = wrong = 0
    for d in s.detections:
        near = [
            o for o in s.truth[0].objects if np.hypot(*np.subtract(d.position, o.position)) < 0.4
        ]
        if len(near) == 1:
            o = near[0]
            by_truth[o.cls] = by_truth.get(o.cls, 0) + 1
            generic += o.cls in ("CokeCan", "BeerCan") and d.cls == "Can"
    assert by_truth["Cup"] / (2 * n_frames) > 0.7  # cups and cans seen more often
    assert by_truth["Table"] / n_frames < 0.35
    assert by_truth["CokeCan"] + by_truth["BeerCan"] > 1.5 * 0.7 * n_frames
    assert generic > 0.2 * (by_truth["CokeCan"] + by_truth["BeerCan"])
    wrong = len(s.metadata["wrong_labels"])  # type: ignore[arg-type]
    assert 0 < wrong < 0.08 * len(s.detections)


def test_sim2_occlusions_door_and_false_pair() -> None:
    s = sim2(np.random.default_rng(0))
    m = s.metadata["moments"]
    assert isinstance(m, dict)
    assert m["B"] - m["A"] == pytest.approx(1.5) and m["D"] - m["C"] == pytest.approx(1.5)
    assert m["A"] < m["B"] < m["E"] < m["C"] < m["D"] < m["F"]
    frames = [f for f in s.truth if f.objects]
    first, last = frames[0].objects[0], frames[-1].objects[0]
    door = np.asarray(s.metadata["door"])
    assert np.hypot(*(np.asarray(first.position) - door)) < 0.5
    assert np.hypot(*(np.asarray(last.position) - door)) < 0.5
    speeds = [np.hypot(*f.objects[0].velocity) for f in frames]
    assert np.allclose(speeds, 1.0, atol=1e-6)
    # anti-clockwise: positive signed area of the walked loop
    xy = np.asarray([f.objects[0].position for f in frames])
    area = 0.5 * np.sum(xy[:-1, 0] * xy[1:, 1] - xy[1:, 0] * xy[:-1, 1])
    assert area > 20.0
    person = {f.time: f.objects[0] for f in frames}
    for start, end in ((m["A"], m["B"]), (m["C"], m["D"])):
        assert all(not person[t].visible for t in person if start <= t < end - 1e-9)
    # the false pair of E is there for every seed, at the same place and times
    for seed in (0, 1):
        other = sim2(np.random.default_rng(seed))
        at = {(d.position, d.time) for d in other.detections}
        for x, y, dt in SIM2_FALSE_PAIR:
            assert any(p == (x, y) and abs(t - (m["E"] + dt)) < 0.1 + 1e-6 for p, t in at)


def test_sim2_person_detected_at_about_ten_hertz_but_never_while_occluded() -> None:
    s = sim2(np.random.default_rng(1), clutter_rate=0.0)
    m = s.metadata["moments"]
    assert isinstance(m, dict)
    pair_times = {round(m["E"] + dt, 3) for _, _, dt in SIM2_FALSE_PAIR}
    person = [d for d in s.detections if round(d.time, 3) not in pair_times or d.position[0] < 6]
    assert all(not (m["A"] <= d.time < m["B"] or m["C"] <= d.time < m["D"]) for d in person)
    walk = s.metadata["leave_time"] - s.metadata["enter_time"]  # type: ignore[operator]
    assert 0.8 * 10 * (walk - 3) < len(person) < 10 * walk


def test_robocup_sizes_labels_range_and_occlusion() -> None:
    s = robocup(np.random.default_rng(0), n_peers=3, n_opponents=4, duration=3.0)
    assert len(s.truth[0].objects) == 7
    assert len(s.truth) == 31  # 10 Hz truth over 3 s
    selfloc = [d for d in s.detections if d.detector == "self_localization"]
    assert len(selfloc) == 3 * 91
    assert all(d.cls == "Peer" and d.label == d.source for d in selfloc)
    omni = [d for d in s.detections if d.detector == "omnivision"]
    assert {d.cls for d in omni} == {"Robot"} and all(d.label is None for d in omni)
    assert all(
        d.sensor_position is not None
        and np.hypot(*np.subtract(d.position, d.sensor_position)) <= 5.0 + 1.5
        for d in omni
    )
    speeds = [np.hypot(*o.velocity) for f in s.truth for o in f.objects]
    assert max(speeds) <= 4.0 + 1e-9
    big = robocup(np.random.default_rng(0), duration=3.0)
    assert big.metadata["occluded_detections"] > 0  # type: ignore[operator]
