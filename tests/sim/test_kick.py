"""``semwm simulate kick``: paper 004's kick experiment (Table I order, Fig. 6 trace)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from semwm.cli import main
from semwm.knowledge.loader import load_knowledge
from semwm.knowledge.shipped import shipped_knowledge_path
from semwm.sim.kick import KickSetup, ball_at, draw, run_kick


def test_the_ball_rolls_out_at_its_deceleration() -> None:
    setup = KickSetup()
    d = draw(np.random.default_rng(1), setup)
    rest = ball_at(setup.kick_time + d.speed / d.alpha + 5.0, setup, d)
    travelled = float(np.linalg.norm(rest - np.asarray(setup.ball_start)))
    assert travelled == pytest.approx(d.speed**2 / (2 * d.alpha), rel=1e-12)


def test_kick_hypotheses_find_the_ball_first_and_teammates_before_none() -> None:
    knowledge = load_knowledge(shipped_knowledge_path("robocup_kick.yaml"))
    result = run_kick(knowledge, seed=0, trials=6)
    summary = result.summary()
    assert summary["kick"]["mean"] < summary["teammate"]["mean"] < summary["none"]["mean"]
    assert all(s["never_seen"] == 0 for s in summary.values())
    # paired trials: the kick model is never slower than A on its own
    for kick, none in zip(summary["kick"]["values"], summary["none"]["values"], strict=True):
        assert kick <= none
    # Fig. 6: without hypotheses, the estimate A looks at goes suspicious, then invalid
    states = result.trials["none"][0].states
    after = states[states.index("suspicious") :]
    assert "invalid" in after


def test_the_command_writes_time_to_see_and_the_plot(tmp_path: Path) -> None:
    out = tmp_path / "kick"
    assert main(["simulate", "kick", "--trials", "2", "--seed", "3", "--out", str(out)]) == 0
    metrics = json.loads((out / "metrics.json").read_text())
    assert set(metrics["time_to_see"]) == {"none", "teammate", "kick"}
    for model in ("none", "teammate", "kick"):
        row = metrics["time_to_see"][model]
        assert row["trials"] == 2 and row["mean"] > 0 and row["std"] >= 0
    assert (out / "plot.png").stat().st_size > 10_000
    assert len((out / "trials.jsonl").read_text().splitlines()) == 6


def test_robocup_with_a_ball_and_camera_views_runs_with_and_without_negative_information() -> None:
    from semwm.knowledge.loader import load_document
    from semwm.sim.robocup_ball import ball_knowledge, make_ball_scenario, run_ball

    document = load_document(shipped_knowledge_path("robocup.yaml"))
    knowledge = ball_knowledge(document)
    assert knowledge.detectors["omnivision"].field_of_view == 90.0
    scenario = make_ball_scenario(np.random.default_rng(0), duration=3.0, n_opponents=1)
    balls = [p for _, points in scenario.truth for p in points if p.id == "ball"]
    assert balls[0].position != balls[-1].position  # kicked
    assert all(key in scenario.poses for key in {(d.time, d.source) for d in scenario.detections})
    with_views = run_ball(knowledge, scenario, True)
    without = run_ball(knowledge, scenario, False)
    assert with_views.n_frames == without.n_frames == len(scenario.truth)
    assert with_views.gospa.total != without.gospa.total  # the views change the world
