"""The reorder history is bounded in count as well as in time (issue 13: memory)."""

from __future__ import annotations

import pytest

from semwm import load_knowledge
from semwm.detection import OutOfOrderError
from semwm.knowledge.shipped import shipped_knowledge_path
from semwm.world import WorldModel

TIMES = [round(0.1 * k, 1) for k in range(1, 21)]  # 20 scans, 0.1 s apart


def _world(max_scans: int) -> WorldModel:
    wm = WorldModel(
        load_knowledge(shipped_knowledge_path("sim1.yaml")),
        reorder_window=10.0,  # the time window alone would keep every scan
    )
    wm.max_reorder_scans = max_scans
    return wm


def _cup(t: float, source: str = "cam") -> dict[str, object]:
    return {"time": t, "class": "Cup", "position": [1.0 + 0.01 * t, 1.0], "source": source}


def _summary(wm: WorldModel) -> list[tuple[int, str, tuple[float, ...]]]:
    return [(o.id, o.cls, tuple(o.position)) for o in wm.world().objects]


def test_a_late_scan_before_the_forgotten_history_is_refused_and_changes_nothing() -> None:
    wm = _world(max_scans=5)
    for t in TIMES:
        wm.ingest(_cup(t))
    before = (_summary(wm), wm.world().time)
    with pytest.raises(OutOfOrderError, match="at most 5 scans"):
        wm.ingest(_cup(1.05, source="late"))  # within the 10 s window, before the kept 5
    assert (_summary(wm), wm.world().time) == before


def test_a_late_scan_within_the_kept_history_is_replayed_in_time_order() -> None:
    bounded = _world(max_scans=5)
    for t in TIMES:
        bounded.ingest(_cup(t))
    bounded.ingest(_cup(1.85, source="late"))  # between kept scans 1.8 and 1.9

    in_order = _world(max_scans=5)
    for t in sorted([*TIMES, 1.85]):
        in_order.ingest(_cup(t, source="late" if t == 1.85 else "cam"))
    assert _summary(bounded) == _summary(in_order)


def test_without_the_count_bound_the_same_late_scan_is_replayed() -> None:
    wm = _world(max_scans=1000)
    for t in TIMES:
        wm.ingest(_cup(t))
    wm.ingest(_cup(1.05, source="late"))
    assert wm.world().time == pytest.approx(2.0)
