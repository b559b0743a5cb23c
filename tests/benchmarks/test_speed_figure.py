"""``bench_speed``'s figure drawn from the committed run: the three trackers per
detection, the long match by quarter, the cost per version in play."""

from __future__ import annotations

import json
import sys
from pathlib import Path

BENCHMARKS = Path(__file__).resolve().parents[2] / "benchmarks"
sys.path.insert(0, str(BENCHMARKS))

import bench_speed  # noqa: E402


def test_the_figure_of_the_committed_run_is_drawn(tmp_path: Path) -> None:
    doc = json.loads((BENCHMARKS / "results" / "speed.json").read_text())
    path = tmp_path / "speed.png"
    bench_speed.figure(doc, path)
    data = path.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 20_000
    committed = BENCHMARKS / "results" / "speed.png"
    assert committed.exists(), "bench_speed --update-results draws results/speed.png"
