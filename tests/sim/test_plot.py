"""The run plot: labelled (classes, ids, axes with units, a legend entry per series)
and readable at RoboCup scale (detections subsampled, one line per world id)."""

from __future__ import annotations

from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
import pytest

from semwm.knowledge.loader import load_knowledge
from semwm.knowledge.shipped import shipped_knowledge_path
from semwm.sim import plot
from semwm.sim.plot import (
    draw_run,
    plot_run,
    truth_paths,
    world_tracks,
)
from semwm.sim.runner import RunResult, run_scenario
from semwm.sim.scenarios import make_scenario


def _run(name: str, **sizes: float) -> RunResult:
    scenario = make_scenario(name, 0, **sizes)
    knowledge = load_knowledge(shipped_knowledge_path(scenario.knowledge_file))
    return run_scenario(scenario, knowledge, progress=False)


@pytest.fixture(scope="module")
def sim1() -> RunResult:
    return _run("sim1", duration=4.0)


def _texts(result: RunResult) -> tuple[list[str], list[str], str, str]:
    fig = draw_run(result.scenario, result.worlds, result.metrics)
    try:
        ax = fig.axes[0]
        legend = [t.get_text() for t in ax.get_legend().get_texts()]
        notes = [t.get_text() for t in ax.texts]
        return legend, notes, ax.get_xlabel(), ax.get_ylabel()
    finally:
        plt.close(fig)


def test_sim1_plot_names_classes_ids_and_marks_static_truth(sim1: RunResult) -> None:
    legend, notes, xlabel, ylabel = _texts(sim1)
    assert (xlabel, ylabel) == ("x [m]", "y [m]")
    truth_classes = {o.cls for o in sim1.scenario.truth[0].objects}
    world = sim1.worlds[-1].objects
    for cls in truth_classes:
        assert f"truth: static {cls}" in legend
    for obj in world:
        assert f"world: {obj.cls} track (#id at its last point in view)" in legend
        assert f"#{obj.id} {obj.label or obj.cls}" in notes
    for o in sim1.scenario.truth[0].objects:
        assert f"{o.label or o.id} ({o.cls})" in notes
    assert legend[0] == f"detections ({len(sim1.scenario.detections)})"


def test_truth_paths_tell_static_from_moving() -> None:
    assert all(p.static for p in truth_paths(make_scenario("sim1", 0, duration=2.0)))
    assert not any(p.static for p in truth_paths(make_scenario("sim2", 0)))


def test_world_tracks_one_per_id_with_its_last_class(sim1: RunResult) -> None:
    tracks = world_tracks(sim1.scenario, sim1.worlds)
    ids = {o.id for w in sim1.worlds for o in w.objects}
    assert set(tracks) == ids
    last = {o.id: o.cls for w in sim1.worlds for o in w.objects}
    for track_id, track in tracks.items():
        assert track.cls == last[track_id]
        counts = sum(any(o.id == track_id for o in w.objects) for w in sim1.worlds)
        assert track.rows.shape == (counts, 3)
        assert np.all(np.diff(track.rows[:, 0]) > 0)


def test_robocup_detections_are_subsampled_and_every_class_has_a_legend_entry(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    result = _run("robocup", duration=1.0)  # 10 s would have ~5000 detections; 1 s and a cap of 100
    monkeypatch.setattr(plot, "MAX_DETECTIONS_DRAWN", 100)
    n = len(result.scenario.detections)
    step = int(np.ceil(n / 100))
    assert step > 1
    legend, _, _, _ = _texts(result)
    assert legend[0] == f"detections (every {plot.ordinal(step)} of {n})"
    assert not any(entry.startswith("sensor path") for entry in legend)  # five robots: none
    for cls in {o.cls for f in result.scenario.truth for o in f.objects}:
        assert f"truth: {cls} path (square: start)" in legend
    path = plot_run(result.scenario, result.worlds, result.metrics, tmp_path / "plot.png")
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_a_world_track_line_breaks_where_the_object_was_not_in_the_world() -> None:
    rows = np.array([[0.0, 0.0, 0.0], [0.1, 1.0, 0.0], [0.5, 9.0, 9.0], [0.6, 9.5, 9.0]])
    broken = plot.with_gaps(rows, 0.1)
    assert broken.shape == (5, 3)
    assert np.isnan(broken[2]).all()  # absent at 0.2-0.4 s: no line from (1, 0) to (9, 9)
    assert np.array_equal(broken[[0, 1, 3, 4]], rows)
    assert np.array_equal(plot.with_gaps(rows[:2], 0.1), rows[:2])  # no gap: unchanged


@pytest.mark.parametrize(
    ("n", "text"),
    [(1, "1st"), (2, "2nd"), (3, "3rd"), (4, "4th"), (11, "11th"), (12, "12th"),
     (13, "13th"), (21, "21st"), (22, "22nd"), (101, "101st"), (111, "111th")],
)  # fmt: skip
def test_ordinals(n: int, text: str) -> None:
    assert plot.ordinal(n) == text


def test_the_title_counts_in_the_singular_for_one() -> None:
    result = _run("sim2")  # one person
    fig = draw_run(result.scenario, result.worlds, result.metrics)
    try:
        title = fig.axes[0].get_title()
    finally:
        plt.close(fig)
    assert title.endswith(" for 1 true object"), title
    assert "objects" not in title


def test_the_patrol_plot_draws_the_robots_path() -> None:
    from semwm.cli.simulate import scenario_knowledge

    scenario = make_scenario("patrol", 0, duration=10.0)
    knowledge = load_knowledge(scenario_knowledge(scenario))
    result = run_scenario(scenario, knowledge, progress=False)
    fig = draw_run(result.scenario, result.worlds, result.metrics)
    try:
        ax = fig.axes[0]
        legend = [t.get_text() for t in ax.get_legend().get_texts()]
        (line,) = [line for line in ax.get_lines() if line.get_label() == "sensor path (robot)"]
        drawn = np.column_stack(line.get_data())
    finally:
        plt.close(fig)
    assert "sensor path (robot)" in legend
    sensors = [d.sensor_position for d in scenario.detections if d.source == "robot"]
    assert all(s is not None for s in sensors)
    distinct = {(s[0], s[1]) for s in sensors if s is not None}
    assert {tuple(p) for p in drawn} == distinct
    assert len(drawn) > 10
    # the path spans the robot's loop, not a point
    assert np.ptp(drawn[:, 0]) > 2.0 or np.ptp(drawn[:, 1]) > 2.0
