"""The plot of a run (``plot.png`` of ``semwm simulate``), in the style of paper 002 Fig. 2.

It takes only the run's data (the scenario, the world at every truth time, the
metrics), never the runner. What it draws, in x-y metres:

* detections: small grey circles; when there are more than
  :data:`MAX_DETECTIONS_DRAWN`, every k-th (the legend says which k);
* truth: a static object as a large hollow marker in its class's colour, written
  with its id and class; a moving object as a thick translucent line in its
  class's colour from a start square, written with its id (and label);
* world: one line per world id in its class's colour (by its last class), written
  ``#id Class`` (or ``#id label``) at its last position; sim2 keeps the paper's
  black;
* the legend: every series, one entry per class for truth and world;
* scenario marks: the region's border (RoboCup: the field lines), sim2's door and
  the moments A-F.
"""

from __future__ import annotations

from collections import defaultdict
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Circle

from semwm.sim.metrics import Metrics
from semwm.sim.scenarios import Scenario
from semwm.world_types import WorldState

MAX_DETECTIONS_DRAWN = 1500
"""More detections than this are subsampled (every k-th) so tracks stay visible."""

Limits = tuple[tuple[float, float], tuple[float, float]]

STATIC_TOLERANCE_M = 1e-6
"""A truth object that moves less than this over the run is drawn as static."""


@dataclass(frozen=True)
class Track:
    """A world id over the run: rows ``(time, x, y)``, its last class and label."""

    id: int
    rows: np.ndarray
    cls: str
    label: str | None


def world_tracks(scenario: Scenario, worlds: Sequence[WorldState]) -> dict[int, Track]:
    """World id -> its :class:`Track` over every truth time it was in the world."""
    rows: dict[int, list[tuple[float, float, float]]] = defaultdict(list)
    last: dict[int, tuple[str, str | None]] = {}
    for frame, state in zip(scenario.truth, worlds, strict=True):
        for obj in state.objects:
            rows[obj.id].append((frame.time, obj.position[0], obj.position[1]))
            last[obj.id] = (obj.cls, obj.label)
    return {k: Track(k, np.asarray(v), *last[k]) for k, v in rows.items()}


def false_track_of_e(
    scenario: Scenario, worlds: Sequence[WorldState], radius: float = 1.0
) -> tuple[int, np.ndarray] | None:
    """sim2: the world track born near the false pair of moment E, if any:
    its id and rows ``(time, x, y)``."""
    pair = scenario.metadata.get("false_pair")
    if not isinstance(pair, list) or not pair:
        return None
    x, y, t_e = pair[0]
    for track_id, track in world_tracks(scenario, worlds).items():
        t0, x0, y0 = track.rows[0]
        if t_e - 1e-6 <= t0 <= t_e + 1.0 and np.hypot(x0 - x, y0 - y) < radius:
            return track_id, track.rows
    return None


@dataclass(frozen=True)
class TruthPath:
    """A true object over the run: positions ``(n, 2)``, class and label."""

    id: str
    xy: np.ndarray
    cls: str
    label: str | None

    @property
    def static(self) -> bool:
        return bool(np.ptp(self.xy, axis=0).max() < STATIC_TOLERANCE_M)


def truth_paths(scenario: Scenario) -> list[TruthPath]:
    """Every true object's positions over the run, in order of first appearance."""
    rows: dict[str, list[tuple[float, float]]] = defaultdict(list)
    info: dict[str, tuple[str, str | None]] = {}
    for frame in scenario.truth:
        for obj in frame.objects:
            rows[obj.id].append((obj.position[0], obj.position[1]))
            info[obj.id] = (obj.cls, obj.label)
    return [TruthPath(k, np.asarray(v), *info[k]) for k, v in rows.items()]


def class_colours(classes: Sequence[str]) -> dict[str, Any]:
    """One ``tab10`` colour per class name, in sorted order (stable between runs)."""
    cmap = plt.get_cmap("tab10")
    return {name: cmap(i % 10) for i, name in enumerate(sorted(set(classes)))}


