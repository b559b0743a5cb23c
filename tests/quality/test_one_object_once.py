"""The published world shows each physical object once (semwm.world._same_objects).

People who pass close by one another can leave the hypotheses disagreeing about
which lineage is whom. When the most probable hypothesis has one of them leaving
through the door, that lineage used to be shown in another hypothesis's version,
which is the very person the best hypothesis calls by another lineage: two objects,
two ids, on one spot (door_exits: 26 frames over 10 of 20 seeds before the fix).
"""

from __future__ import annotations

import numpy as np
import pytest

from semwm.knowledge.loader import load_knowledge
from semwm.knowledge.shipped import shipped_knowledge_path
from semwm.sim.runner import run_scenario
from semwm.sim.scenarios import make_scenario


@pytest.mark.parametrize("seed", [6, 12])
def test_people_who_swapped_lineages_are_not_shown_twice(seed: int) -> None:
    scenario = make_scenario("door_exits", seed, duration=45.0)
    knowledge = load_knowledge(shipped_knowledge_path(scenario.knowledge_file))
    result = run_scenario(scenario, knowledge, progress=False)
    twice = []
    for world in result.worlds:
        positions = np.array([o.position[:2] for o in world.objects]).reshape(-1, 2)
        gaps = np.linalg.norm(positions[:, None] - positions[None, :], axis=-1)
        close = np.argwhere(np.triu(gaps < 0.02, 1))
        twice += [(world.time, world.objects[a].id, world.objects[b].id) for a, b in close]
    assert twice == []  # (time, id, id) of objects shown on one spot
    # was 30 and 15, then 28 and 13; issue 28's missed-detection model gives 32 and 12
    # (door_exits over 20 seeds: 268 switches against 258, GOSPA 0.2578 against 0.2581)
    assert result.metrics.id_switches <= {6: 32, 12: 13}[seed]
