"""The Rust engine's path for a batch read as one scan (``WorldModel._ingest_scan``)
makes its ``IngestResult`` without the frozen dataclass's constructor
(``_ingest_result``): it must give the value the general path gives, as frozen."""

from __future__ import annotations

import dataclasses
from typing import Any

import pytest

from semwm.knowledge.loader import load_knowledge
from semwm.knowledge.shipped import shipped_knowledge_path
from semwm.world import IngestResult, WorldModel


def _batches() -> list[list[dict[str, Any]]]:
    """Scans of the room: a first (which the general path takes: the state is not yet
    the core's), one inside the region, one with a detection far outside it (ignored,
    with its reason), one of two detections."""
    person = {"class": "Person", "source": "cam"}
    return [
        [{**person, "time": 0.0, "position": [5.0, 4.0]}],
        [{**person, "time": 0.1, "position": [5.0, 4.0]}],
        [
            {**person, "time": 0.2, "position": [5.02, 4.01]},
            {**person, "time": 0.2, "position": [500.0, 400.0]},
        ],
        [
            {**person, "time": 0.3, "position": [5.03, 4.0]},
            {**person, "time": 0.3, "position": [2.0, 1.0]},
        ],
    ]


def test_the_scans_path_gives_the_general_paths_result(monkeypatch: pytest.MonkeyPatch) -> None:
    knowledge = load_knowledge(shipped_knowledge_path("sim2.yaml"))
    general = WorldModel(knowledge, engine="python")
    fast = WorldModel(knowledge, engine="rust")

    def general_path(*args: object) -> None:
        raise AssertionError("the batch took the general path")

    first, *batches = _batches()
    assert fast.ingest(first) == general.ingest(first)
    monkeypatch.setattr(fast, "_ingest", general_path)
    ignored_somewhere = False
    for batch in batches:
        expected, got = general.ingest(batch), fast.ingest(batch)
        assert type(got) is IngestResult
        assert got == expected
        assert repr(got) == repr(expected)
        assert dataclasses.asdict(got) == dataclasses.asdict(expected)
        assert hash(got) == hash(expected)
        assert got.ignored == len(got.ignored_detections)
        ignored_somewhere |= got.ignored > 0
        with pytest.raises(dataclasses.FrozenInstanceError):
            got.applied = 0  # type: ignore[misc]
    assert ignored_somewhere
