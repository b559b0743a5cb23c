"""Concurrent scans placed in arrival order (``semwm.sources``): a scan of another source
at most the tolerance older than the world's newest processed scan is moved just after
it instead of being replayed; anything else keeps its time."""

from __future__ import annotations

import math
from typing import Any

from semwm.sources import SourceRegistry


def _scan(t: float, source: str | None, x: float = 1.0) -> dict[str, Any]:
    return {"time": t, "class": "Cup", "position": [x, 2.0], "source": source}


def _accepted(registry: SourceRegistry, *scans: dict[str, Any]) -> None:
    registry.accepted(registry.place(list(scans)))


def test_a_concurrent_scan_of_another_source_goes_just_after_the_newest() -> None:
    registry = SourceRegistry()
    _accepted(registry, _scan(10.003, "r3"))
    placement = registry.place(
        [_scan(10.001, "r1"), _scan(10.001, "r1", 2.0)], newest=10.003, tolerance=0.005
    )
    moved = math.nextafter(10.003, math.inf)
    assert [d["time"] for d in placement.detections] == [moved, moved]  # one scan, one time
    assert placement.moved == {("r1", 10.001): moved}
    assert placement.latest == {"r1": moved}
    registry.accepted(placement)
    assert registry.status("r1").last_time == moved  # type: ignore[union-attr]


def test_several_concurrent_scans_keep_their_order_at_distinct_times() -> None:
    registry = SourceRegistry()
    placement = registry.place(
        [_scan(9.999, "r2"), _scan(9.998, "r1"), _scan(10.0, None)], newest=10.0, tolerance=0.005
    )
    times = [d["time"] for d in placement.detections]
    first = math.nextafter(10.0, math.inf)
    second = math.nextafter(first, math.inf)
    third = math.nextafter(second, math.inf)
    assert times == [second, first, third]  # r1 (oldest) first, then r2, then no source


def test_late_scans_beyond_the_tolerance_or_out_of_their_sources_order_keep_their_time() -> None:
    registry = SourceRegistry()
    _accepted(registry, _scan(10.002, "r1"))
    sent = [
        _scan(9.99, "r2"),  # 10 ms late: more than the tolerance, replayed
        _scan(10.001, "r1"),  # older than r1's own last scan: its own order, replayed
        _scan(10.002, "r1"),  # r1's scan of the same time: merged with it, as before
        _scan(10.01, "r3"),  # newer than the newest: in order anyway
    ]
    placement = registry.place(sent, newest=10.004, tolerance=0.005)
    assert [d["time"] for d in placement.detections] == [9.99, 10.001, 10.002, 10.01]
    assert placement.moved == {}


def test_no_tolerance_or_no_world_time_moves_nothing() -> None:
    registry = SourceRegistry()
    sent = [_scan(9.999, "r1")]
    assert registry.place(sent, newest=10.0, tolerance=0.0).detections == tuple(sent)
    assert registry.place(sent, newest=None, tolerance=0.005).detections == tuple(sent)


def test_a_scan_of_the_newest_instant_that_sorts_after_the_newest_source_keeps_its_time() -> None:
    # synchronised sensors: the world processes (time, source) in order, so (10.0, "r4")
    # after (10.0, "r3") is in order and keeps its time; (10.0, "r2") would be a replay
    registry = SourceRegistry()
    sent = [_scan(10.0, "r4"), _scan(10.0, "r2"), _scan(10.0, None)]
    placement = registry.place(sent, newest=10.0, tolerance=0.005, newest_source="r3")
    first = math.nextafter(10.0, math.inf)
    second = math.nextafter(first, math.inf)
    assert [d["time"] for d in placement.detections] == [10.0, second, first]
    assert placement.moved == {(None, 10.0): first, ("r2", 10.0): second}
    # the newest source unknown (no reorder log): every scan of that instant is moved
    assert registry.place(sent, newest=10.0, tolerance=0.005).moved.keys() == {
        ("r4", 10.0),
        ("r2", 10.0),
        (None, 10.0),
    }
