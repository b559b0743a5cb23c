"""``GET /world``'s body written directly (``api/world_json.py``) is, byte for byte,
what the response model gave: ``WorldOut`` validated from the world's dicts and
serialised with its aliases, on real worlds (IMM modes, class distributions, labels,
confidences, provisional ids, an object at the edge of existence)."""

from __future__ import annotations

import math

import pytest

from api.schemas import WorldObjectOut, WorldOut
from api.world_json import object_json, world_json
from semwm.confidence import Confidence
from semwm.knowledge.loader import load_knowledge
from semwm.knowledge.shipped import shipped_knowledge_path
from semwm.sim.runner import scans
from semwm.sim.scenarios import make_scenario
from semwm.world import WorldModel
from semwm.world_types import WorldObject, WorldState


def _through_the_model(state: WorldState) -> bytes:
    return WorldOut.model_validate(state.to_dict()).model_dump_json(by_alias=True).encode()


@pytest.mark.parametrize(
    ("name", "sizes"), [("sim1", {}), ("sim2", {}), ("robocup", {"duration": 0.5})]
)
def test_the_body_is_the_response_models(name: str, sizes: dict[str, float]) -> None:
    scenario = make_scenario(name, 2, **sizes)
    world = WorldModel(load_knowledge(shipped_knowledge_path(scenario.knowledge_file)))
    compared = 0
    for k, scan in enumerate(scans(scenario.detections)):
        world.ingest(scan)
        if k % 5:
            continue
        for state in (world.world(), world.world(min_existence=0.001)):
            assert world_json(state) == _through_the_model(state)
            for obj in state.objects[:2]:
                expected = WorldObjectOut.model_validate(obj.to_dict()).model_dump_json(
                    by_alias=True
                )
                assert object_json(obj) == expected.encode()
            compared += len(state.objects)
    assert compared > 20


def test_ints_non_finite_numbers_and_empty_worlds_as_the_model_writes_them() -> None:
    odd = WorldObject(
        7, "Cup", "r1", (1.0, -0.0), None, ((math.inf, 0.0), (0.0, 1e-300)), 1, 3, 2,
        None, {"Cup": 1.0}, Confidence(1, "valid"),
    )  # fmt: skip
    for state in (WorldState(12, (odd,)), WorldState(None, ()), WorldState(0.5, ())):
        assert world_json(state) == _through_the_model(state)
    assert b'"existence":1.0' in world_json(WorldState(1.0, (odd,)))  # an int as a float
    assert b"[null,0.0]" in world_json(WorldState(1.0, (odd,)))  # inf as null
