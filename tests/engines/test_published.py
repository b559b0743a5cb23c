"""The Rust engine's published world (``semwm._core.Published``,
``core/src/python/published.rs``): the table ``WorldModel._published`` holds after a
common scan, whose ``VersionRef`` values are made only when read. It must read as the
dict the specification's publishing makes, and pickle as one."""

from __future__ import annotations

import pickle

import pytest

from semwm.filters.engine import rust_core
from semwm.knowledge.loader import load_knowledge
from semwm.knowledge.shipped import shipped_knowledge_path
from semwm.mhf.core_engine import track_of
from semwm.mhf.state import Track
from semwm.sim.runner import scans
from semwm.sim.scenarios import make_scenario
from semwm.world import WorldModel

from . import needs_rust

pytestmark = needs_rust


def _is_table(published: object) -> bool:
    core = rust_core()
    return core is not None and isinstance(published, core.Published)


def _models(scenario: str, upto: int) -> tuple[WorldModel, WorldModel]:
    """The scenario's first ``upto`` scans, ingested by each engine."""
    sc = make_scenario(scenario, 0)
    knowledge = load_knowledge(shipped_knowledge_path(sc.knowledge_file))
    rust, python = WorldModel(knowledge, engine="rust"), WorldModel(knowledge, engine="python")
    for frame in list(scans(sc.detections))[:upto]:
        rust.ingest(frame)
        python.ingest(frame)
    return rust, python


@pytest.mark.parametrize("upto", [3, 40, 120])
def test_reads_as_the_specifications_table(upto: int) -> None:
    rust, python = _models("sim2", upto)
    table, expected = rust._published, python._published
    assert isinstance(expected, dict)
    assert len(table) == len(expected) > 0
    assert list(table) == list(expected)  # ids, in the published world's order
    assert list(table.keys()) == list(expected.keys())
    for object_id, version in table.items():
        assert object_id in table
        assert table[object_id] is version  # made once
        assert table.get(object_id) is version
        want = expected[object_id]
        assert (version.lineage, version.cls) == (want.lineage, want.cls)
        assert track_of(version).key == want.key
    assert [v.lineage for v in table.values()] == [t.lineage for t in expected.values()]
    missing = max(table) + 1000
    assert missing not in table and "1" not in table
    assert table.get(missing) is None and table.get(missing, "x") == "x"
    with pytest.raises(KeyError):
        table[missing]
    assert table == dict(table.items())


def test_the_common_scan_publishes_a_table_whose_values_wait() -> None:
    rust, _ = _models("sim2", 60)
    table = rust._published
    assert _is_table(table)
    lineages = table.lineages()  # read without making the values
    assert lineages == [v.lineage for v in table.values()]
    assert set(lineages) == {lineage for lineage, i in rust._ids.items() if i in table}


def test_pickles_as_a_dict_of_tracks() -> None:
    rust, _ = _models("sim2", 60)
    table = rust._published
    assert _is_table(table)
    copied = pickle.loads(pickle.dumps(table))
    assert type(copied) is dict
    assert list(copied) == list(table)
    for object_id, track in copied.items():
        assert isinstance(track, Track)
        want = track_of(table[object_id])
        assert (track.key, track.lineage, track.cls) == (want.key, want.lineage, want.cls)
        assert (track.x == want.x).all()
