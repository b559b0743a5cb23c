"""A world model restored from a snapshot goes on as the one it was taken of: the same
worlds, scan by scan, through objects leaving the published world, their ids waiting
(the Rust engine's published versions name core states, which live in one process only:
they are pickled as their tracks)."""

from __future__ import annotations

from typing import Any

import pytest

from semwm.knowledge.loader import load_knowledge
from semwm.knowledge.shipped import shipped_knowledge_path
from semwm.persistence.snapshot import restore_snapshot, take_snapshot
from semwm.sim.runner import scans
from semwm.sim.scenarios import make_scenario
from semwm.world import WorldModel

CASES = [
    ("door_exits", {"duration": 40.0}),  # people leave: ids wait, may come back
    ("sim2", {}),  # a person leaves by the door, another comes in
]


def _world(model: WorldModel) -> list[Any]:
    return [
        (o.id, o.cls, o.label, round(o.existence, 12), [round(v, 9) for v in o.position])
        for o in model.world().objects
    ]


@pytest.mark.parametrize(("name", "sizes"), CASES, ids=[c[0] for c in CASES])
def test_a_restored_model_goes_on_as_the_original(name: str, sizes: dict[str, Any]) -> None:
    scenario = make_scenario(name, 0, **sizes)
    knowledge = load_knowledge(shipped_knowledge_path(scenario.knowledge_file))
    frames = list(scans(scenario.detections))
    probe = WorldModel(knowledge, reorder_window=0.5)
    lost_at = []  # the scans after which an id waits for its object
    for index, scan in enumerate(frames):
        probe.ingest(scan)
        if probe._lost:
            lost_at.append(index)
    assert lost_at  # the case holds objects that left the published world
    # snapshots just before an object leaves, and while its id waits
    for cut in (lost_at[0] - 1, lost_at[0], lost_at[len(lost_at) // 2]):
        original = WorldModel(knowledge, reorder_window=0.5)
        for scan in frames[: cut + 1]:
            original.ingest(scan)
        restored = restore_snapshot(take_snapshot(original, cut))
        assert restored.engine == original.engine
        for scan in frames[cut + 1 :]:
            original.ingest(scan)
            restored.ingest(scan)
            assert _world(restored) == _world(original)
