"""Plots of a run in the style of paper 002 Fig. 2 (matplotlib, Agg backend).

Detections are grey circles, the world's tracks black dots (one colour per world
id in the multi-object scenarios; sim2 stays grey and black like the paper), the
truth a thin line. sim2 marks the door and the moments A-F; robocup draws the
field lines.
"""

from __future__ import annotations

from collections import defaultdict
from pathlib import Path
from typing import TYPE_CHECKING, Any

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.patches import Circle

if TYPE_CHECKING:
    from semwm.sim.runner import RunResult


def world_tracks(result: RunResult) -> dict[int, np.ndarray]:
    """World id -> rows ``(time, x, y)`` of every truth time it was in the world."""
    rows: dict[int, list[tuple[float, float, float]]] = defaultdict(list)
    for frame, state in zip(result.scenario.truth, result.worlds, strict=True):
        for obj in state.objects:
            rows[obj.id].append((frame.time, obj.position[0], obj.position[1]))
    return {k: np.asarray(v) for k, v in rows.items()}


def false_track_of_e(result: RunResult, radius: float = 1.0) -> tuple[int, np.ndarray] | None:
    """sim2: the world track born near the false pair of moment E, if any."""
    pair = result.scenario.metadata.get("false_pair")
    if not isinstance(pair, list) or not pair:
        return None
    x, y, t_e = pair[0]
    for track_id, track in world_tracks(result).items():
        t0, x0, y0 = track[0]
        if t_e - 1e-6 <= t0 <= t_e + 1.0 and np.hypot(x0 - x, y0 - y) < radius:
            return track_id, track
    return None


def _truth_lines(result: RunResult) -> dict[str, np.ndarray]:
    rows: dict[str, list[tuple[float, float]]] = defaultdict(list)
    for frame in result.scenario.truth:
        for obj in frame.objects:
            rows[obj.id].append((obj.position[0], obj.position[1]))
    return {k: np.asarray(v) for k, v in rows.items()}


def _field_lines(ax: Any) -> None:
    """RoboCup MSL field, 18 x 12 m, centre at the origin."""
    style = {"color": "tab:green", "lw": 0.8, "alpha": 0.6}
    ax.plot([-9, 9, 9, -9, -9], [-6, -6, 6, 6, -6], **style)
    ax.plot([0, 0], [-6, 6], **style)
    ax.add_patch(Circle((0.0, 0.0), 2.0, fill=False, **style))
    for side in (-1, 1):
        x_line = side * 9
        for depth, half in ((0.75, 1.95), (2.25, 3.25)):
            x_in = side * (9 - depth)
            ax.plot([x_line, x_in, x_in, x_line], [-half, -half, half, half], **style)


def plot_run(result: RunResult, path: str | Path) -> Path:
    """Draw ``result`` to ``path`` (PNG); returns the path."""
    scenario = result.scenario
    paper_style = scenario.name == "sim2"
    fig, ax = plt.subplots(figsize=(8, 6.4), dpi=110)
    (x_lo, x_hi), (y_lo, y_hi) = scenario.region[0], scenario.region[1]
    if scenario.name == "robocup":
        _field_lines(ax)
    else:
        ax.plot([x_lo, x_hi, x_hi, x_lo, x_lo], [y_lo, y_lo, y_hi, y_hi, y_lo], color="k", lw=1)

    detections = np.asarray([d.position[:2] for d in scenario.detections]).reshape(-1, 2)
    ax.scatter(
        detections[:, 0],
        detections[:, 1],
        s=12,
        facecolors="none",
        edgecolors="0.6",
        linewidths=0.6,
        label="detections",
        zorder=1,
    )
    for i, line in enumerate(_truth_lines(result).values()):
        ax.plot(
            line[:, 0],
            line[:, 1],
            color="tab:blue",
            lw=0.7,
            alpha=0.7,
            label="truth" if i == 0 else None,
            zorder=2,
        )

    tracks = world_tracks(result)
    colours = plt.get_cmap("tab20")
    for i, (track_id, track) in enumerate(sorted(tracks.items())):
        colour = "k" if paper_style else colours(i % 20)
        ax.plot(
            track[:, 1],
            track[:, 2],
            ".",
            ms=2.5,
            color=colour,
            zorder=3,
            label="world" if i == 0 else None,
        )
        if not paper_style:
            ax.annotate(
                str(track_id), (float(track[-1, 1]), float(track[-1, 2])), fontsize=6, color=colour
            )

    door = scenario.metadata.get("door")
    if isinstance(door, tuple | list):
        ax.plot(
            [door[0]],
            [door[1]],
            marker="s",
            ms=10,
            mfc="none",
            mec="tab:brown",
            mew=1.5,
            zorder=4,
            label="door",
        )
    moments = scenario.metadata.get("moments")
    if isinstance(moments, dict):
        _annotate_moments(ax, result, moments)

    ax.set_xlim(x_lo - 0.5, x_hi + 0.5)
    ax.set_ylim(y_lo - 0.5, y_hi + 0.5)
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    gospa = result.metrics.gospa
    ax.set_title(
        f"{scenario.name} (seed {scenario.seed}): GOSPA {gospa.total:.2f} "
        f"(c={gospa.c:g}, p={gospa.p:g}), ID switches {result.metrics.id_switches}",
        fontsize=9,
    )
    ax.legend(loc="upper right", fontsize=7, framealpha=0.8)
    fig.tight_layout()
    out = Path(path)
    fig.savefig(out)
    plt.close(fig)
    return out


def _annotate_moments(ax: Any, result: RunResult, moments: dict[str, Any]) -> None:
    """A-D at the person's true position, E at the false pair, F where the false
    track of E was last in the world (else at E)."""
    truth = {
        frame.time: frame.objects[0].position for frame in result.scenario.truth if frame.objects
    }
    times = np.asarray(sorted(truth))
    places: dict[str, tuple[float, float]] = {}
    for name in "ABCD":
        if name in moments and times.size:
            t = times[np.argmin(np.abs(times - float(moments[name])))]
            places[name] = (truth[t][0], truth[t][1])
    pair = result.scenario.metadata.get("false_pair")
    if isinstance(pair, list) and pair:
        places["E"] = (pair[0][0], pair[0][1])
        found = false_track_of_e(result)
        places["F"] = (found[1][-1, 1], found[1][-1, 2]) if found else places["E"]
    for name, (x, y) in places.items():
        ax.annotate(
            name,
            (x, y),
            xytext=(6, 6),
            textcoords="offset points",
            fontsize=11,
            fontweight="bold",
            zorder=5,
        )
