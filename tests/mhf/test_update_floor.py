"""Update children under eq. (3)'s floor are not built (``_update_floor``): the same
hypotheses, weights and objects as when every child is built and then pruned."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from semwm.mhf.filter import MultipleHypothesisFilter
from semwm.world import WorldModel

from .kb import knowledge, static_class

REGION = ((-1.0, 4.0), (-1.0, 4.0))


@pytest.fixture(autouse=True)
def _python_engine(monkeypatch: pytest.MonkeyPatch) -> None:
    """These tests patch the Python engine's methods, so they run the Python engine
    whatever ``SEMWM_ENGINE`` says; the Rust engine's expansion (core/src/expansion.rs)
    takes the same shortcut and is held to the Python engine by tests/engines/."""
    monkeypatch.setenv("SEMWM_ENGINE", "python")


def _classes() -> list:
    return [
        static_class("Can", f_existing=2.0, f_new=0.3, r=0.04),
        static_class("CokeCan", is_a=["Can"], f_existing=2.0, f_new=0.2, r=0.04),
        static_class("Cup", f_existing=2.0, f_new=0.3, r=0.04),
    ]


def _scans(seed: int) -> list[list[dict[str, Any]]]:
    """Detections around four objects close together, with clutter: many hypotheses."""
    rng = np.random.default_rng(seed)
    objects = rng.uniform(0.5, 2.5, (4, 2))
    scans = []
    for k in range(20):
        t = 0.25 * k
        scan = [
            {
                "time": t,
                "class": str(rng.choice(["Can", "CokeCan", "Cup"])),
                "position": list(p + rng.normal(0.0, 0.2, 2)),
            }
            for p in objects
            if rng.random() < 0.8
        ]
        for _ in range(rng.poisson(1.0)):
            scan.append({"time": t, "class": "Cup", "position": list(rng.uniform(-0.5, 3.5, 2))})
        if scan:
            scans.append(scan)
    return scans


def _run(seed: int, ratio: float, max_h: int, skip: bool, monkeypatch: pytest.MonkeyPatch):
    kb = knowledge(
        _classes(), model="mht", ratio=ratio, max_hypotheses=max_h, region=REGION, f_clutter=2.0
    )
    with monkeypatch.context() as patch:
        if not skip:
            patch.setattr(MultipleHypothesisFilter, "_update_floor", lambda *_: float("-inf"))
        wm = WorldModel(kb, reorder_window=0.0)
        for scan in _scans(seed):
            wm.ingest(scan)
        state = wm._state
        return (
            [[(h.log_weight, h.tracks) for h in c.hypotheses] for c in state.clusters],
            sorted(state.tracks),
            wm.world(),
        )


@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize(("ratio", "max_h"), [(0.01, 100), (0.2, 5), (0.001, 300)])
def test_skipping_children_under_the_floor_changes_nothing(
    seed: int, ratio: float, max_h: int, monkeypatch: pytest.MonkeyPatch
) -> None:
    skipped = _run(seed, ratio, max_h, True, monkeypatch)
    built = _run(seed, ratio, max_h, False, monkeypatch)
    assert skipped == built  # bit for bit: weights, object versions, keys, the world


def test_the_floor_skips_children_here(monkeypatch: pytest.MonkeyPatch) -> None:
    """The scans above do reach the skip (else the test above would prove nothing)."""
    floors: list[float] = []
    original = MultipleHypothesisFilter._update_floor

    def spy(self: MultipleHypothesisFilter, *args: Any) -> float:
        floors.append(original(self, *args))
        return floors[-1]

    monkeypatch.setattr(MultipleHypothesisFilter, "_update_floor", spy)
    kb = knowledge(_classes(), model="mht", ratio=0.01, max_hypotheses=100, region=REGION)
    wm = WorldModel(kb, reorder_window=0.0)
    for scan in _scans(0):
        wm.ingest(scan)
    assert any(f > float("-inf") for f in floors)
