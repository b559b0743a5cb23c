"""Values made per scan or per object of a query without their frozen dataclass's
constructor (``semwm.world_types.made_without_init``): the Rust engine's path for a
batch read as one scan makes its ``IngestResult`` so, and every query its
``WorldObject``s. Each must be the value the constructor makes, as frozen."""

from __future__ import annotations

import dataclasses
from typing import Any

import pytest

from semwm.confidence import Confidence, ConfidenceBook
from semwm.filters.engine import rust_core
from semwm.knowledge.loader import load_knowledge
from semwm.knowledge.shipped import shipped_knowledge_path
from semwm.mhf.core_engine import CoreBook, CoreState, as_python_book
from semwm.world import IngestResult, WorldModel, _Asked
from semwm.world_types import WorldObject, WorldState


def _batches() -> list[list[dict[str, Any]]]:
    """Scans of the room: two inside the region, one with a detection far outside it
    (ignored, with its reason), one of two detections."""
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

    monkeypatch.setattr(fast, "_ingest", general_path)  # the first scan too
    ignored_somewhere = False
    for batch in _batches():
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


@pytest.mark.parametrize("engine", ["rust", "python"])
def test_world_objects_are_the_constructors_values(engine: str) -> None:
    model = WorldModel(load_knowledge(shipped_knowledge_path("sim2.yaml")), engine=engine)
    for batch in _batches():
        model.ingest(batch)
    names = {field.name for field in dataclasses.fields(WorldObject)}
    seen = 0
    for min_existence in (None, 1e-6):  # published objects, and tentative ones
        for got in model.world(time=0.4, min_existence=min_existence).objects:
            assert set(vars(got)) == names
            expected = WorldObject(**{name: getattr(got, name) for name in names})
            assert got == expected
            assert repr(got) == repr(expected)
            assert got.to_dict() == expected.to_dict()
            with pytest.raises(dataclasses.FrozenInstanceError):
                got.existence = 0.0  # type: ignore[misc]
            confidence = got.confidence
            assert confidence is not None and type(confidence) is Confidence
            made = Confidence(confidence.value, confidence.state)
            assert confidence == made and repr(confidence) == repr(made)
            assert hash(confidence) == hash(made)
            with pytest.raises(dataclasses.FrozenInstanceError):
                confidence.value = 0.0  # type: ignore[misc]
            seen += 1
    assert seen >= 2


@pytest.mark.parametrize("engine", ["rust", "python"])
def test_a_world_state_is_the_constructors_value(engine: str) -> None:
    model = WorldModel(load_knowledge(shipped_knowledge_path("sim2.yaml")), engine=engine)
    for batch in _batches():
        model.ingest(batch)
    got = model.world(time=0.4)
    assert type(got) is WorldState and got.objects
    expected = WorldState(time=got.time, objects=got.objects)
    assert got == expected and repr(got) == repr(expected)
    assert set(vars(got)) == {field.name for field in dataclasses.fields(WorldState)}
    with pytest.raises(dataclasses.FrozenInstanceError):
        got.time = 0.0  # type: ignore[misc]


def test_a_query_of_the_rust_engine_makes_no_track() -> None:
    """``Engine.world_at``'s rows carry what a query shows of each version: the world
    is read without a ``Track`` (numpy arrays) of each version."""
    model = WorldModel(load_knowledge(shipped_knowledge_path("sim2.yaml")), engine="rust")
    for batch in _batches():
        model.ingest(batch)
    core = model._mhf._core
    assert core is not None
    made = dict(core._made.tracks)
    objects = model.world(time=0.5, min_existence=1e-6).objects
    assert objects and core._made.tracks == made


@pytest.mark.skipif(rust_core() is None, reason="the Rust core is not built")
def test_a_query_reads_the_confidences_of_a_book_the_core_does_not_hold() -> None:
    """The core carries each object's confidence to the query's time when it holds the
    book (``Engine.world_at``); from the specification's book the query reads it in
    Python (``BookView.at``): the same objects either way."""
    model = WorldModel(load_knowledge(shipped_knowledge_path("sim2.yaml")), engine="rust")
    for batch in _batches():
        model.ingest(batch)
    core = model._mhf._core
    state, book = model._state, model._book
    assert core is not None and type(state) is CoreState and type(book) is CoreBook
    asked = _Asked(1e-6, None, None, None, None)
    held = model._core_objects(core.engine, state, book, 0.9, asked)
    read = model._core_objects(core.engine, state, as_python_book(book), 0.9, asked)
    assert type(as_python_book(book)) is ConfidenceBook
    assert len(held) >= 2 and read == held
    values = [obj.confidence.value for obj in held if obj.confidence is not None]
    assert len(values) == len(held) and min(values) < 1.0  # carried: decayed since seen
