"""Turning user detections into MHF measurements, or saying exactly what is wrong."""

from __future__ import annotations

import functools
import math
from collections.abc import Iterable, Mapping
from typing import TYPE_CHECKING, Any, NamedTuple

import numpy as np
from pydantic import TypeAdapter, ValidationError
from scipy.special import chdtri

from semwm.detection import MAX_TIME, MAX_TIME_STD, Detection, DetectionError, DetectionProblem
from semwm.filters.factory import FilterFactory
from semwm.knowledge.model import Knowledge
from semwm.mhf.measurement import Measurement

if TYPE_CHECKING:
    from semwm import _core
    from semwm.mhf.core_engine import CoreEngine

DetectionInput = Detection | Mapping[str, Any]
_new_tuple = tuple.__new__


class ClassesHeld(ValueError):
    """New knowledge lacks classes that tracked objects hold; nothing was changed.

    ``held`` maps each such class to the ids of its published objects (``None``
    stands for unpublished ones)."""

    def __init__(self, held: Mapping[str, set[int | None]]) -> None:
        self.held = {cls: set(ids) for cls, ids in held.items()}
        super().__init__(f"tracked objects hold classes the knowledge lacks: {sorted(self.held)}")


def as_batch(detections: DetectionInput | Iterable[DetectionInput]) -> list[DetectionInput]:
    """One detection or an iterable of them, as a list."""
    if type(detections) is list:  # the common batch, without the Mapping ABC's check
        return list(detections)
    if isinstance(detections, Detection | Mapping):
        return [detections]
    return list(detections)


_DETECTIONS: TypeAdapter[list[Detection]] = TypeAdapter(list[Detection])


def parse(batch: list[DetectionInput]) -> list[Detection]:
    """Parse dicts into :class:`Detection` values; every problem is collected.

    A batch of several is validated in one call (``Detection`` values pass through
    as they are); only a batch with a problem is walked again one item at a time, to
    report each problem with its index and field.
    """
    if len(batch) > 1:
        try:
            return _DETECTIONS.validate_python(batch)
        except ValidationError:
            pass  # find every problem, with its index, below
    problems: list[DetectionProblem] = []
    parsed: list[Detection] = []
    for index, item in enumerate(batch):
        if isinstance(item, Detection):
            parsed.append(item)
            continue
        try:
            parsed.append(Detection.model_validate(item))
        except ValidationError as error:
            for e in error.errors():
                loc = tuple("class" if p == "cls" else p for p in e["loc"])
                problems.append(DetectionProblem(path=(index, *loc), message=e["msg"]))
    if problems:
        raise DetectionError(problems)
    return parsed


def _square_problem(matrix: tuple[tuple[float, ...], ...], d: int, what: str) -> str | None:
    if len(matrix) != d or any(len(row) != d for row in matrix):
        lengths = ", ".join(str(len(row)) for row in matrix)
        return f"{what} must be {d} x {d}; found {len(matrix)} rows of lengths {lengths or 'none'}"
    array = np.asarray(matrix, dtype=float)
    if array.shape != (d, d):
        return f"{what} must be {d} x {d}; found shape {array.shape}"
    if not np.allclose(array, array.T, rtol=1e-9, atol=1e-12):
        return f"{what} must be symmetric"
    if np.linalg.eigvalsh(array).min() <= 0.0:
        return f"{what} must be positive definite"
    return None