def _field_lines(ax: Any) -> None:
    """RoboCup MSL field, 18 x 12 m, centre at the origin."""
    style = {"color": "tab:green", "lw": 0.8, "alpha": 0.5}
    ax.plot([-9, 9, 9, -9, -9], [-6, -6, 6, 6, -6], **style)
    ax.plot([0, 0], [-6, 6], **style)
    ax.add_patch(Circle((0.0, 0.0), 2.0, fill=False, **style))
    for side in (-1, 1):
        x_line = side * 9
        for depth, half in ((0.75, 1.95), (2.25, 3.25)):
            x_in = side * (9 - depth)
            ax.plot([x_line, x_in, x_in, x_line], [-half, -half, half, half], **style)


def ordinal(n: int) -> str:
    """``1st``, ``2nd``, ``3rd``, ``4th``, ``11th``, ``12th``, ``21st``..."""
    suffix = "th" if 10 <= n % 100 <= 20 else {1: "st", 2: "nd", 3: "rd"}.get(n % 10, "th")
    return f"{n}{suffix}"


def counted(n: int, word: str) -> str:
    """``1 true object``, ``2 true objects``."""
    return f"{n} {word}{'' if n == 1 else 's'}"


MAX_SENSOR_PATHS = 2
"""A scenario whose scans come from at most this many moving sensors (``patrol``'s
robot) has each sensor's path drawn; more (``robocup``'s team) would hide the tracks."""


def sensor_paths(scenario: Scenario) -> dict[str, np.ndarray]:
    """Source -> its sensor's positions (k, 2), in time order, from the detections'
    ``sensor_position``; empty for scenarios of fixed sensors or of many."""
    paths: dict[str, list[tuple[float, float]]] = {}
    for detection in scenario.detections:
        if detection.sensor_position is not None:
            point = (detection.sensor_position[0], detection.sensor_position[1])
            path = paths.setdefault(detection.source or "sensor", [])
            if not path or path[-1] != point:
                path.append(point)
    if len(paths) > MAX_SENSOR_PATHS:
        return {}
    return {source: np.asarray(points) for source, points in paths.items()}


def _draw_sensor_paths(ax: Any, scenario: Scenario) -> list[Line2D]:
    handles = []
    for source, path in sensor_paths(scenario).items():
        (line,) = ax.plot(
            path[:, 0], path[:, 1], color="0.35", lw=1.0, ls=(0, (4, 3)), zorder=1,
            label=f"sensor path ({source})",
        )  # fmt: skip
        handles.append(line)
    return handles


def _draw_detections(ax: Any, scenario: Scenario) -> Line2D:
    detections = np.asarray([d.position[:2] for d in scenario.detections]).reshape(-1, 2)
    step = max(1, int(np.ceil(len(detections) / MAX_DETECTIONS_DRAWN)))
    shown = detections[::step]
    what = f"every {ordinal(step)} of {len(detections)}" if step > 1 else f"{len(detections)}"
    ax.scatter(
        shown[:, 0], shown[:, 1], s=10, facecolors="none", edgecolors="0.65", lw=0.5, zorder=1
    )
    return Line2D(
        [], [], ls="", marker="o", mfc="none", mec="0.65", ms=4, label=f"detections ({what})"
    )


