"""The shortcut for a detection that certainly updates one object
(:meth:`MultipleHypothesisFilter._certain_update`) gives exactly what the general
expansion gives: the same worlds, frame by frame, with the shortcut on and off."""

from __future__ import annotations

import pytest

from semwm.knowledge.loader import load_knowledge
from semwm.knowledge.shipped import shipped_knowledge_path
from semwm.mhf.filter import MultipleHypothesisFilter
from semwm.sim.runner import run_scenario
from semwm.sim.scenarios import make_scenario


def _worlds(name: str, seed: int, **sizes: float) -> list[list[tuple[object, ...]]]:
    scenario = make_scenario(name, seed, **sizes)
    knowledge = load_knowledge(shipped_knowledge_path(scenario.knowledge_file))
    result = run_scenario(scenario, knowledge, progress=False)
    return [
        [(o.id, o.cls, tuple(o.position), o.existence, o.label) for o in world.objects]
        for world in result.worlds
    ]


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
    with_shortcut = _worlds(name, seed, **sizes)
    assert any(taken)  # the case is common: it was taken
    monkeypatch.setattr(MultipleHypothesisFilter, "_certain_update", lambda *a: None)
    assert _worlds(name, seed, **sizes) == with_shortcut
