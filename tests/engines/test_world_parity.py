"""Both engines give the same worlds, frame by frame, on the shipped scenarios.

After every scan: the same published objects (ids, classes, labels, counts) with
positions, velocities, covariances, existence, mode and class probabilities within
1e-9, and the same hypotheses (count, and the 20 most probable within 1e-9). The Python
engine is the specification (docs/engines.md)."""

from __future__ import annotations

import math
from typing import Any

import pytest

from semwm.knowledge.loader import load_knowledge
from semwm.knowledge.shipped import shipped_knowledge_path
from semwm.sim.runner import scans
from semwm.sim.scenarios import make_scenario
from semwm.world import WorldModel
from semwm.world_types import WorldObject

from . import needs_rust

pytestmark = needs_rust

TOL = 1e-9
SCENARIOS = [("sim1", {}), ("sim2", {}), ("robocup", {"duration": 2.0})]


def _numbers(obj: WorldObject) -> list[float]:
    values = [*obj.position, *(obj.velocity or ()), *sum(obj.covariance, ()), obj.existence]
    values += [*(obj.mode_probabilities or {}).values()]
    values += [*(obj.class_probabilities or {}).values()]
    return values


def _keys(obj: WorldObject) -> tuple[Any, ...]:
    return (
        obj.id,
        obj.cls,
        obj.label,
        tuple(obj.mode_probabilities or ()),
        tuple(obj.class_probabilities or ()),
    )


def _largest_difference(a: list[float], b: list[float]) -> float:
    assert len(a) == len(b)
    return max((abs(x - y) for x, y in zip(a, b, strict=True)), default=0.0)


@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize(("name", "sizes"), SCENARIOS, ids=[s[0] for s in SCENARIOS])
def test_same_world_every_frame(name: str, sizes: dict[str, float], seed: int) -> None:
    scenario = make_scenario(name, seed, **sizes)
    knowledge = load_knowledge(shipped_knowledge_path(scenario.knowledge_file))
    python = WorldModel(knowledge, engine="python")
    rust = WorldModel(knowledge, engine="rust")
    frames = objects = 0
    for scan in scans(scenario.detections):
        python.ingest(scan)
        rust.ingest(scan)
        expected = python.world(min_existence=1e-6).objects
        got = rust.world(min_existence=1e-6).objects
        assert [_keys(o) for o in got] == [_keys(o) for o in expected], f"frame {frames}"
        for g, e in zip(got, expected, strict=True):
            assert _largest_difference(_numbers(g), _numbers(e)) <= TOL, (frames, g.id)
        p_hyp = sorted(h.probability for h in python.hypotheses(20))
        r_hyp = sorted(h.probability for h in rust.hypotheses(20))
        assert len(r_hyp) == len(p_hyp) and _largest_difference(r_hyp, p_hyp) <= TOL
        assert rust.hypothesis_count == python.hypothesis_count
        frames += 1
        objects += len(expected)
    assert frames > 10 and objects > frames  # a real run, not an empty one
    assert math.isfinite(rust.latest_time or 0.0)
