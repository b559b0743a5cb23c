"""The shortcut for a detection that certainly updates one object
(:meth:`MultipleHypothesisFilter._certain_update`) gives exactly what the general
expansion gives: the same worlds, frame by frame, with the shortcut on and off."""

from __future__ import annotations

import pytest

from semwm.knowledge.loader import load_knowledge
from semwm.knowledge.shipped import shipped_knowledge_path
from semwm.mhf.association import Associator
from semwm.mhf.filter import MultipleHypothesisFilter
from semwm.world import WorldModel

from .worlds import scenario_worlds as _worlds


@pytest.fixture(autouse=True)
def _python_engine(monkeypatch: pytest.MonkeyPatch) -> None:
    """These tests patch the Python engine's methods, so they run the Python engine
    whatever ``SEMWM_ENGINE`` says; the Rust engine's expansion (core/src/expansion.rs)
    takes the same shortcut and is held to the Python engine by tests/engines/."""
    monkeypatch.setenv("SEMWM_ENGINE", "python")


@pytest.mark.parametrize(
    ("name", "seed", "sizes"),
    [("sim1", 5, {}), ("robocup", 9, {"duration": 1.0}), ("grid", 0, {"duration": 1.0})],
)
def test_the_shortcut_changes_no_world(
    monkeypatch: pytest.MonkeyPatch, name: str, seed: int, sizes: dict[str, float]
) -> None:
    taken = []
    shortcut = MultipleHypothesisFilter._certain_update

    def counted(self: MultipleHypothesisFilter, *args: object) -> object:
        result = shortcut(self, *args)  # type: ignore[arg-type]
        taken.append(result is not None)
        return result

    monkeypatch.setattr(MultipleHypothesisFilter, "_certain_update", counted)
    # detection by detection: no scan's certain updates settled at once (tested below)
    monkeypatch.setattr(MultipleHypothesisFilter, "_settleable", lambda *a: None)
    with_shortcut = _worlds(name, seed, **sizes)
    assert any(taken)  # the case is common: it was taken
    monkeypatch.setattr(MultipleHypothesisFilter, "_certain_update", lambda *a: None)
    assert _worlds(name, seed, **sizes) == with_shortcut


@pytest.mark.parametrize(
    ("name", "seed", "sizes"),
    [("grid", 3, {"duration": 1.0}), ("sim1", 2, {}), ("sim1", 7, {})],
)
def test_settling_a_scans_certain_updates_at_once_changes_no_world(
    monkeypatch: pytest.MonkeyPatch, name: str, seed: int, sizes: dict[str, float]
) -> None:
    """Detections the associator settles (:class:`SettledUpdate`: no options built) give
    the worlds the detection-by-detection path gives, frame by frame."""
    settled = []
    original = Associator._settled

    def counted(self: Associator, *args: object) -> object:
        result = original(self, *args)  # type: ignore[arg-type]
        settled.append(len(result))
        return result

    monkeypatch.setattr(Associator, "_settled", counted)
    with_settling = _worlds(name, seed, **sizes)
    assert sum(settled) > 0  # it was taken
    monkeypatch.setattr(MultipleHypothesisFilter, "_settleable", lambda *a: None)
    assert _worlds(name, seed, **sizes) == with_settling


def _two_cups_world(settling: bool, monkeypatch: pytest.MonkeyPatch) -> list[list[object]]:
    """Two cups seen alone for a while, then scans where two detections fall near one
    cup (the second is a near duplicate), and scans where each cup has one."""
    if not settling:
        monkeypatch.setattr(MultipleHypothesisFilter, "_settleable", lambda *a: None)
    world = WorldModel(load_knowledge(shipped_knowledge_path("sim1.yaml")), engine="python")
    frames: list[list[object]] = []
    for k in range(30):
        t = 0.1 * k
        scan = [
            {"time": t, "class": "Cup", "position": [1.0 + 0.004 * (k % 3), 1.0]},
            {"time": t, "class": "Cup", "position": [3.0, 1.0 - 0.003 * (k % 2)]},
        ]
        if k % 5 == 4:  # a second detection close to the first cup
            scan.append({"time": t, "class": "Cup", "position": [1.03, 1.02]})
        world.ingest(scan)
        frames.append(
            [(o.id, o.cls, tuple(o.position), o.existence) for o in world.world().objects]
        )
    monkeypatch.undo()
    return frames


def test_an_object_two_detections_gate_is_not_settled(monkeypatch: pytest.MonkeyPatch) -> None:
    settled = []
    original = Associator._settled

    def counted(self: Associator, *args: object) -> dict[int, object]:
        result = original(self, *args)  # type: ignore[arg-type]
        settled.append(len(result))
        return result  # type: ignore[return-value]

    monkeypatch.setattr(Associator, "_settled", counted)
    with_settling = _two_cups_world(True, monkeypatch)
    assert 1 in settled  # in the scans with a duplicate only the second cup settles
    assert _two_cups_world(False, monkeypatch) == with_settling
