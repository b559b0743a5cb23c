"""Checks of the ``leftbehind`` scenario (issue 28): what the world concludes from not
seeing something.

Pure functions over a scenario (its ``metadata["objects"]``: the truth about views)
and the worlds :func:`semwm.sim.runner.run_scenario` publishes at every truth time
(at the default ``min_existence``):

* :func:`kept_out_of_view` (a): every object out of the robot's view stays published
  the whole time it is out of view and present, once the robot has seen it for a
  view interval of at least ``min_view`` s.
* :func:`removed_leaves` (b): every object removed while in view leaves the world
  within ``within`` s of its next missed view (the first scan after the removal
  whose view holds its place); with ``in_view=False`` the same for objects removed
  out of view (reported, not part of issue 28's acceptance).
* :func:`kept_unseen_by_other` (c): every object the other source (``cam2``) never
  detected is published the whole time it is present, once established as in (a).

An object "is published" at a time when some world object of any class lies within
``match_radius`` m of it (the objects stand at least 1 m apart; the class is another
question). Each check returns a :class:`ViewCheck`: how many objects and frames it
asked about, how many failed, and the worst case (which object, when).

:func:`with_sensor_views` wraps a world model so that the robot's and cam2's scans
carry their sensor view (``SensorReport``: position and heading), the empty ones
("looked and saw nothing") included, as a robot that knows its pose would send them.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, cast

import numpy as np

from semwm.detection import Detection, SensorReport
from semwm.knowledge.model import Knowledge
from semwm.sim.runner import WorldModelFactory, WorldModelLike
from semwm.sim.scenarios import Scenario
from semwm.world_types import WorldState

MATCH_RADIUS = 0.5
"""Distance (m) within which a world object counts as the real object: 10 sigma of the
cameras' 5 cm noise, half the objects' least separation."""
MIN_VIEW = 2.0
"""An object is asked to be kept once the robot has had it in view (present) for one
interval of at least this long (s): about 16 detections at 8 Hz."""
LEAVE_WITHIN = 2.0
"""Issue 28: an object removed in view leaves the world within this long (s) of its next
missed view."""
_EPS = 1e-6


@dataclass(frozen=True)
class ViewCheck:
    """One check over one run.

    ``objects_asked``/``objects_failed``: objects the check applies to / that fail it;
    ``frames_asked``/``frames_failed``: truth frames summed over the objects (for (b):
    frames after the deadline); ``worst``: the worst failing case (``object``,
    ``time`` it first failed, ``detail``; for (b) also ``latency_s``, ``None`` when still
    published at the end), else ``None``.
    """

    name: str
    objects_asked: int
    objects_failed: int
    frames_asked: int
    frames_failed: int
    worst: dict[str, Any] | None

    @property
    def passed(self) -> bool:
        return self.objects_failed == 0

    def detail(self) -> str:
        if self.passed:
            return f"{self.objects_asked} objects, {self.frames_asked} frames: all pass"
        w = self.worst or {}
        return (
            f"{self.objects_failed}/{self.objects_asked} objects fail "
            f"({self.frames_failed}/{self.frames_asked} frames); worst {w.get('object')} "
            f"at t={w.get('time')}: {w.get('detail')}"
        )

    def to_dict(self) -> dict[str, Any]:
        return {
            "name": self.name,
            "passed": self.passed,
            "objects_asked": self.objects_asked,
            "objects_failed": self.objects_failed,
            "frames_asked": self.frames_asked,
            "frames_failed": self.frames_failed,
            "worst": self.worst,
        }


def _objects(scenario: Scenario) -> dict[str, dict[str, Any]]:
    objects = scenario.metadata.get("objects")
    if not isinstance(objects, dict):
        raise TypeError("a leftbehind scenario's metadata needs 'objects' (a dict by object id)")
    return objects


def _published(state: WorldState, position: Sequence[float], radius: float) -> bool:
    here = np.asarray(position, dtype=float)[:2]
    return any(
        float(np.linalg.norm(np.asarray(o.position[:2], dtype=float) - here)) <= radius
        for o in state.objects
    )


def _in(t: float, intervals: Sequence[Sequence[float]], pad: float = 0.0) -> bool:
    return any(a - pad - _EPS <= t <= b + pad + _EPS for a, b in intervals)


def _present(info: Mapping[str, Any], t: float) -> bool:
    placed = info.get("placed")
    removed = info.get("removed")
    return (placed is None or t >= float(placed) - _EPS) and (
        removed is None or t < float(removed) - _EPS
    )


def established_at(info: Mapping[str, Any], min_view: float = MIN_VIEW) -> float | None:
    """The end of the object's first view interval (present) of at least ``min_view`` s:
    from then on the robot has seen it enough to know it; ``None`` if never."""
    for a, b in info["view_intervals"]:
        if b - a >= min_view - _EPS:
            return float(b)
    return None


def _kept(
    scenario: Scenario,
    worlds: Sequence[WorldState],
    name: str,
    asked: Mapping[str, Mapping[str, Any]],
    out_of_view_only: bool,
    radius: float,
    min_view: float,
    step: float,
) -> ViewCheck:
    frames_asked = frames_failed = 0
    failing: dict[str, tuple[int, float]] = {}  # object -> (frames missing, first time)
    objects_asked = 0
    for oid, info in asked.items():
        start = established_at(info, min_view)
        if start is None:
            continue
        objects_asked += 1
        for frame, state in zip(scenario.truth, worlds, strict=True):
            t = frame.time
            if t <= start + _EPS or not _present(info, t):
                continue
            if out_of_view_only and _in(t, info["all_view_intervals"], pad=step):
                continue
            frames_asked += 1
            if not _published(state, info["position"], radius):
                frames_failed += 1
                count, first = failing.get(oid, (0, t))
                failing[oid] = (count + 1, first)
    worst = None
    if failing:
        oid, (count, first) = max(failing.items(), key=lambda kv: kv[1][0])
        worst = {
            "object": oid,
            "time": round(first, 3),
            "frames_missing": count,
            "detail": f"not published from t={first:g} ({count} frames missing; "
            f"known since t={established_at(asked[oid], min_view):g})",
        }
    return ViewCheck(name, objects_asked, len(failing), frames_asked, frames_failed, worst)


def _step(scenario: Scenario) -> float:
    return float(str(scenario.metadata.get("scan_step", 0.1)))


def kept_out_of_view(
    scenario: Scenario,
    worlds: Sequence[WorldState],
    *,
    radius: float = MATCH_RADIUS,
    min_view: float = MIN_VIEW,
) -> ViewCheck:
    """(a): every object, once established (:func:`established_at`), is published at
    every truth time it is present and out of the robot's view (one scan step away from
    every view interval)."""
    return _kept(
        scenario,
        worlds,
        "(a) kept out of view",
        _objects(scenario),
        True,
        radius,
        min_view,
        _step(scenario),
    )


def kept_unseen_by_other(
    scenario: Scenario,
    worlds: Sequence[WorldState],
    *,
    radius: float = MATCH_RADIUS,
    min_view: float = MIN_VIEW,
) -> ViewCheck:
    """(c): every object ``cam2`` never detected, once established, is published at every
    truth time it is present (in the robot's view or not)."""
    asked = {k: v for k, v in _objects(scenario).items() if int(v["cam2_detections"]) == 0}
    return _kept(
        scenario,
        worlds,
        "(c) kept when the other source never saw it",
        asked,
        False,
        radius,
        min_view,
        _step(scenario),
    )


def next_view_after(info: Mapping[str, Any], t: float, step: float) -> float | None:
    """The first scan time at or after ``t`` at which the object's place is in the
    robot's view: its next missed view once removed at ``t``."""
    for a, b in info["all_view_intervals"]:
        if b + _EPS >= t:
            first = max(float(a), float(np.ceil((t - _EPS) / step) * step))
            return round(first, 9)
    return None


def removed_leaves(
    scenario: Scenario,
    worlds: Sequence[WorldState],
    *,
    in_view: bool = True,
    within: float = LEAVE_WITHIN,
    radius: float = MATCH_RADIUS,
) -> ViewCheck:
    """(b): every object removed while in the robot's view (``in_view=False``: out of
    it) is not published at any truth time from ``within`` s after its next missed
    view to the end of the run. Its latency: the last time it was published minus the
    next missed view (``None`` and ``still_published``: still published at the end)."""
    step = _step(scenario)
    name = (
        f"(b) removed in view leaves within {within:g} s"
        if in_view
        else f"(b') removed out of view leaves within {within:g} s"
    )
    objects_asked = frames_asked = frames_failed = 0
    failing: list[dict[str, Any]] = []
    end = scenario.truth[-1].time if scenario.truth else 0.0
    for oid, info in _objects(scenario).items():
        if info.get("removed") is None or bool(info.get("removed_in_view")) != in_view:
            continue
        removed = float(info["removed"])
        missed = next_view_after(info, removed, step)
        if missed is None or missed + within > end:
            continue  # never looked at again within the run: nothing to conclude
        objects_asked += 1
        last_seen = None
        count = 0
        for frame, state in zip(scenario.truth, worlds, strict=True):
            if frame.time < removed - _EPS or not _published(state, info["position"], radius):
                if frame.time >= missed + within - _EPS:
                    frames_asked += 1
                continue
            last_seen = frame.time
            if frame.time >= missed + within - _EPS:
                frames_asked += 1
                count += 1
        frames_failed += count
        if count:
            still = last_seen is not None and last_seen >= end - _EPS
            latency = None if still else round(float(last_seen or 0.0) - missed, 3)
            failing.append(
                {
                    "object": oid,
                    "time": round(missed + within, 3),
                    "latency_s": latency,
                    "still_published": still,
                    "removed": removed,
                    "next_missed_view": missed,
                    "detail": (
                        f"removed at t={removed:g}, missed view from t={missed:g}, "
                        + ("still published at the end" if still else f"left {latency:.2f} s after")
                    ),
                }
            )
    worst = (
        max(failing, key=lambda f: math.inf if f["latency_s"] is None else f["latency_s"])
        if failing
        else None
    )
    return ViewCheck(name, objects_asked, len(failing), frames_asked, frames_failed, worst)


def leftbehind_checks(scenario: Scenario, worlds: Sequence[WorldState]) -> list[ViewCheck]:
    """Every check of this module on one run: (a), (b), (b') and (c)."""
    return [
        kept_out_of_view(scenario, worlds),
        removed_leaves(scenario, worlds, in_view=True),
        removed_leaves(scenario, worlds, in_view=False),
        kept_unseen_by_other(scenario, worlds),
    ]


def acceptance(scenario: Scenario, worlds: Sequence[WorldState]) -> list[ViewCheck]:
    """Issue 28's acceptance checks for the run's variant: with sensor poses (a) and
    (b); without, (c)."""
    if scenario.metadata.get("poses"):
        return [kept_out_of_view(scenario, worlds), removed_leaves(scenario, worlds)]
    return [kept_unseen_by_other(scenario, worlds)]


# --------------------------------------------------------------------------- views

_ORDER = {"robot": 0, "cam2": 1}


class SensorViews:
    """A world model fed the scenario's sensor views: each robot or cam2 scan goes in
    with its ``SensorReport`` (pose and detector), and every scan without detections is
    posted empty before the next scan or query that follows it in time."""

    def __init__(self, inner: Any, scenario: Scenario) -> None:
        self.inner = inner
        meta = scenario.metadata
        cam2 = [float(v) for v in cast(list[float], meta["cam2_pose"])]
        views: list[tuple[float, int, str, list[float]]] = [
            (float(t), 0, "robot", [float(x), float(y), float(h)])
            for t, x, y, h in cast(list[list[float]], meta["robot_poses"])
        ]
        views += [(float(t), 1, "cam2", cam2) for t in cast(list[float], meta["cam2_times"])]
        views.sort(key=lambda v: (v[0], v[1]))
        self._views = views
        self._next = 0

    def _report(self, view: tuple[float, int, str, list[float]], empty: bool) -> SensorReport:
        t, _, source, pose = view
        detector = "camera" if source == "robot" else "cam2"
        return SensorReport(
            pose=tuple(pose), time=t if empty else None, source=source, detector=detector
        )

    def _post_before(self, key: tuple[float, int]) -> None:
        while self._next < len(self._views) and self._views[self._next][:2] < key:
            self.inner.ingest([], sensor=self._report(self._views[self._next], True))
            self._next += 1

    def ingest(self, detections: Sequence[Detection]) -> Any:
        first = detections[0]
        key = (first.time, _ORDER.get(first.source or "", 2))
        self._post_before(key)
        view = self._views[self._next] if self._next < len(self._views) else None
        if view is not None and abs(view[0] - key[0]) < _EPS and view[1] == key[1]:
            self._next += 1
            return self.inner.ingest(detections, sensor=self._report(view, False))
        return self.inner.ingest(detections)

    def world(self, time: float | None = None) -> WorldState:
        if time is not None:
            self._post_before((time + _EPS, 99))
        state: WorldState = self.inner.world(time=time)
        return state


def with_sensor_views(scenario: Scenario) -> WorldModelFactory:
    """A runner factory (``run_scenario(..., world_model_factory=...)``): a fresh
    ``WorldModel(knowledge, reorder_window=0)`` fed ``scenario``'s sensor views."""
    from semwm.world import WorldModel

    def factory(knowledge: Knowledge) -> WorldModelLike:
        return SensorViews(WorldModel(knowledge, reorder_window=0.0), scenario)

    return factory