def _draw_truth(ax: Any, paths: list[TruthPath], colours: dict[str, Any]) -> list[Line2D]:
    handles: dict[tuple[str, bool], Line2D] = {}
    for path in paths:
        colour = colours[path.cls]
        name = path.label or path.id
        if path.static:
            x, y = path.xy[0]
            ax.scatter([x], [y], s=260, facecolors="none", edgecolors=[colour], lw=1.6, zorder=2)
            ax.annotate(
                f"{name} ({path.cls})",
                (x, y),
                xytext=(0, -17),
                textcoords="offset points",
                ha="center",
                fontsize=7,
                color=colour,
            )
            handles.setdefault(
                (path.cls, True),
                Line2D(
                    [],
                    [],
                    ls="",
                    marker="o",
                    mfc="none",
                    mec=colour,
                    mew=1.6,
                    ms=11,
                    label=f"truth: static {path.cls}",
                ),
            )
        else:
            ax.plot(path.xy[:, 0], path.xy[:, 1], color=colour, lw=4, alpha=0.25, zorder=2)
            ax.plot(*path.xy[0], marker="s", ms=5, color=colour, alpha=0.6, zorder=2)
            ax.annotate(
                name,
                path.xy[0],
                xytext=(-4, 5),
                textcoords="offset points",
                fontsize=6,
                color=colour,
                alpha=0.9,
            )
            handles.setdefault(
                (path.cls, False),
                Line2D(
                    [],
                    [],
                    color=colour,
                    lw=4,
                    alpha=0.25,
                    marker="s",
                    ms=5,
                    label=f"truth: {path.cls} path (square: start)",
                ),
            )
    return list(handles.values())


def _last_inside(xs: np.ndarray, ys: np.ndarray, limits: Limits) -> int:
    """Index of the last point inside the drawn limits (else the last point)."""
    (x_lo, x_hi), (y_lo, y_hi) = limits
    inside = np.flatnonzero((xs >= x_lo) & (xs <= x_hi) & (ys >= y_lo) & (ys <= y_hi))
    return int(inside[-1]) if inside.size else len(xs) - 1


def with_gaps(rows: np.ndarray, step: float) -> np.ndarray:
    """``rows`` ``(time, x, y)`` with a NaN row wherever the track was absent from the
    world for a frame or more (consecutive times more than 1.5 ``step`` apart), so a
    line drawn through them breaks there instead of joining distant points."""
    if len(rows) < 2 or not step > 0.0:
        return rows
    gaps = np.flatnonzero(np.diff(rows[:, 0]) > 1.5 * step) + 1
    return np.insert(rows, gaps, np.nan, axis=0) if gaps.size else rows


def _draw_world(
    ax: Any,
    tracks: dict[int, Track],
    colours: dict[str, Any],
    paper_style: bool,
    limits: Limits,
    step: float = 0.0,
) -> list[Line2D]:
    handles: dict[str, Line2D] = {}
    for track_id, track in sorted(tracks.items()):
        colour = "k" if paper_style else colours[track.cls]
        broken = with_gaps(track.rows, step)
        ax.plot(broken[:, 1], broken[:, 2], "-", lw=1.0, color=colour, zorder=3)
        xs, ys = track.rows[:, 1], track.rows[:, 2]
        end = _last_inside(xs, ys, limits)
        ax.plot(xs[end : end + 1], ys[end : end + 1], "o", ms=2.5, color=colour, zorder=3)
        ax.annotate(
            f"#{track_id} {track.label or track.cls}",
            (float(xs[end]), float(ys[end])),
            xytext=(4, 3),
            textcoords="offset points",
            fontsize=6,
            color=colour,
            zorder=5,
        )
        key = "world" if paper_style else track.cls
        handles.setdefault(
            key,
            Line2D(
                [],
                [],
                color=colour,
                lw=1.0,
                marker="o",
                ms=2.5,
                label=f"world: {track.cls} track (#id at its last point in view)"
                if not paper_style
                else "world track (#id at its last point in view)",
            ),
        )
    return list(handles.values())


def plot_run(
    scenario: Scenario, worlds: Sequence[WorldState], metrics: Metrics, path: str | Path
) -> Path:
    """Draw a run (:func:`draw_run`) to ``path`` (PNG); returns the path."""
    fig = draw_run(scenario, worlds, metrics)
    out = Path(path)
    fig.savefig(out)
    plt.close(fig)
    return out


