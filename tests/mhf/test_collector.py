"""The cyclic garbage collector is paused while a batch is processed and resumed after,
as it was, however pauses overlap; not for a small batch the Rust engine takes in one
call (``WorldModel._ingest_scan``), which makes too few Python objects for it to pay.
A query's answer of many objects is made with it paused too."""

from __future__ import annotations

import gc
import threading
from collections.abc import Iterator

import pytest

from semwm.collector import collector_paused
from semwm.detection import DetectionError
from semwm.filters.engine import ENGINES, rust_core
from semwm.knowledge.loader import load_knowledge
from semwm.knowledge.shipped import shipped_knowledge_path
from semwm.world import WorldModel


@pytest.fixture(autouse=True)
def _collector_enabled() -> Iterator[None]:
    gc.enable()
    yield
    gc.enable()


def test_paused_within_and_resumed_after() -> None:
    with collector_paused():
        assert not gc.isenabled()
    assert gc.isenabled()


def test_overlapping_pauses_resume_when_the_last_one_ends() -> None:
    first_in, second_in, first_out = threading.Event(), threading.Event(), threading.Event()
    seen: list[bool] = []

    def first() -> None:
        with collector_paused():
            first_in.set()
            second_in.wait(5)
        first_out.set()

    thread = threading.Thread(target=first)
    thread.start()
    first_in.wait(5)
    with collector_paused():
        second_in.set()
        first_out.wait(5)
        seen.append(gc.isenabled())  # the first pause ended, this one has not
    thread.join(5)
    assert seen == [False]
    assert gc.isenabled()


def test_a_collector_disabled_before_stays_disabled() -> None:
    gc.disable()
    with collector_paused():
        pass
    assert not gc.isenabled()


def test_ingest_processes_with_the_collector_paused_even_when_it_refuses() -> None:
    # the Python engine: every batch takes the general path (_process_scans)
    model = WorldModel(load_knowledge(shipped_knowledge_path("sim1.yaml")), engine="python")
    during: list[bool] = []
    process = model._process_scans

    def watched(*args: object, **kwargs: object) -> object:
        during.append(gc.isenabled())
        return process(*args, **kwargs)  # type: ignore[arg-type]

    model._process_scans = watched  # type: ignore[method-assign]
    model.ingest([{"time": 1.0, "class": "Cup", "position": [1.0, 1.0]}])
    assert during == [False] and gc.isenabled()
    with pytest.raises(DetectionError):
        model.ingest([{"time": 2.0, "class": "Nope", "position": [1.0, 1.0]}])
    assert gc.isenabled()


@pytest.mark.skipif(rust_core() is None, reason="the Rust core is not built")
def test_a_scan_in_one_call_pauses_the_collector_only_when_large() -> None:
    model = WorldModel(load_knowledge(shipped_knowledge_path("sim1.yaml")), engine="rust")
    during: list[bool] = []
    one_call = model._ingest_scan

    def watched(*args: object) -> object:
        enabled = gc.isenabled()
        done = one_call(*args)  # type: ignore[arg-type]
        if done is not None:  # taken in one call
            during.append(enabled)
        return done

    model._ingest_scan = watched  # type: ignore[method-assign]

    def scan(time: float, size: int) -> list[dict[str, object]]:
        return [
            {"time": time, "class": "Cup", "position": [0.1 + 0.1 * i, 1.0]} for i in range(size)
        ]

    model.ingest(scan(1.0, 2))  # the first scan too: the model starts in the core
    model.ingest(scan(2.0, 2))
    model.ingest(scan(3.0, 80))
    assert during == [True, True, False] and gc.isenabled()


@pytest.mark.parametrize("engine", ENGINES)
def test_a_large_worlds_objects_are_made_with_the_collector_paused(
    engine: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    """``world()`` makes each object's Python values (several objects each, none in a
    cycle) with the collector paused when it answers more than 64 objects, and not for
    a small world, where the pause would cost more than it saves; it is resumed after,
    also when the query refuses. Each object and its confidence are made by
    ``made_without_init``, watched here."""
    if engine == "rust" and rust_core() is None:
        pytest.skip("the Rust core is not built")
    import semwm.world as world_module

    model = WorldModel(load_knowledge(shipped_knowledge_path("sim1.yaml")), engine=engine)
    during: list[bool] = []
    make = world_module.made_without_init

    def watched(*args: object, **kwargs: object) -> object:
        during.append(gc.isenabled())
        if failing and len(during) == 5:
            raise RuntimeError("planted")
        return make(*args, **kwargs)  # type: ignore[arg-type]

    failing = False
    monkeypatch.setattr(world_module, "made_without_init", watched)
    cups = [{"class": "Cup", "position": [0.3 * (i % 10), 0.3 * (i // 10)]} for i in range(80)]
    model.ingest([{**cup, "time": 1.0} for cup in cups[:3]])
    during.clear()  # the batch's result
    assert len(model.world(min_existence=1e-6).objects) == 3
    # each object and its confidence, and the answer
    assert during == [True] * (2 * 3 + 1) and gc.isenabled()
    model.ingest([{**cup, "time": 2.0} for cup in cups])
    during.clear()
    answered = model.world(min_existence=1e-6).objects
    assert len(answered) > 64 and during[:-1] == [False] * (2 * len(answered))
    assert gc.isenabled()
    during.clear()
    failing = True
    with pytest.raises(RuntimeError, match="planted"):
        model.world(min_existence=1e-6)
    assert during == [False] * 5 and gc.isenabled()


@pytest.mark.skipif(rust_core() is None, reason="the Rust core is not built")
def test_the_cores_rows_of_a_large_world_are_made_with_the_collector_paused() -> None:
    """The Rust engine's ``Engine.world_at`` answers a row of Python values per object
    (several containers each): for a world of more than 64 versions it runs with the
    collector paused too, and not for a small one."""
    model = WorldModel(load_knowledge(shipped_knowledge_path("sim1.yaml")), engine="rust")
    core = model._mhf._core
    assert core is not None
    during: list[bool] = []

    class Watched:
        def __init__(self, engine: object) -> None:
            self.engine = engine

        def world_at(self, *args: object) -> object:
            during.append(gc.isenabled())
            return self.engine.world_at(*args)  # type: ignore[attr-defined]

        def __getattr__(self, name: str) -> object:
            return getattr(self.engine, name)

    core.engine = Watched(core.engine)  # type: ignore[assignment]
    cups = [{"class": "Cup", "position": [0.3 * (i % 10), 0.3 * (i // 10)]} for i in range(80)]
    model.ingest([{**cup, "time": 1.0} for cup in cups[:3]])
    assert len(model.world(min_existence=1e-6).objects) == 3
    assert during == [True] and gc.isenabled()
    model.ingest([{**cup, "time": 2.0} for cup in cups])
    assert len(model.world(min_existence=1e-6).objects) > 64
    assert during == [True, False] and gc.isenabled()
