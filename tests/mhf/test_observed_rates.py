"""Detection rates observed on the sources' streams (semwm.mhf.rates), and what they fix:
a team reporting far faster than the knowledge's rate."""

from __future__ import annotations

import numpy as np
import pytest

from semwm import WorldModel
from semwm.knowledge.loader import knowledge_from_text
from semwm.mhf.rates import WINDOW_DETECTIONS, ObservedRates

KNOWLEDGE = """
world: {dimension: 2, region: [[0, 4], [0, 3]], observed_detection_rates: %s}
classes:
- name: Cup
  category: static
  detection_frequency: 2.0
  new_frequency: 0.05
  filter: {type: kalman, model: {motion_model: zeroth_order, system_noise: [[0.0001, 0], [0, 0.0001]]}}
  measurement_noise: [[0.0025, 0], [0, 0.0025]]
detectors:
- {name: camera, clutter_frequency: 0.5}
"""
CUPS = [(1.0, 1.0), (1.7, 1.0), (2.4, 1.0), (3.1, 1.0)]
DUPLICATE_TICK = 30  # t = 1 s


def scans(rates: ObservedRates, *, hz: float, p_detect: float, count: int) -> ObservedRates:
    rng = np.random.default_rng(0)
    alive = set(range(100))
    for k in range(count):
        detected = [i for i in range(100) if rng.random() < p_detect]
        rates = rates.after_scan("robot", k / hz, {"camera": detected}, {}, alive)
    return rates


@pytest.mark.parametrize(("hz", "p_detect"), [(30.0, 0.9), (10.0, 0.5), (2.5, 0.8)])
def test_a_streams_rate_is_its_scan_rate_times_its_detection_probability(
    hz: float, p_detect: float
) -> None:
    rates = scans(ObservedRates(), hz=hz, p_detect=p_detect, count=200)
    assert rates.rate(("robot", "camera")) == pytest.approx(hz * p_detect, rel=0.1)
    assert rates.rate(("robot", "lidar")) == 0.0  # a stream never seen
    assert rates.rate(("other", "camera")) == 0.0


def test_the_knowledge_rate_is_a_floor_and_a_stream_counts_only_while_it_sees_the_object() -> None:
    rates = scans(ObservedRates(), hz=30.0, p_detect=1.0, count=60)  # last scan at 59/30 s
    g = rates.rate(("robot", "camera"))
    assert g == pytest.approx(30.0, rel=0.05)
    last = 59 / 30
    lineages = [3, 500]  # 3 was detected in every scan; 500 never
    base = np.array([2.0, 2.0])
    now = rates.from_stream(("robot", "camera"), lineages, base, last + 0.01)
    assert now.tolist() == pytest.approx([g, 2.0])
    later = rates.from_stream(("robot", "camera"), lineages, base, last + 2 * WINDOW_DETECTIONS / g)
    assert later.tolist() == [2.0, 2.0]
    assert rates.from_stream(
        ("robot", "camera"), lineages, np.array([50.0, 2.0]), last
    ).tolist() == [
        50.0,
        2.0,
    ]
    # over an interval the stream counts for the part in which it still sees the object
    window = WINDOW_DETECTIONS / g
    averaged = rates.over(lineages, base, last, last + 2 * window)
    assert averaged.tolist() == pytest.approx([2.0 + (g - 2.0) / 2, 2.0])


def test_lineages_that_are_gone_are_forgotten() -> None:
    rates = ObservedRates().after_scan("robot", 0.0, {"camera": [1, 2]}, {"camera": [3]}, {1, 2, 3})
    assert set(rates.seen) == {1, 2, 3}
    rates = rates.after_scan("robot", 0.1, {"camera": [1]}, {}, {1})
    assert set(rates.seen) == {1}


def team_stream(observed: bool, until: float) -> tuple[WorldModel, list[int]]:
    """Five robots at 30 Hz on four cups 0.7 m apart (5 cm noise); at t = 1 s robot0
    also reports a cup 0.3 m from the first one, outside its gate: a duplicate.
    Returns the model and the stored hypothesis count after each frame from t = 1 s."""
    wm = WorldModel(knowledge_from_text(KNOWLEDGE % str(observed).lower(), "yaml"))
    rng = np.random.default_rng(1)
    counts = []
    for tick in range(round(until * 30) + 1):
        t = tick / 30
        for robot in range(5):
            detections = [
                {
                    "time": t + 0.001 * robot,
                    "class": "Cup",
                    "position": (np.array(xy) + rng.normal(0.0, 0.05, 2)).tolist(),
                    "source": f"robot{robot}",
                }
                for xy in CUPS
            ]
            if tick == DUPLICATE_TICK and robot == 0:
                detections.append(
                    {"time": t, "class": "Cup", "position": [1.0, 1.3], "source": "robot0"}
                )
            wm.ingest(detections)
        if tick >= DUPLICATE_TICK:
            counts.append(wm.hypothesis_count)
    return wm, counts


def duplicate_existence(wm: WorldModel) -> float:
    near = [
        o.existence
        for o in wm.world(min_existence=1e-12).objects
        if float(np.hypot(*(np.asarray(o.position) - (1.0, 1.3)))) < 0.1
    ]
    return max(near, default=0.0)


def test_a_teams_duplicate_loses_existence_at_the_teams_rate_not_the_knowledges() -> None:
    # Nobody reports the duplicate again. At the knowledge's 2 Hz its existence would
    # fall by about exp(-2 x 0.2) = 0.67 in 0.2 s; the robots are observed to report
    # what they see at about 30 Hz each, and it falls faster than exp(-10 x 0.2).
    # (With the classes' rates this stream is not only wrong but slow: duplicates of
    # gate misses pile up in the hypotheses, minutes for one simulated second.)
    born, _ = team_stream(True, 1.0)
    later, _ = team_stream(True, 1.2)
    first = duplicate_existence(born)
    assert 0.01 < first < 0.5
    assert duplicate_existence(later) < first * np.exp(-10 * 0.2)


def test_a_teams_hypotheses_stay_bounded_and_its_world_is_the_four_cups() -> None:
    wm, counts = team_stream(True, 4.0)
    assert max(counts) <= 4 * len(CUPS), max(counts)
    assert sorted(np.round(o.position, 1).tolist() for o in wm.world().objects) == [
        list(xy) for xy in CUPS
    ]


def test_the_class_rate_applies_only_where_some_sensor_reaches() -> None:
    rates = ObservedRates()
    for k in range(5):
        rates = rates.after_scan("a", k / 10, {"camera": [1]}, {}, {1}, (0.0, 0.0))
        rates = rates.after_scan("b", k / 10, {"camera": [2]}, {}, {2}, (10.0, 0.0))
    positions = np.array([[1.0, 1.0], [5.0, 0.0], [9.0, 0.0]])
    assert rates.covered(positions, 3.0, 0.4).tolist() == [1.0, 0.0, 1.0]
    assert rates.covered(positions, None, 0.4).tolist() == [
        1.0,
        1.0,
        1.0,
    ]  # a detector without range
    # a source that does not say where its sensor is: coverage unknown, everywhere
    unknown = rates.after_scan("c", 0.4, {"camera": [3]}, {}, {1, 2, 3})
    unknown = unknown.after_scan("c", 0.5, {"camera": [3]}, {}, {1, 2, 3})
    assert unknown.covered(positions, 3.0, 0.5).tolist() == [1.0, 1.0, 1.0]
    # a source silent for many of its intervals no longer counts
    assert rates.covered(positions, 3.0, 5.0).tolist() == [1.0, 1.0, 1.0]
