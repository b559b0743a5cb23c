"""Both engines learn the same rates from the sources' streams (``ObservedRates``: the
sources' clocks, each stream's counts, which lineages each stream has seen, its false
alarms) and report the same rates beside the knowledge's (``GET /sources``), scan by
scan. The Rust engine keeps them in the core (``core/src/mhf/rates.rs``)."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from semwm.knowledge.loader import load_knowledge
from semwm.knowledge.shipped import shipped_knowledge_path
from semwm.mhf.rates import ObservedRates
from semwm.sim.runner import scans
from semwm.sim.scenarios import make_scenario
from semwm.world import WorldModel

from . import needs_rust

pytestmark = needs_rust

TOL = 1e-9
BENCHMARK_KNOWLEDGE = Path(__file__).resolve().parents[2] / "benchmarks" / "knowledge"


def _close(a: float | None, b: float | None) -> bool:
    if a is None or b is None:
        return a is b
    return math.isclose(a, b, rel_tol=TOL, abs_tol=TOL)


def _assert_same_rates(python: ObservedRates, rust: ObservedRates, where: str) -> None:
    assert python.sources.keys() == rust.sources.keys(), where
    for name, clock in python.sources.items():
        other = rust.sources[name]
        assert clock.last_time == other.last_time, where
        assert _close(clock.interval, other.interval), where
        assert clock.position == other.position, where
        assert _close(clock.speed, other.speed), where
    assert python.streams.keys() == rust.streams.keys(), where
    for key, counts in python.streams.items():
        other_counts = rust.streams[key]
        assert counts.detected == other_counts.detected, (where, key)
        assert _close(counts.hits, other_counts.hits), (where, key)
        assert _close(counts.expected, other_counts.expected), (where, key)
    assert {k: dict(v) for k, v in python.seen.items()} == {
        k: dict(v) for k, v in rust.seen.items()
    }, where
    assert python.false_alarms == rust.false_alarms, where


@pytest.mark.parametrize(
    ("name", "sizes"),
    [("robocup", {"duration": 1.5}), ("datasheet", {"duration": 15.0}), ("sim2", {})],
)
def test_the_same_rates_scan_by_scan(name: str, sizes: dict[str, float]) -> None:
    scenario = make_scenario(name, 1, **sizes)
    benchmark = BENCHMARK_KNOWLEDGE / scenario.knowledge_file
    path = benchmark if benchmark.is_file() else shipped_knowledge_path(scenario.knowledge_file)
    knowledge = load_knowledge(path)
    python = WorldModel(knowledge, engine="python")
    rust = WorldModel(knowledge, engine="rust")
    for index, scan in enumerate(scans(scenario.detections)):
        python.ingest(scan)
        rust.ingest(scan)
        _assert_same_rates(
            python._state.observed, rust._state.observed, f"{name}: after scan {index}"
        )
    expected = [r.to_dict() for r in python.rate_report()]
    got = [r.to_dict() for r in rust.rate_report()]
    assert [(r["detector"], r["warnings"]) for r in got] == [
        (r["detector"], r["warnings"]) for r in expected
    ]
    for g, e in zip(got, expected, strict=True):
        assert _close(g["clutter_hz"], e["clutter_hz"])  # type: ignore[arg-type]
        assert g["detection_hz"].keys() == e["detection_hz"].keys()  # type: ignore[attr-defined]
        for cls, value in e["detection_hz"].items():  # type: ignore[attr-defined]
            assert _close(g["detection_hz"][cls], value)  # type: ignore[index]
