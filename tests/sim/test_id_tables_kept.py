"""Id tables a query cached are never changed under it: ``WorldModel._tables()`` gives
the live tables, and publishing makes new ones instead of changing those in place
(a query's tentative chain and the reorder log's saved tables hold them)."""

from __future__ import annotations

from typing import Any

import pytest

from semwm.filters.engine import Engine
from semwm.knowledge.loader import load_knowledge
from semwm.knowledge.shipped import shipped_knowledge_path
from semwm.sim.runner import scans
from semwm.sim.scenarios import make_scenario
from semwm.world import WorldModel

CASES = [
    ("door_exits", {"duration": 40.0}),  # people leave: ids wait, come back, are handed over
    ("sim2", {}),  # a person leaves by the door, another comes in
]


@pytest.mark.parametrize(("name", "sizes"), CASES, ids=[c[0] for c in CASES])
def test_publishing_never_changes_tables_it_gave_out(
    name: str, sizes: dict[str, Any], engine: Engine
) -> None:
    scenario = make_scenario(name, 0, **sizes)
    model = WorldModel(
        load_knowledge(shipped_knowledge_path(scenario.knowledge_file)),
        reorder_window=0.5,
        engine=engine,
    )
    general = model._publish_changed
    calls: list[int] = []

    def counted(current: Any) -> None:
        calls.append(1)
        general(current)

    model._publish_changed = counted  # type: ignore[method-assign]
    for scan in scans(scenario.detections):
        ids, next_id, published, lost = model._tables()
        before = (dict(ids), dict(published), dict(lost))
        model.ingest(scan)
        assert (dict(ids), dict(published), dict(lost)) == before
    # the general path ran: an object left, an id was handed over or stopped waiting
    assert len(calls) >= 2
