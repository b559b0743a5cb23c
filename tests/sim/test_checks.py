"""The acceptance checks of semwm.sim.checks on hand-made truth and worlds."""

from __future__ import annotations

from semwm.sim.checks import (
    SCENARIO_CHECKS,
    final_objects_match,
    inside_region,
    labels_kept,
    no_id_switch,
    one_id_each,
)
from semwm.sim.scenarios import SCENARIOS, TruthFrame, TruthObject
from semwm.world_types import WorldObject, WorldState

REGION = ((0.0, 4.0), (0.0, 3.0))


def _truth(t: float, *objects: tuple[str, str, float, float, str | None]) -> TruthFrame:
    return TruthFrame(
        t, tuple(TruthObject(i, c, (x, y), (0.0, 0.0), label=lab) for i, c, x, y, lab in objects)
    )


def _world(t: float, *objects: tuple[int, str, float, float, str | None]) -> WorldState:
    return WorldState(
        t,
        tuple(
            WorldObject(
                id=i,
                cls=c,
                label=lab,
                position=(x, y),
                velocity=None,
                covariance=((0.01, 0.0), (0.0, 0.01)),
                existence=1.0,
                last_seen=t,
                created=0.0,
                mode_probabilities=None,
            )
            for i, c, x, y, lab in objects
        ),
    )


CUP = ("cup", "Cup", 1.0, 1.0, None)
CAN = ("can", "CokeCan", 2.0, 2.0, None)


def test_final_objects_match_needs_one_object_each_with_the_exact_class() -> None:
    truth = [_truth(0.0, CUP, CAN), _truth(1.0, CUP, CAN)]
    good = _world(1.0, (1, "Cup", 1.05, 1.0, None), (2, "CokeCan", 2.0, 2.1, None))
    assert final_objects_match(truth, [good, good], c=0.5).passed
    extra = _world(
        1.0, (1, "Cup", 1.05, 1.0, None), (2, "CokeCan", 2.0, 2.1, None), (3, "Cup", 1.1, 1.0, None)
    )
    result = final_objects_match(truth, [good, extra], c=0.5)
    assert not result.passed and "1 extra" in result.detail
    superclass = _world(1.0, (1, "Cup", 1.0, 1.0, None), (2, "Can", 2.0, 2.0, None))
    result = final_objects_match(truth, [good, superclass], c=0.5)
    assert not result.passed and "CokeCan as Can" in result.detail
    far = _world(1.0, (1, "Cup", 1.0, 1.0, None), (2, "CokeCan", 2.6, 2.0, None))  # 0.6 > c
    result = final_objects_match(truth, [good, far], c=0.5)
    assert not result.passed and "1 missed" in result.detail


def test_no_id_switch() -> None:
    assert no_id_switch(0).passed
    assert not no_id_switch(2).passed


def test_one_id_each_fails_on_a_new_id_and_on_a_shared_id() -> None:
    truth = [_truth(0.0, CUP, CAN), _truth(1.0, CUP, CAN)]
    same = [
        _world(0.0, (1, "Cup", 1.0, 1.0, None), (2, "CokeCan", 2.0, 2.0, None)),
        _world(1.0, (1, "Cup", 1.0, 1.0, None), (2, "CokeCan", 2.0, 2.0, None)),
    ]
    assert one_id_each(truth, same, c=0.5).passed
    renamed = [same[0], _world(1.0, (1, "Cup", 1.0, 1.0, None), (5, "CokeCan", 2.0, 2.0, None))]
    result = one_id_each(truth, renamed, c=0.5)
    assert not result.passed and "can: 2 ids" in result.detail
    # one person leaves, another comes in and is published under the same id
    visits = [_truth(0.0, ("p1", "Person", 1.0, 1.0, None)), _truth(1.0, ("p2", "P", 3, 2, None))]
    reused = [_world(0.0, (7, "Person", 1.0, 1.0, None)), _world(1.0, (7, "Person", 3, 2, None))]
    result = one_id_each(visits, reused, c=0.5)
    assert not result.passed and "id 7 on 2 real objects" in result.detail
    never = one_id_each(truth, [_world(0.0), _world(1.0)], c=0.5)
    assert not never.passed and "0 ids" in never.detail


def test_inside_region_allows_the_margin_and_no_more() -> None:
    just = [_world(0.0, (1, "Person", 4.2, 1.0, None))]
    assert inside_region(just, REGION, margin=0.25).passed
    out = [_world(0.0, (1, "Person", 1.0, -0.3, None)), _world(1.0, (1, "P", 1.0, -1.0, None))]
    result = inside_region(out, REGION, margin=0.25)
    assert not result.passed and "2 object-frames" in result.detail and "1.00 m" in result.detail


def test_labels_kept_needs_the_label_on_one_near_object_under_one_id() -> None:
    truth = [_truth(t, ("peer1", "Peer", 1.0 + t, 1.0, "peer1")) for t in (0.0, 1.0, 2.0)]
    kept = [_world(t, (3, "Peer", 1.0 + t, 1.1, "peer1")) for t in (0.0, 1.0, 2.0)]
    assert labels_kept(truth, kept, c=2.0).passed
    switched = [*kept[:2], _world(2.0, (4, "Peer", 3.0, 1.0, "peer1"))]
    result = labels_kept(truth, switched, c=2.0)
    assert not result.passed and "id 3 -> 4 at t=2" in result.detail
    lost = [*kept[:2], _world(2.0, (3, "Robot", 3.0, 1.0, None))]
    result = labels_kept(truth, lost, c=2.0)
    assert not result.passed and "0 objects labelled at t=2" in result.detail
    twice = [*kept[:2], _world(2.0, (3, "Peer", 3, 1, "peer1"), (4, "Peer", 3, 1, "peer1"))]
    assert not labels_kept(truth, twice, c=2.0).passed
    astray = [*kept[:2], _world(2.0, (3, "Peer", 6.0, 1.0, "peer1"))]
    result = labels_kept(truth, astray, c=2.0)
    assert not result.passed and "3.00 m away" in result.detail


def test_every_benchmarked_scenario_has_checks() -> None:
    shipped_and_variants = set(SCENARIOS) - {"grid"}
    assert set(SCENARIO_CHECKS) == shipped_and_variants
