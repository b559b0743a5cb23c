"""``WorldModel._publish`` takes a shortcut when no published object left and no id
waits for its object (``_publish_unchanged``; with the Rust engine, the core's
``Engine.publish``): it must publish what the general path (``_publish_changed``)
publishes, frame by frame (ids, tables and the next id)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from semwm.filters.engine import Engine
from semwm.knowledge.loader import load_knowledge
from semwm.knowledge.model import Knowledge
from semwm.knowledge.shipped import shipped_knowledge_path
from semwm.sim.runner import scans
from semwm.sim.scenarios import make_scenario
from semwm.world import WorldModel

BENCHMARK_KNOWLEDGE = Path(__file__).resolve().parents[2] / "benchmarks" / "knowledge"

CASES = [
    ("robocup", {"duration": 3.0}),  # robots entering, labels, ids handed over
    ("door_exits", {"duration": 30.0}),  # people leaving: lost ids waiting
    ("sim1", {}),
    ("datasheet", {"duration": 30.0}),  # people in and out of view, learnt coverage
]


def _knowledge(name: str) -> Knowledge:
    """A shipped knowledge file, or a benchmark's (datasheet)."""
    if (BENCHMARK_KNOWLEDGE / name).is_file():
        return load_knowledge(BENCHMARK_KNOWLEDGE / name)
    return load_knowledge(shipped_knowledge_path(name))


def _general_path_only(model: WorldModel) -> None:
    """``model`` publishes by the general path every time."""
    model._publish_unchanged = model._publish_changed  # type: ignore[method-assign]
    core = model._mhf._core
    if core is not None:  # the core's shortcut: never taken
        core.publish = lambda state, published, ids, lost, next_id: (  # type: ignore[method-assign]
            core.current(state, published, ids),
            None,
        )


def _frames(
    name: str, sizes: dict[str, Any], seed: int, shortcut: bool, engine: Engine
) -> list[Any]:
    scenario = make_scenario(name, seed, **sizes)
    model = WorldModel(_knowledge(scenario.knowledge_file), reorder_window=0.5, engine=engine)
    if not shortcut:
        _general_path_only(model)
    frames = []
    for scan in scans(scenario.detections):
        model.ingest(scan)
        frames.append(
            (
                [(o.id, o.cls, o.label, o.position) for o in model.world().objects],
                dict(model._ids),
                sorted(model._published),
                model._next_id,
            )
        )
    return frames


@pytest.mark.parametrize(("name", "sizes"), CASES, ids=[c[0] for c in CASES])
@pytest.mark.parametrize("seed", [0, 1])
def test_the_shortcut_publishes_what_the_general_path_does(
    name: str, sizes: dict[str, Any], seed: int, engine: Engine
) -> None:
    assert _frames(name, sizes, seed, True, engine) == _frames(name, sizes, seed, False, engine)
