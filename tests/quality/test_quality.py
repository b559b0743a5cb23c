"""Quality regression guard: seeded sim1 and sim2 must not get worse.

Fails if a scenario's mean GOSPA exceeds ``baseline * 1.1 + 0.05`` or its ID
switches exceed ``baseline + 1``. The baseline (``baseline.json``, with the commit
it was generated at) is regenerated with::

    python tests/quality/test_quality.py --write-baseline
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

from semwm.knowledge.loader import load_knowledge
from semwm.knowledge.shipped import shipped_knowledge_path
from semwm.sim.runner import run_scenario
from semwm.sim.scenarios import make_scenario

BASELINE = Path(__file__).with_name("baseline.json")
CASES: dict[str, dict[str, Any]] = {
    "sim1": {"seed": 0, "sizes": {"duration": 20.0}},
    "sim2": {"seed": 0, "sizes": {}},
}


def measure(name: str) -> dict[str, float]:
    case = CASES[name]
    scenario = make_scenario(name, case["seed"], **case["sizes"])
    knowledge = load_knowledge(shipped_knowledge_path(scenario.knowledge_file))
    m = run_scenario(scenario, knowledge, progress=False).metrics
    return {"gospa": m.gospa.total, "id_switches": m.id_switches}


@pytest.mark.parametrize("name", sorted(CASES))
def test_no_quality_regression(name: str) -> None:
    baseline = json.loads(BASELINE.read_text())["scenarios"][name]
    got = measure(name)
    limit = baseline["gospa"] * 1.1 + 0.05
    assert got["gospa"] <= limit, f"{name}: GOSPA {got['gospa']:.4f} > {limit:.4f} ({baseline})"
    assert got["id_switches"] <= baseline["id_switches"] + 1, (
        f"{name}: ID switches {got['id_switches']} > {baseline['id_switches']} + 1"
    )


def write_baseline() -> dict[str, Any]:
    commit = subprocess.run(
        ["git", "rev-parse", "HEAD"], capture_output=True, text=True, cwd=BASELINE.parent
    ).stdout.strip()
    doc = {
        "commit": commit,
        "rule": "fail if gospa > baseline*1.1 + 0.05 or id_switches > baseline + 1",
        "cases": CASES,
        "scenarios": {name: measure(name) for name in sorted(CASES)},
    }
    BASELINE.write_text(json.dumps(doc, indent=2) + "\n")
    return doc


if __name__ == "__main__":
    if "--write-baseline" in sys.argv:
        print(json.dumps(write_baseline(), indent=2))