def check(
    detections: list[Detection], knowledge: Knowledge, factory: FilterFactory, first_seq: int
) -> list[Measurement]:
    """Check detections against the knowledge and resolve their noise and clutter rates.

    Raises
    ------
    DetectionError
        With the path (index in the batch, field) and message of every problem.
    """
    d = knowledge.world.dimension
    problems: list[DetectionProblem] = []
    measurements: list[Measurement] = []
    classes, detectors = knowledge.classes, knowledge.detectors
    default_detector = knowledge.default_detector
    pairs: dict[tuple[str, str], _Resolved] = {}  # once per (class, detector) a batch
    append = measurements.append
    for index, det in enumerate(detections):
        detector = det.detector if det.detector is not None else default_detector
        cls = det.cls
        sensor = det.sensor_position
        if (  # the common case, nothing to report: no problem list, no closure
            det.covariance is None
            and cls in classes
            and detector in detectors
            and len(det.position) == d
            and (sensor is None or len(sensor) == d)
        ):
            if not problems:
                pair = pairs.get((cls, detector))
                if pair is None:
                    pair = pairs[cls, detector] = _resolved(cls, detector, knowledge, factory)
                append(_measurement(det, first_seq + index, detector, pair))
            continue
        found: list[DetectionProblem] = []

        def problem(
            field: str, message: str, found: list[DetectionProblem] = found, index: int = index
        ) -> None:
            found.append(DetectionProblem(path=(index, field), message=message))

        if det.cls not in knowledge.classes:
            known_classes = ", ".join(sorted(knowledge.classes))
            problem("class", f"unknown class {det.cls!r}; known classes: {known_classes}")
        if len(det.position) != d:
            problem("position", f"position must have {d} coordinates; found {len(det.position)}")
        detector = det.detector if det.detector is not None else knowledge.default_detector
        if detector not in knowledge.detectors:
            known_detectors = ", ".join(knowledge.detectors)
            problem(
                "detector", f"unknown detector {detector!r}; known detectors: {known_detectors}"
            )
        if det.covariance is not None:
            message = _square_problem(det.covariance, d, "covariance")
            if message is not None:
                problem("covariance", message)
        if det.sensor_position is not None and len(det.sensor_position) != d:
            problem(
                "sensor_position",
                f"sensor position must have {d} coordinates; found {len(det.sensor_position)}",
            )
        if found:
            problems.extend(found)
            continue
        pair = _resolved(det.cls, detector, knowledge, factory)
        if det.covariance is not None:
            pair = pair._replace(R=np.asarray(det.covariance, dtype=float))
        measurements.append(_measurement(det, first_seq + index, detector, pair))
    if problems:
        raise DetectionError(problems)
    return measurements


class _Resolved(NamedTuple):
    """What a (class, detector) pair gives each of its detections."""

    R: np.ndarray  # the measurement noise (shared, read-only)
    trust_labels: bool  # paper 004: foreign-controlled objects are tracked from observation only
    clutter_rate: float


def _resolved(cls: str, detector: str, knowledge: Knowledge, factory: FilterFactory) -> _Resolved:
    """The noise, label trust and clutter rate of a (class, detector) pair."""
    return _Resolved(
        factory.measurement_noise(cls, detector),
        knowledge.classes[cls].trust_labels,
        knowledge.detectors[detector].clutter_frequency,
    )


def _measurement(det: Detection, seq: int, detector: str, pair: _Resolved) -> Measurement:
    """A checked detection with its noise and clutter rate resolved (the named tuple made
    as its own ``__new__`` makes it, without that Python-level call: once per detection)."""
    sensor = det.sensor_position
    return _new_tuple(
        Measurement,
        (
            seq,
            det.time,
            det.cls,
            np.array(det.position, dtype=float),
            pair.R,
            detector,
            det.source,
            det.label if pair.trust_labels else None,
            pair.clutter_rate,
            None if sensor is None else np.array(sensor, dtype=float),
            det.time_std or 0.0,
        ),
    )


def core_reader(
    knowledge: Knowledge, factory: FilterFactory, engine: CoreEngine
) -> _core.DetectionReader:
    """The Rust engine's reader of plain batches (``core/src/python/reader.rs``): what
    :func:`parse`, :func:`check` and ``WorldModel._placed`` make of a batch whose every
    detection is plain, in one pass (its ``read`` answers ``None`` for any other batch,
    which then takes the specification's path). It is handed what this module computes:
    each (class, detector) pair's :func:`_resolved` values, its detector's range and
    :func:`region_bounds` for its noise, the gate of :func:`out_of_range`'s margin, and
    the indices of ``engine``'s tables, for which it reads each scan's rows (a
    ``semwm._core.Scan``)."""
    from semwm import _core

    pairs: dict[tuple[str, str], Any] = {}
    p = knowledge.world.gate_probability
    gate = _line_of_sight_gate(p) if p < 1.0 else None  # out_of_range's margin
    for cls in knowledge.classes:
        for detector, spec in knowledge.detectors.items():
            pair = _resolved(cls, detector, knowledge, factory)
            bounds = region_bounds(knowledge, pair.R)
            pairs[cls, detector] = (
                pair.R,
                pair.trust_labels,
                float(pair.clutter_rate),
                None if spec.range is None else float(spec.range),
                bounds,
                engine.index[cls],
                engine.detectors[detector],
                gate,
            )
    return _core.DetectionReader(
        engine.engine,
        Measurement,
        Detection,
        knowledge.world.dimension,
        MAX_TIME,
        MAX_TIME_STD,
        knowledge.default_detector,
        pairs,
    )


