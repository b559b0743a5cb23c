"""Issue 28's acceptance on the ``leftbehind`` scenario, seeds 0-2, both variants.

A robot patrolling a room leaves objects behind (seen, out of view about a minute,
seen again). With sensor poses (each scan's pose and heading passed as its sensor
view, :func:`semwm.sim.leftbehind.with_sensor_views`): (a) every object out of view
stays in the published world while present, (b) every object removed in view leaves
it within 2 s of its next missed view. Without poses: (c) every object the fixed
camera ``cam2`` never saw stays while present. Knowledge:
``benchmarks/knowledge/leftbehind.yaml`` (datasheets and floor plan only).

Before issue 28's model change an object left the world about 1 s after it left the
robot's view. After it, with poses, (b) passes and (a) misses single frames; without
poses (c) still fails (see the mark).
"""

from __future__ import annotations

from pathlib import Path

import pytest

from semwm import load_knowledge
from semwm.sim.leftbehind import acceptance, leftbehind_checks, with_sensor_views
from semwm.sim.runner import run_scenario
from semwm.sim.scenarios import make_scenario

KNOWLEDGE = Path(__file__).resolve().parents[2] / "benchmarks" / "knowledge" / "leftbehind.yaml"


@pytest.mark.xfail(
    strict=False,
    reason="issue 28, not met yet: with poses (a) misses 1-2 single frames of 7158 (seed 0) "
    "and (b) passes; without poses the learnt coverage (a source's span around what it "
    "reports) counts a moving robot's scans as misses for objects beside its field of view "
    "(seed 0: 8 of 12 objects lost on leaving the view)",
)
@pytest.mark.parametrize("poses", [True, False], ids=["poses", "no_poses"])
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_leftbehind_keeps_what_it_cannot_see(seed: int, poses: bool) -> None:
    scenario = make_scenario("leftbehind", seed, poses=poses)
    factory = with_sensor_views(scenario) if poses else None
    result = run_scenario(
        scenario, load_knowledge(KNOWLEDGE), progress=False, world_model_factory=factory
    )
    report = {c.name: c.detail() for c in leftbehind_checks(scenario, result.worlds)}
    for check in acceptance(scenario, result.worlds):
        assert check.objects_asked > 0, check.name
        assert check.passed, (check.detail(), report)
