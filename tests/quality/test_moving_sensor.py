"""A robot whose short-range detector moves (the ``patrol`` variant): what it left
behind stays in the world, and an object it lost is not taken for one it sees.

Both cases were found by running ``benchmarks/knowledge/patrol.yaml``, a file written
from a datasheet only, on the ``patrol`` scenario's seeds."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from semwm import WorldModel, load_knowledge
from semwm.filters.small import mahalanobis_squared
from semwm.sim.checks import run_checks
from semwm.sim.runner import run_scenario
from semwm.sim.scenarios import make_scenario
from semwm.world import _coinciding

PATROL_KNOWLEDGE = Path(__file__).resolve().parents[2] / "benchmarks" / "knowledge" / "patrol.yaml"


def _model() -> WorldModel:
    return WorldModel(load_knowledge(PATROL_KNOWLEDGE), reorder_window=0.0)


def _seen(time: float, cls: str, at: tuple[float, float], sensor: tuple[float, float]) -> dict:
    return {
        "time": round(time, 6),
        "class": cls,
        "position": list(at),
        "source": "robot",
        "detector": "scanner",
        "sensor_position": list(sensor),
    }


def _nearest(world, cls: str, at: tuple[float, float]):
    same = [o for o in world.objects if o.cls == cls]
    return min(same, key=lambda o: np.hypot(o.position[0] - at[0], o.position[1] - at[1]))


def test_a_silent_moving_sensor_does_not_deny_what_it_left_behind() -> None:
    """The robot sees a pallet 5.9 m away for 3 s, drives on at 1 m/s and reports
    nothing for 1 s (no object in view). Where it was, the pallet would be in view; the
    robot has moved on, so the silence says nothing about the pallet. It used to take
    the whole second as one of "pallet in view, not detected" (rate 8.5 Hz): existence
    0.15, gone from the world."""
    wm = _model()
    pallet = (15.9, 10.0)
    robot_x = 10.0
    t = 0.0
    while t < 3.0:  # the robot creeps along y = 10 at 0.01 m/s: the pallet stays 5.9 m off
        wm.ingest([_seen(t, "Pallet", pallet, (robot_x, 10.0))])
        t += 0.1
    # it drives away (x decreasing) at 1 m/s; one scan with something else in view
    robot_x -= 0.1
    wm.ingest([_seen(t, "Person", (robot_x - 2.0, 12.0), (robot_x, 10.0))])
    wm.ingest([_seen(t + 1.0, "Person", (robot_x - 3.0, 12.0), (robot_x - 1.0, 10.0))])
    kept = _nearest(wm.world(t + 1.0), "Pallet", pallet)
    assert np.hypot(kept.position[0] - pallet[0], kept.position[1] - pallet[1]) < 0.1
    assert kept.existence > 0.9


def test_a_standing_sensor_still_denies_what_leaves_its_view() -> None:
    """A sensor that stands still and goes on scanning (it reports a pallet): the person
    it saw is gone from its view, each of its scans is a miss, and the person goes."""
    wm = _model()
    sensor = (10.0, 10.0)
    for k in range(30):
        wm.ingest([_seen(0.1 * k, "Person", (12.0, 10.0), sensor)])
    for k in range(30, 40):
        wm.ingest([_seen(0.1 * k, "Pallet", (7.0, 10.0), sensor)])
    assert not [o for o in wm.world(4.0).objects if o.cls == "Person"]


def test_silence_from_a_standing_sensor_is_not_a_miss() -> None:
    """Silence is never a miss (issue 28): a sensor that stops sending says nothing about
    what it saw, even standing still; the next scan counts as at most two of its
    intervals of looking, not the whole silence."""
    wm = _model()
    sensor = (10.0, 10.0)
    for k in range(30):
        wm.ingest([_seen(0.1 * k, "Person", (12.0, 10.0), sensor)])
    wm.ingest([_seen(6.0, "Pallet", (7.0, 10.0), sensor)])
    (person,) = [o for o in wm.world(min_existence=1e-9).objects if o.cls == "Person"]
    assert person.existence > 0.1


def test_estimates_of_very_different_spread_are_not_one_object() -> None:
    """The published world groups lineages whose estimates coincide as one object. A
    person lost for 30 s has an estimate spread over tens of metres, and under that
    spread the estimate of a person in view nearby is "within the gate" of the means'
    Mahalanobis distance: in the patrol run of seed 3 such groups summed to existence
    1 and were published as the lost person, 7 m outside the warehouse, in place of
    the one in view. Two estimates of that different spread are not one object
    (Bhattacharyya distance); with equal spread the test is the Mahalanobis one."""
    rng = np.random.default_rng(0)
    delta = rng.normal(0.0, 0.3, (500, 2))
    spread = np.repeat(np.diag([0.02, 0.05])[None], 500, axis=0)
    d2 = mahalanobis_squared(delta, spread + spread)
    assert np.array_equal(_coinciding(delta, spread, spread), d2 <= 1.0)
    assert 0 < (d2 <= 1.0).sum() < 500
    lost = np.diag([2200.0, 2200.0])[None]
    in_view = np.diag([0.004, 0.004])[None]
    offset = np.array([[4.0, 3.0]])
    assert mahalanobis_squared(offset, lost + in_view)[0] < 0.1  # the old test: one object
    assert not _coinciding(offset, lost, in_view)[0]
    assert not _coinciding(np.zeros((1, 2)), lost, in_view)[0]  # even at the same mean
    assert _coinciding(offset, lost, 1.01 * lost)[0]  # two lost estimates alike: one


@pytest.mark.parametrize("seed", [1, 3])
def test_the_patrol_variant_passes_its_checks(seed: int) -> None:
    """Seeds where the two defects above showed (seed 1: a pallet dropped at the edge
    of the view; seed 3: a lost person published 7 m outside the warehouse)."""
    scenario = make_scenario("patrol", seed, duration=45.0)
    result = run_scenario(scenario, load_knowledge(PATROL_KNOWLEDGE), progress=False)
    failed = [c for c in run_checks(result) if not c.passed]
    assert not failed, failed
