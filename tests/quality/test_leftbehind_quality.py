"""Issue 28's acceptance on the ``leftbehind`` scenario, seeds 0-2, both variants.

A robot patrolling a room leaves objects behind (seen, out of view about a minute,
seen again). With sensor poses (each scan's pose and heading passed as its sensor
view, :func:`semwm.sim.leftbehind.with_sensor_views`): (a) every object out of view
stays in the published world while present, (b) every object removed in view leaves
it within 2 s of its next missed view. Without poses: (c) every object the fixed
camera ``cam2`` never saw stays while present. Knowledge:
``benchmarks/knowledge/leftbehind.yaml`` (datasheets and floor plan only).

Before issue 28's model change an object left the world about 1 s after it left the
robot's view. After it, (b) passes, and (a) and (c) hold in nearly every frame (see
the test).
"""

from __future__ import annotations

from pathlib import Path

import pytest

from semwm import load_knowledge
from semwm.sim.leftbehind import acceptance, with_sensor_views
from semwm.sim.runner import run_scenario
from semwm.sim.scenarios import make_scenario

KNOWLEDGE = Path(__file__).resolve().parents[2] / "benchmarks" / "knowledge" / "leftbehind.yaml"


def _run(seed: int, poses: bool):  # type: ignore[no-untyped-def]
    scenario = make_scenario("leftbehind", seed, poses=poses)
    factory = with_sensor_views(scenario) if poses else None
    result = run_scenario(
        scenario, load_knowledge(KNOWLEDGE), progress=False, world_model_factory=factory
    )
    return scenario, result


@pytest.mark.parametrize("poses", [True, False], ids=["poses", "no_poses"])
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_leftbehind_keeps_what_it_cannot_see_in_nearly_every_frame(seed: int, poses: bool) -> None:
    """What today's model achieves, held: with poses every object removed in view leaves
    within 2 s of its next missed view (b), and objects out of view are published in at
    least 99.5 % of their frames (a); without poses, objects the fixed camera never saw
    in at least 99.5 % (c). Before issue 28's change (a) and (c) failed on every object.

    Not yet met: the acceptance's "every frame". An object that a view misses three
    scans running (recall 0.8) drops below min_existence for 1-3 frames (bench_quality,
    20 seeds: (a) 30 of 214 objects, 1.2 % of their frames; (c) 5 of 167, 5 frames)."""
    scenario, result = _run(seed, poses)
    checks = {c.name[:3]: c for c in acceptance(scenario, result.worlds)}
    for name, check in checks.items():
        assert check.objects_asked > 0, name
        if name == "(b)":
            assert check.passed, check.detail()
        else:
            assert check.frames_failed <= 0.005 * check.frames_asked, check.detail()
