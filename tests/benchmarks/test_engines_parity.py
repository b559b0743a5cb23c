"""bench_engines --parity-seeds: both engines in step over every scenario; each difference
tallied, none missed (a Rust side nudged by 1e-6, or one that drops a detection, shows)."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from semwm import world
from semwm.filters.engine import rust_core
from semwm.mhf import core_engine
from semwm.sim.scenarios import SCENARIOS

BENCHMARKS = Path(__file__).resolve().parents[2] / "benchmarks"
sys.path.insert(0, str(BENCHMARKS))

import bench_engines  # noqa: E402

pytestmark = pytest.mark.skipif(rust_core() is None, reason="the Rust core is not built")

SIM1 = next(case for case in bench_engines.PARITY_CASES if case.scenario == "sim1")


def test_every_scenario_has_a_parity_case() -> None:
    scenarios = {case.scenario for case in bench_engines.PARITY_CASES}
    assert set(SCENARIOS) <= scenarios and "kick" in scenarios
    assert any(case.association_model == "paper" for case in bench_engines.PARITY_CASES)


def test_a_run_in_step_is_equal_and_written() -> None:
    doc = bench_engines.run_parity(1, cases=(SIM1,), require_all=False)
    (row,) = doc["cases"]
    assert row["equal"] and row["differing"] == 0 and row["first"] is None
    assert row["frames"] > 40 and row["objects"] > row["frames"] and row["queries"] > 4
    assert row["largest"] <= bench_engines.TOLERANCE
    assert "Parity holds" in bench_engines.parity_markdown(doc)


def _every_scan_through_scan_rows(monkeypatch: pytest.MonkeyPatch) -> None:
    """The Rust side's batches read by the specification (its models made without the
    core's reader), so that each of its scans goes to the core through
    ``CoreEngine.scan_rows`` (the reader's scans go in one call,
    ``Engine.process_and_publish``)."""
    monkeypatch.setattr(world, "core_reader", lambda *arguments: None)


def test_a_nudged_rust_engine_shows(monkeypatch: pytest.MonkeyPatch) -> None:
    """Every measurement 1e-6 m off on the Rust side: the largest difference says so."""

    def nudged(self: Any, measurements: Any) -> Any:
        return [m._replace(z=m.z + 1e-6 * (np.arange(m.z.size) == 0)) for m in measurements]

    _every_scan_through_scan_rows(monkeypatch)
    monkeypatch.setattr(core_engine.CoreEngine, "scan_rows", nudged)
    tally = bench_engines.parity_run(SIM1, 0)
    assert 1e-7 < tally.largest < 1e-5


def test_a_rust_engine_that_drops_a_detection_shows(monkeypatch: pytest.MonkeyPatch) -> None:
    def dropping(self: Any, measurements: Any) -> Any:
        return list(measurements)[:-1] or list(measurements)

    _every_scan_through_scan_rows(monkeypatch)
    monkeypatch.setattr(core_engine.CoreEngine, "scan_rows", dropping)
    doc = bench_engines.run_parity(1, cases=(SIM1,), require_all=False)
    (row,) = doc["cases"]
    assert not row["equal"] and row["differing"] > 0 and row["first"].startswith("seed 0, call")
    assert "Parity does not hold" in bench_engines.parity_markdown(doc)
