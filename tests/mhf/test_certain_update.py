"""The shortcut for a detection that certainly updates one object
(:meth:`MultipleHypothesisFilter._certain_update`) gives exactly what the general
expansion gives: the same worlds, frame by frame, with the shortcut on and off."""

from __future__ import annotations

import pytest

from semwm.mhf.filter import MultipleHypothesisFilter

from .worlds import scenario_worlds as _worlds


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
