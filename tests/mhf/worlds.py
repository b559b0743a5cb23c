"""A scenario's published worlds, frame by frame, for tests that hold two ways of
computing them to the same result."""

from __future__ import annotations

from semwm.knowledge.loader import load_knowledge
from semwm.knowledge.shipped import shipped_knowledge_path
from semwm.sim.runner import run_scenario
from semwm.sim.scenarios import make_scenario


def scenario_worlds(name: str, seed: int, **sizes: float) -> list[list[tuple[object, ...]]]:
    """Each frame's objects (id, class, position, existence, label) of ``name``'s run."""
    scenario = make_scenario(name, seed, **sizes)
    knowledge = load_knowledge(shipped_knowledge_path(scenario.knowledge_file))
    result = run_scenario(scenario, knowledge, progress=False)
    return [
        [(o.id, o.cls, tuple(o.position), o.existence, o.label) for o in world.objects]
        for world in result.worlds
    ]