def draw_run(scenario: Scenario, worlds: Sequence[WorldState], metrics: Metrics) -> Figure:
    """The figure of a run: detections, truth, the world's tracks, the scenario's
    marks and the metrics in the title (the caller closes it)."""
    paper_style = scenario.name == "sim2"
    paths = truth_paths(scenario)
    tracks = world_tracks(scenario, worlds)
    colours = class_colours([p.cls for p in paths] + [t.cls for t in tracks.values()])
    (x_lo, x_hi), (y_lo, y_hi) = scenario.region[0], scenario.region[1]
    width = x_hi - x_lo + 1.0
    height = y_hi - y_lo + 1.0
    large = len(paths) > 6 or len(tracks) > 12
    size = 13.0 if large else 9.0
    fig, ax = plt.subplots(figsize=(size, size * height / width + 1.6), dpi=110)
    if scenario.name == "robocup":
        _field_lines(ax)
    else:
        ax.plot([x_lo, x_hi, x_hi, x_lo, x_lo], [y_lo, y_lo, y_hi, y_hi, y_lo], color="k", lw=1)

    handles = [_draw_detections(ax, scenario), *_draw_sensor_paths(ax, scenario)]
    handles += _draw_truth(ax, paths, colours)
    limits = ((x_lo - 0.5, x_hi + 0.5), (y_lo - 0.5, y_hi + 0.5))
    times = np.array([frame.time for frame in scenario.truth])
    step = float(np.median(np.diff(times))) if len(times) > 1 else 0.0
    handles += _draw_world(ax, tracks, colours, paper_style, limits, step)

    door = scenario.metadata.get("door")
    if isinstance(door, tuple | list):
        ax.plot([door[0]], [door[1]], marker="s", ms=11, mfc="none", mec="tab:brown", mew=1.5)
        handles.append(
            Line2D(
                [],
                [],
                ls="",
                marker="s",
                ms=9,
                mfc="none",
                mec="tab:brown",
                mew=1.5,
                label="door (known object)",
            )
        )
    moments = scenario.metadata.get("moments")
    if isinstance(moments, dict):
        _annotate_moments(ax, scenario, worlds, moments)
        track_of_e = false_track_of_e(scenario, worlds) is not None
        f_text = "F: where it was removed" if track_of_e else "no track born there, so no F"
        handles.append(
            Line2D(
                [],
                [],
                ls="",
                marker="$A$",
                color="k",
                ms=7,
                label=f"A-B, C-D: occlusions; E: false pair; {f_text}",
            )
        )

    ax.set_xlim(*limits[0])
    ax.set_ylim(*limits[1])
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    gospa = metrics.gospa
    ax.set_title(
        f"{scenario.name} (seed {scenario.seed}, {scenario.duration:g} s): "
        f"GOSPA {gospa.total:.2f} m (c={gospa.c:g} m, p={gospa.p:g}), "
        f"ID switches {metrics.id_switches}, {counted(len(tracks), 'world id')} for "
        f"{counted(len(paths), 'true object')}",
        fontsize=9,
    )
    ax.legend(
        handles=handles,
        loc="upper center",
        bbox_to_anchor=(0.5, -0.07),
        ncol=3 if large else 2,
        fontsize=7,
        frameon=False,
    )
    fig.tight_layout()
    return fig


def _annotate_moments(
    ax: Any, scenario: Scenario, worlds: Sequence[WorldState], moments: dict[str, Any]
) -> None:
    """A-D at the person's true position, E at the false pair, F where the false
    track of E was last in the world (when there was one)."""
    truth = {frame.time: frame.objects[0].position for frame in scenario.truth if frame.objects}
    times = np.asarray(sorted(truth))
    places: dict[str, tuple[float, float]] = {}
    for name in "ABCD":
        if name in moments and times.size:
            t = times[np.argmin(np.abs(times - float(moments[name])))]
            places[name] = (truth[t][0], truth[t][1])
    pair = scenario.metadata.get("false_pair")
    if isinstance(pair, list) and pair:
        places["E"] = (pair[0][0], pair[0][1])
        found = false_track_of_e(scenario, worlds)
        if found:
            places["F"] = (found[1][-1, 1], found[1][-1, 2])
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
