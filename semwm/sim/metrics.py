"""Tracking metrics: GOSPA, ID switches, false and missed objects, class accuracy.

Pure functions over plain values: a frame is a list of :class:`Point` (an id, a
class and a position) for the truth and one for the estimates.

GOSPA (Rahmathullah, García-Fernández, Svensson, "Generalized optimal sub-pattern
assignment metric", FUSION 2017) with :math:`\\alpha = 2`:

.. math::

    d_p^{(c, 2)}(X, Y) = \\Big( \\min_{\\gamma} \\sum_{(i, j) \\in \\gamma}
        d(x_i, y_j)^p + \\frac{c^p}{2} \\big(|X| - |\\gamma|\\big)
        + \\frac{c^p}{2} \\big(|Y| - |\\gamma|\\big) \\Big)^{1/p}

where :math:`\\gamma` ranges over assignments of pairs with :math:`d < c`. The
three sums are its parts, reported *before* the :math:`1/p` power (as Stone Soup
does): localisation :math:`\\sum d^p`, missed :math:`c^p/2 \\cdot` (missed truths),
false :math:`c^p/2 \\cdot` (false estimates); with ``p = 1`` they add up to the total.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Hashable, Sequence
from dataclasses import asdict, dataclass, field

import numpy as np
from scipy.optimize import linear_sum_assignment


@dataclass(frozen=True)
class Point:
    """A truth or estimated object in one frame: its id, class and position (m)."""

    id: Hashable
    cls: str
    position: tuple[float, ...]


@dataclass(frozen=True)
class GospaFrame:
    """GOSPA of one frame, its parts and its assignment (truth index, estimate index)."""

    total: float
    localisation: float
    missed: float
    false: float
    n_missed: int
    n_false: int
    assignment: tuple[tuple[int, int], ...]


def _positions(points: Sequence[Point], dim: int) -> np.ndarray:
    array = np.zeros((len(points), dim))
    for i, point in enumerate(points):
        n = min(dim, len(point.position))
        array[i, :n] = point.position[:n]
    return array


def gospa_frame(
    truth: Sequence[Point], estimates: Sequence[Point], *, c: float, p: float = 1.0
) -> GospaFrame:
    """GOSPA (alpha = 2) between the truth and the estimates of one frame.

    Positions of different length are compared on their common leading axes
    (a 3D estimate against 2D truth uses x, y).

    Parameters
    ----------
    c
        Cut-off distance (m): a pair at least this far apart counts as one missed
        and one false object (``c^p/2`` each).
    p
        Order, ``p >= 1``.
    """
    if c <= 0.0 or p < 1.0:
        raise ValueError(f"GOSPA needs c > 0 and p >= 1; got c={c}, p={p}")
    half = c**p / 2.0
    assignment: list[tuple[int, int]] = []
    localisation = 0.0
    if truth and estimates:
        dim = min(min(len(t.position) for t in truth), min(len(e.position) for e in estimates))
        x = _positions(truth, dim)
        y = _positions(estimates, dim)
        distance = np.linalg.norm(x[:, None, :] - y[None, :, :], axis=-1)
        cost = np.minimum(distance, c) ** p
        rows, cols = linear_sum_assignment(cost)
        for i, j in zip(rows, cols, strict=True):
            if distance[i, j] < c:
                assignment.append((int(i), int(j)))
                localisation += float(cost[i, j])
    n_missed = len(truth) - len(assignment)
    n_false = len(estimates) - len(assignment)
    missed = half * n_missed
    false = half * n_false
    total = (localisation + missed + false) ** (1.0 / p)
    return GospaFrame(total, localisation, missed, false, n_missed, n_false, tuple(assignment))


@dataclass(frozen=True)
class GospaSummary:
    """GOSPA averaged over frames (each part averaged separately) with its parameters."""

    c: float
    p: float
    alpha: float
    total: float
    localisation: float
    missed: float
    false: float


@dataclass(frozen=True)
class CountSummary:
    """A per-frame count: its mean over frames and its total."""

    mean: float
    total: int


@dataclass(frozen=True)
class ClassAccuracy:
    """Over all assigned (truth, estimate) pairs of all frames: the fraction whose
    estimated class equals the true one, and the fraction whose classes are
    taxonomy-compatible (one is-a the other)."""

    exact: float | None
    compatible: float | None
    n_assigned: int


@dataclass(frozen=True)
class Metrics:
    """Every metric of a run. ``time_per_detection`` is filled in by the runner."""

    gospa: GospaSummary
    id_switches: int
    false_objects: CountSummary
    missed_objects: CountSummary
    class_accuracy: ClassAccuracy
    n_frames: int
    time_per_detection: dict[str, float] = field(default_factory=dict)

    def to_dict(self) -> dict[str, object]:
        return asdict(self)


def unobserved_floor(
    frames: Sequence[tuple[float, Sequence[Point]]],
    reports: Sequence[tuple[float, Sequence[float]]],
    *,
    c: float,
    p: float = 1.0,
) -> float:
    """The mean GOSPA every tracker pays for objects nothing has reported yet.

    A truth object counts as *unobserved* in a frame (``(time, truth points)``) until a
    report (``(time, position)``: a detection, clutter included) at or before that
    time has come within ``c / 2`` of it (an estimate there would cost less than the
    miss); a report is compared with the truth frame nearest to it in time. Each
    unobserved object is missed, ``c^p / 2``, whatever a tracker does (unless one of
    its estimates lies within ``c / 2`` of an object by chance), so this is the part of
    a mean GOSPA (``p = 1``: over the same frames) that no tracker can remove: a
    ratio of two trackers' GOSPA is pulled towards 1 by it.
    """
    if c <= 0.0 or p < 1.0:
        raise ValueError(f"GOSPA needs c > 0 and p >= 1; got c={c}, p={p}")
    if not frames:
        return 0.0
    times = np.array([time for time, _ in frames])
    first_seen: dict[Hashable, float] = {}
    reach = c / 2.0
    for time, position in reports:
        k = int(np.searchsorted(times, time))
        if k == len(times) or (k > 0 and time - times[k - 1] <= times[k] - time):
            k -= 1
        for point in frames[k][1]:
            n = min(len(point.position), len(position))
            near = math.dist(point.position[:n], tuple(position)[:n]) <= reach
            if near and time < first_seen.get(point.id, math.inf):
                first_seen[point.id] = time
    half = float(c**p) / 2.0
    missed = [
        sum(1 for point in truth if first_seen.get(point.id, math.inf) > time)
        for time, truth in frames
    ]
    return half * float(np.mean(missed))


def count_id_switches(assignments: Sequence[dict[Hashable, Hashable]]) -> int:
    """ID switches over a sequence of frames.

    ``assignments[k]`` maps each assigned truth id to its estimate id in frame k.
    A switch is counted when a truth id is assigned to a different estimate id
    than the last one it was assigned to (frames where it is unassigned, e.g.
    during an occlusion without a track, are skipped, as in CLEAR MOT's IDSW):
    a track lost and re-created under a new id counts one switch.
    """
    last: dict[Hashable, Hashable] = {}
    switches = 0
    for frame in assignments:
        for truth_id, estimate_id in frame.items():
            if truth_id in last and last[truth_id] != estimate_id:
                switches += 1
            last[truth_id] = estimate_id
    return switches


def compute_metrics(
    truth_frames: Sequence[Sequence[Point]],
    estimate_frames: Sequence[Sequence[Point]],
    *,
    c: float,
    p: float = 1.0,
    compatible: Callable[[str, str], bool] | None = None,
) -> Metrics:
    """All metrics over paired frames (``truth_frames[k]`` with ``estimate_frames[k]``).

    ``compatible(estimated_class, true_class)`` decides taxonomy compatibility
    (e.g. :meth:`semwm.knowledge.Taxonomy.compatible`); without it only exact
    matches count as compatible.
    """
    if len(truth_frames) != len(estimate_frames):
        raise ValueError(
            f"need one estimate frame per truth frame; got {len(truth_frames)} truth and "
            f"{len(estimate_frames)} estimate frames"
        )
    same: Callable[[str, str], bool] = compatible or (lambda a, b: a == b)
    frames = [
        gospa_frame(t, e, c=c, p=p) for t, e in zip(truth_frames, estimate_frames, strict=True)
    ]
    n = len(frames)

    def mean(values: Sequence[float]) -> float:
        return float(np.mean(values)) if values else 0.0

    gospa = GospaSummary(
        c=c,
        p=p,
        alpha=2.0,
        total=mean([f.total for f in frames]),
        localisation=mean([f.localisation for f in frames]),
        missed=mean([f.missed for f in frames]),
        false=mean([f.false for f in frames]),
    )
    assignments: list[dict[Hashable, Hashable]] = []
    exact = compatible_count = assigned = 0
    for truth, estimates, frame in zip(truth_frames, estimate_frames, frames, strict=True):
        pairs: dict[Hashable, Hashable] = {}
        for i, j in frame.assignment:
            pairs[truth[i].id] = estimates[j].id
            assigned += 1
            exact += estimates[j].cls == truth[i].cls
            compatible_count += same(estimates[j].cls, truth[i].cls)
        assignments.append(pairs)
    false_total = sum(f.n_false for f in frames)
    missed_total = sum(f.n_missed for f in frames)
    return Metrics(
        gospa=gospa,
        id_switches=count_id_switches(assignments),
        false_objects=CountSummary(false_total / n if n else 0.0, false_total),
        missed_objects=CountSummary(missed_total / n if n else 0.0, missed_total),
        class_accuracy=ClassAccuracy(
            exact=exact / assigned if assigned else None,
            compatible=compatible_count / assigned if assigned else None,
            n_assigned=assigned,
        ),
        n_frames=n,
    )
