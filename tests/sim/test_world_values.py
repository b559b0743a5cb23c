"""The world's answer values as plain dicts (``WorldObject.to_dict``,
``HypothesisObject.to_dict``): written out for speed, they must stay what
``dataclasses.asdict`` gives (``cls`` renamed ``class``, last), field for field and
in order, on real worlds with IMM modes, class distributions and confidences."""

from __future__ import annotations

from dataclasses import asdict, fields
from typing import Any

import pytest

from semwm.knowledge.loader import load_knowledge
from semwm.knowledge.shipped import shipped_knowledge_path
from semwm.sim.runner import scans
from semwm.sim.scenarios import make_scenario
from semwm.world import WorldModel
from semwm.world_types import HypothesisObject, WorldObject


def _asdict(value: Any) -> dict[str, Any]:
    data = asdict(value)
    data["class"] = data.pop("cls")
    return data


@pytest.mark.parametrize(("name", "sizes"), [("sim2", {}), ("robocup", {"duration": 0.5})])
def test_to_dict_is_asdict_with_class_last(name: str, sizes: dict[str, float]) -> None:
    scenario = make_scenario(name, 1, **sizes)
    world = WorldModel(load_knowledge(shipped_knowledge_path(scenario.knowledge_file)))
    seen: set[str] = set()
    for scan in scans(scenario.detections):
        world.ingest(scan)
        values: list[WorldObject | HypothesisObject] = list(
            world.world(min_existence=0.001).objects
        )
        values += [o for h in world.hypotheses(3) for o in h.objects]
        for value in values:
            expected, got = _asdict(value), value.to_dict()
            assert got == expected and list(got) == list(expected)
            seen.update(k for k, v in got.items() if v is not None)
            # Python floats, not numpy scalars (an existence below 1 was an np.float64)
            assert type(value.existence) is float
            assert all(type(v) is float for v in value.position)
        for obj in world.world(min_existence=0.001).objects:
            numbers = [*obj.position, *(obj.velocity or ()), *sum(obj.covariance, ())]
            numbers += [*(obj.mode_probabilities or {}).values()]
            numbers += [*(obj.class_probabilities or {}).values()]
            numbers += [obj.confidence.value] if obj.confidence is not None else []
            assert all(type(v) is float for v in numbers)
    # every field was filled at least once (modes, class probabilities, confidence;
    # labels in RoboCup only)
    unlabelled = {"label"} if name == "sim2" else set()
    assert {f.name for f in fields(WorldObject)} - {"cls"} - unlabelled <= seen


def test_the_nested_dicts_are_copies() -> None:
    obj = WorldObject(
        1, "Cup", None, (1.0, 2.0), None, ((1.0, 0.0), (0.0, 1.0)), 1.0, 0.0, 0.0,
        {"a": 1.0}, {"Cup": 1.0},
    )  # fmt: skip
    data = obj.to_dict()
    assert data["mode_probabilities"] == {"a": 1.0}
    assert data["mode_probabilities"] is not obj.mode_probabilities
    assert data["class_probabilities"] is not obj.class_probabilities