def out_of_range(det: Detection, knowledge: Knowledge, R: np.ndarray | None = None) -> bool:
    r"""Paper 000 C2: the detection lies outside its detector's range from the sensor.

    ``range`` bounds where the detector sees an *object*; the position it reports
    carries the measurement noise ``R``, so an object just inside the range is
    reported beyond it about half the time. Cutting at ``range`` itself would drop
    those reports and bias every object near the edge of view towards the sensor.
    With ``R`` the cut is at the range plus the gate's quantile of the noise along
    the line of sight (:math:`u` the unit vector from the sensor, :math:`\gamma` the
    one-dimensional chi-square quantile of ``world.gate_probability``):

    .. math:: \lVert z - s \rVert > r + \sqrt{\gamma\, u^\top R\, u}
    """
    detector = knowledge.detectors[det.detector or knowledge.default_detector]
    if detector.range is None or det.sensor_position is None:
        return False
    offset = [float(a) - float(b) for a, b in zip(det.position, det.sensor_position, strict=True)]
    squared = 0.0
    for value in offset:
        squared += value * value
    distance = math.sqrt(squared)  # what np.linalg.norm computes
    if distance <= detector.range:
        return False  # within the range itself: whatever the margin (>= 0)
    margin = 0.0
    p = knowledge.world.gate_probability
    if R is not None and distance > 0.0 and p < 1.0:
        d = min(len(offset), R.shape[0])
        u = [value / distance for value in offset[:d]]
        rows = R[:d, :d].tolist()
        # (u R) u, in numpy's order
        w = [sum(u[i] * rows[i][j] for i in range(d)) for j in range(d)]
        spread = sum(w[j] * u[j] for j in range(d))
        margin = math.sqrt(_line_of_sight_gate(p) * max(spread, 0.0))
    return distance > detector.range + margin


def outside_region(det: Detection, knowledge: Knowledge, R: np.ndarray) -> bool:
    r"""Whether the detection lies clearly outside the knowledge's region: beyond an edge
    by more than its noise at the gate's one-dimensional quantile on that axis (the
    region is a soft fact: :func:`semwm.mhf.existence.inside_probability`),

    .. math:: z_i < a_i - \sqrt{\gamma R_{ii}} \;\text{or}\; z_i > b_i + \sqrt{\gamma R_{ii}}

    No sensor sees an object there, so it is no evidence about the world; a unit or a
    frame mistake (millimetres for metres, odom for map) usually puts detections there.
    """
    region = knowledge.world.region
    if region is None:
        return False
    p = knowledge.world.gate_probability
    gamma = _line_of_sight_gate(p) if p < 1.0 else 0.0
    for axis, (low, high) in enumerate(region):
        value = float(det.position[axis])
        margin = math.sqrt(gamma * max(float(R[axis, axis]), 0.0))
        if value < low - margin or value > high + margin:
            return True
    return False


def region_bounds(knowledge: Knowledge, R: np.ndarray) -> tuple[list[float], list[float]] | None:
    """Per axis, the lowest and highest position :func:`outside_region` keeps for a
    detection with noise ``R`` (the region widened by the noise at the gate's quantile);
    ``None`` without a region."""
    region = knowledge.world.region
    if region is None:
        return None
    p = knowledge.world.gate_probability
    gamma = _line_of_sight_gate(p) if p < 1.0 else 0.0
    margins = [math.sqrt(gamma * max(float(R[axis, axis]), 0.0)) for axis in range(len(region))]
    return (
        [low - m for (low, _), m in zip(region, margins, strict=True)],
        [high + m for (_, high), m in zip(region, margins, strict=True)],
    )


@functools.lru_cache(maxsize=16)
def _line_of_sight_gate(p: float) -> float:
    """The one-dimensional chi-square quantile of ``p`` (once per gate probability)."""
    return float(chdtri(1, 1.0 - p))
