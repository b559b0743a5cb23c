"""The harder scenario variants of issue 9: shape, determinism per seed, truth
consistent with the detections. No tracking here."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from semwm.knowledge.loader import load_knowledge
from semwm.knowledge.shipped import shipped_knowledge_path
from semwm.sim.scenarios import (
    DATASHEET_REGION,
    SIM2_DOOR,
    SIM2_REGION,
    TABLETOP_CONFUSIONS,
    Scenario,
    corner_occlusion,
    datasheet,
    door_exits,
    make_scenario,
    patrol,
    tabletop_wrong_labels,
)

VARIANTS = ("tabletop_wrong_labels", "corner_occlusion", "door_exits", "datasheet", "patrol")
REPOSITORY = Path(__file__).resolve().parents[2]


def _knowledge_path(scenario: Scenario) -> Path:
    directory = scenario.metadata.get("knowledge_dir")
    if directory is not None:
        return REPOSITORY / str(directory) / scenario.knowledge_file
    return shipped_knowledge_path(scenario.knowledge_file)


def _inside(position: tuple[float, ...], region: tuple[tuple[float, float], ...]) -> bool:
    return all(lo <= v <= hi for v, (lo, hi) in zip(position, region, strict=True))


@pytest.mark.parametrize("name", VARIANTS)
def test_same_seed_same_scenario_other_seed_other(name: str) -> None:
    a, b, c = make_scenario(name, 7), make_scenario(name, 7), make_scenario(name, 8)
    assert a.detections == b.detections and a.truth == b.truth
    assert a.detections != c.detections


@pytest.mark.parametrize("name", VARIANTS)
def test_sorted_in_the_region_and_named_as_the_knowledge(name: str) -> None:
    s = make_scenario(name, 0)
    assert s.name == name
    assert [d.time for d in s.detections] == sorted(d.time for d in s.detections)
    assert [f.time for f in s.truth] == sorted({f.time for f in s.truth})
    assert s.truth[-1].time == pytest.approx(s.duration)
    knowledge = load_knowledge(_knowledge_path(s))
    assert {d.cls for d in s.detections} <= set(knowledge.classes)
    assert {d.detector for d in s.detections} <= set(knowledge.detectors)
    wider = tuple((lo - 1.0, hi + 1.0) for lo, hi in s.region)  # noise may cross a wall
    assert all(_inside(d.position, wider) for d in s.detections)
    for frame in s.truth:
        assert {o.cls for o in frame.objects} <= set(knowledge.classes)
        assert all(_inside(o.position, s.region) for o in frame.objects)
        assert len({o.id for o in frame.objects}) == len(frame.objects)


@pytest.mark.parametrize("seed", range(4))
def test_tabletop_objects_are_first_reported_as_a_sibling(seed: int) -> None:
    s = tabletop_wrong_labels(np.random.default_rng(seed))
    final = s.truth[-1].objects
    assert 4 <= len(final) <= 8
    assert {"CokeCan", "BeerCan"} <= {o.cls for o in final}
    xy = np.array([o.position for o in final])
    distances = np.linalg.norm(xy[:, None] - xy[None], axis=-1) + np.eye(len(final))
    assert distances.min() >= 0.4
    placed = dict(zip([o.id for o in final], s.metadata["placed"], strict=True))  # type: ignore[call-overload]
    for frame in s.truth:  # an object stays where it was put from its placing on
        assert {o.id for o in frame.objects} == {i for i, t in placed.items() if t <= frame.time}
    for obj, n_wrong in zip(final, s.metadata["wrong_first"], strict=True):  # type: ignore[call-overload]
        near = [
            d
            for d in s.detections
            if np.hypot(*np.subtract(d.position, obj.position)) < 0.2 and d.time >= placed[obj.id]
        ]
        first = near[:n_wrong]
        assert len(first) == n_wrong
        assert all(d.cls in TABLETOP_CONFUSIONS[obj.cls] for d in first)
        later = [d.cls for d in near[n_wrong:]]
        assert later.count(obj.cls) > 0.6 * len(later)  # then mostly the right class


@pytest.mark.parametrize("seed", range(4))
def test_corner_occlusion_hides_the_person_at_each_corner(seed: int) -> None:
    s = corner_occlusion(np.random.default_rng(seed))
    occlusions = s.metadata["occlusions"]
    assert isinstance(occlusions, list) and len(occlusions) == 2
    for (start, end), corner in zip(occlusions, s.metadata["corners"], strict=True):  # type: ignore[call-overload]
        assert 2.0 <= end - start <= 4.0
        hidden = [f.objects[0] for f in s.truth if start <= f.time < end]
        assert hidden and not any(o.visible for o in hidden)
        # hidden while turning: nearest to the corner inside the hidden interval
        assert min(np.hypot(*np.subtract(o.position, corner)) for o in hidden) < 0.5
        person_at = {f.time: f.objects[0].position for f in s.truth if f.objects}
        near_person = [
            d
            for d in s.detections
            if start <= d.time < end and np.hypot(*np.subtract(d.position, person_at[d.time])) < 0.3
        ]
        assert near_person == []
    people = [f.objects[0] for f in s.truth if f.objects]
    first = people[0]
    assert np.hypot(first.position[0] - SIM2_DOOR[0], first.position[1] - SIM2_DOOR[1]) < 0.5
    speeds = np.array([np.hypot(*o.velocity) for o in people])
    moving = speeds[speeds > 0.0]
    assert len(moving) > len(people) / 2
    assert np.allclose(moving, s.metadata["speed"], atol=2e-3)  # speed is rounded to 1 mm/s


@pytest.mark.parametrize("seed", range(4))
def test_door_exits_people_come_and_go_through_the_door(seed: int) -> None:
    s = door_exits(np.random.default_rng(seed))
    frames = {f.time: {o.id: o for o in f.objects} for f in s.truth}
    times = sorted(frames)
    ids = {i for f in frames.values() for i in f}
    assert 3 <= len(ids) <= 5
    doorway = np.array([SIM2_DOOR[0], SIM2_REGION[1][1]])
    left = 0
    for person in ids:
        present = [k for k, t in enumerate(times) if person in frames[t]]
        assert present == list(range(present[0], present[-1] + 1))  # one visit
        first = frames[times[present[0]]][person]
        assert np.hypot(*np.subtract(first.position, doorway)) < 0.6
        if present[-1] < len(times) - 1:  # left before the end: through the door
            left += 1
            last = frames[times[present[-1]]][person]
            assert np.hypot(*np.subtract(last.position, doorway)) < 0.6
    assert left >= 1


def test_datasheet_rates_match_the_sensor_and_its_knowledge_file() -> None:
    s = datasheet(np.random.default_rng(0), duration=300.0)
    knowledge = load_knowledge(_knowledge_path(s))
    rate, recall, fp = 10.0, 0.9, 0.2  # the generator's defaults, the datasheet's numbers
    assert knowledge.classes["Person"].detection_frequency == pytest.approx(rate * recall)
    assert knowledge.detectors["overhead"].clutter_frequency == pytest.approx(rate * fp)
    assert knowledge.world.region == DATASHEET_REGION
    # every object in view is reported with probability `recall` per frame
    object_frames = sum(len(f.objects) for f in s.truth)
    by_time: dict[float, list[np.ndarray]] = {}
    for d in s.detections:
        by_time.setdefault(d.time, []).append(np.asarray(d.position))
    hits = 0
    for frame in s.truth:
        seen = by_time.get(frame.time, [])
        for o in frame.objects:
            hits += any(np.hypot(*(p - o.position)) < 0.4 for p in seen)
    p_clutter_near = fp * np.pi * 0.4**2 / 96.0  # a false positive landing within 0.4 m
    expected = recall + (1 - recall) * p_clutter_near
    sigma = np.sqrt(expected * (1 - expected) / object_frames)
    assert abs(hits / object_frames - expected) < 5 * sigma
    # people walk straight at constant velocity; boxes stand still
    for frame in s.truth:
        for o in frame.objects:
            if o.cls == "Box":
                assert o.velocity == (0.0, 0.0)
            else:
                assert 0.8 <= np.hypot(*o.velocity) <= 1.5
    assert len({o.id for f in s.truth for o in f.objects if o.cls == "Person"}) > 10


def test_patrol_reports_only_within_range_of_the_moving_sensor() -> None:
    s = patrol(np.random.default_rng(0), duration=60.0)
    knowledge = load_knowledge(_knowledge_path(s))
    rate, recall, fp, reach = 10.0, 0.85, 0.3, 6.0  # the generator's defaults, the datasheet's
    assert knowledge.classes["Pallet"].detection_frequency == pytest.approx(rate * recall)
    assert knowledge.detectors["scanner"].clutter_frequency == pytest.approx(rate * fp)
    assert knowledge.detectors["scanner"].range == reach
    sensors = {d.sensor_position for d in s.detections}
    assert len(sensors) > 100  # the robot moves
    for d in s.detections:
        assert d.sensor_position is not None
        assert np.hypot(*np.subtract(d.position, d.sensor_position)) <= reach + 0.5
    pallets = {o.id: o.position for o in s.truth[0].objects if o.cls == "Pallet"}
    assert s.metadata["static_ids"] == sorted(pallets, key=lambda k: int(k[6:]))
    for frame in s.truth:  # pallets stand still, people walk at most 1.4 m/s
        for o in frame.objects:
            if o.cls == "Pallet":
                assert o.position == pallets[o.id]
            else:
                assert np.hypot(*o.velocity) <= 1.4 + 1e-9
    first_seen = s.metadata["first_seen"]
    assert isinstance(first_seen, dict) and set(first_seen) <= {o.id for o in s.truth[0].objects}
    for real_id, t in first_seen.items():
        frame = next(f for f in s.truth if f.time == t)
        real = next(o for o in frame.objects if o.id == real_id)
        assert any(
            d.time == t and np.hypot(*np.subtract(d.position, real.position)) < 0.5
            for d in s.detections
        )


@pytest.mark.parametrize(("pallets", "people"), [(0, 2), (3, 0), (0, 0)])
def test_patrol_with_no_pallets_or_no_people(pallets: int, people: int) -> None:
    s = patrol(np.random.default_rng(0), duration=5.0, n_pallets=pallets, n_people=people)
    assert all(len(f.objects) == pallets + people for f in s.truth)
    assert s.metadata["static_ids"] == [f"pallet{i + 1}" for i in range(pallets)]
    assert {d.cls for d in s.detections} <= {"Pallet", "Person"}  # false positives only
