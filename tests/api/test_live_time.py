"""The live page's time text (api/static/live.js ``timeText``), run in Node: a robot's
epoch seconds as a time of day, a scenario's own seconds as seconds (issue 31, case 5)."""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
from pathlib import Path

import pytest

LIVE_JS = Path(__file__).resolve().parents[2] / "api" / "static" / "live.js"


def time_texts(values: list[float | None]) -> list[str]:
    node = shutil.which("node")
    if node is None:
        pytest.skip("node is not installed")
    source = LIVE_JS.read_text(encoding="utf-8")
    constant = re.search(r"^  const EPOCH_FROM = .*;$", source, re.MULTILINE)
    function = re.search(r"^  function timeText\(.*?^  }$", source, re.MULTILINE | re.DOTALL)
    assert constant and function, "live.js has no timeText"
    script = (
        f"{constant.group(0)}\n{function.group(0)}\n"
        f"console.log(JSON.stringify({json.dumps(values)}.map((v) => timeText(v, 2))));"
    )
    result = subprocess.run(
        [node, "-e", script],
        capture_output=True,
        text=True,
        check=True,
        timeout=30,
        env={**os.environ, "TZ": "UTC"},
    )
    texts: list[str] = json.loads(result.stdout)
    return texts


def test_epoch_seconds_are_a_time_of_day_and_scenario_seconds_stay_seconds() -> None:
    # 1764066060.25 s is 2025-11-25 10:21:00.25 UTC (the "1764066060.00 s")
    assert time_texts([1764066060.25, 1764066069.5, 2.2, 0.0, None]) == [
        "10:21:00.25",
        "10:21:09.50",
        "2.20 s",
        "0.00 s",
        "–",
    ]


def test_the_page_uses_it_for_every_time_it_shows() -> None:
    source = LIVE_JS.read_text(encoding="utf-8")
    assert "fmt(data.time" not in source and "fmt(obj.last_seen" not in source
    assert "fmt(obj.created" not in source and "fmt(p.t" not in source
    assert 'setText("stat-time", timeText(data.time, 2))' in source
