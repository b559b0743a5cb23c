"""bench_quality --keep-peers: a run of semwm alone joined with the committed results'
Stone Soup rows (same seeds and sizes), every summary and target made again."""

from __future__ import annotations

import copy
import json
import sys
from pathlib import Path
from typing import Any

import pytest

BENCHMARKS = Path(__file__).resolve().parents[2] / "benchmarks"
sys.path.insert(0, str(BENCHMARKS))

import bench_quality  # noqa: E402


def _committed() -> dict[str, Any]:
    doc: dict[str, Any] = json.loads((BENCHMARKS / "results" / "quality.json").read_text())
    return doc


def _semwm_only(committed: dict[str, Any], name: str, worse: float) -> dict[str, Any]:
    """A semwm-only run of scenario ``name``: the committed semwm rows, each GOSPA
    ``worse`` higher."""
    entry = copy.deepcopy(committed["scenarios"][name])
    rows = [{**r, "gospa": r["gospa"] + worse} for r in entry["runs"]["semwm"]]
    entry["runs"] = {"semwm": rows}
    entry["summary"] = {"semwm": bench_quality.summarise(rows)}
    entry["target"] = bench_quality.target(entry["summary"], entry["runs"])
    doc = {**copy.deepcopy(committed), "machine": {**committed["machine"], "date": "now"}}
    doc["scenarios"] = {name: entry}
    return doc


def test_semwms_rows_are_this_runs_and_the_peers_the_committed_ones() -> None:
    committed = _committed()
    joined = bench_quality.with_peers_from(_semwm_only(committed, "sim1", 1.0), committed)
    old, new = committed["scenarios"]["sim1"], joined["scenarios"]["sim1"]
    assert new["summary"]["semwm"]["gospa_mean"] == pytest.approx(
        old["summary"]["semwm"]["gospa_mean"] + 1.0
    )
    for peer in ("stonesoup_gnn", "stonesoup_jpda"):
        assert new["runs"][peer] == old["runs"][peer]
        assert new["summary"][peer] == old["summary"][peer]
    # the target is made again from the joined rows: 1 m worse on every seed fails it
    assert old["target"]["passed"] and not new["target"]["passed"]
    assert new["target"]["mean_ratio"] > old["target"]["mean_ratio"]
    # scenarios not run now stay as committed; the peers' run is named
    assert joined["scenarios"]["robocup"] == committed["scenarios"]["robocup"]
    assert list(joined["scenarios"]) == [
        n for n in bench_quality.CONFIGS if n in joined["scenarios"]
    ]
    # (joined twice, the peers still come from the run that made them)
    assert joined["peers_from"] == committed.get("peers_from", committed["machine"])
    assert "earlier run of the same seeds" in bench_quality.markdown(joined)


def test_other_seeds_are_refused() -> None:
    committed = _committed()
    doc = _semwm_only(committed, "sim1", 0.0)
    doc["seeds"] = [0, 1, 2]
    with pytest.raises(SystemExit, match="other seeds"):
        bench_quality.with_peers_from(doc, committed)
