"""A ``vision_msgs`` detection array -> semwm detections, and what could not be used.

Each ``Detection3D`` (or ``Detection2D``) becomes one detection:

* **class**: the best-scored of ``results[].hypothesis.class_id`` that names a
  knowledge class (through the class map). A semwm detection has one class, so the
  other scored classes are not used (counted: ``other_scores``);
* **position and covariance**: that result's ``pose`` (``PoseWithCovariance``,
  metres, the 6 x 6 covariance's position block); a 3-D detection whose result
  pose is all zeros takes its ``bbox.center``. A covariance of all zeros (not
  filled in) or one that is not positive definite is left out, so the class's
  ``measurement_noise`` applies (counted);
* **time**: the detection's ``header.stamp``, else the array's (s), else (no stamp
  at all) the bag's log time (counted);
* **source**: the ``header.frame_id`` (the array's, else the detection's);
* with a sensor pose (``--ros2-pose``) the position is in the sensor's frame: it
  is moved into the world frame by the latest pose at or before its time
  (``p = R p_s + t``, ``C = R C_s R^T``) and ``sensor_position`` is ``t``.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from semwm.ros2.classmap import ClassMap

Pose = tuple[np.ndarray, np.ndarray]
"""A sensor pose: rotation ``R`` (3 x 3) and translation ``t`` (3,), world from sensor."""

PoseAt = Callable[[float], Pose | None]
"""The sensor pose at a time (``None`` before the first one)."""


@dataclass
class BagReport:
    """What a bag gave, and every detection or message that could not be used."""

    messages: int = 0
    detections: int = 0
    used: int = 0
    unknown_classes: Counter[str] = field(default_factory=Counter)
    dropped_classes: Counter[str] = field(default_factory=Counter)
    no_results: int = 0
    no_position: int = 0
    no_pose: int = 0
    zero_covariance: int = 0
    bad_covariance: int = 0
    other_scores: int = 0
    out_of_order: int = 0
    most_late: float = 0.0
    undecodable: int = 0
    no_stamp: int = 0

    def lines(self) -> list[str]:
        """The report, one line per kind of problem found (none when all was used)."""
        out: list[str] = []
        if self.unknown_classes:
            listed = ", ".join(f"{name!r} x{n}" for name, n in self.unknown_classes.most_common())
            out.append(
                f"{sum(self.unknown_classes.values())} detections of classes the knowledge "
                f"has not, left out: {listed} (map them to classes with --class-map FILE)"
            )
        if self.dropped_classes:
            listed = ", ".join(f"{name!r} x{n}" for name, n in self.dropped_classes.most_common())
            out.append(
                f"{sum(self.dropped_classes.values())} detections of classes the class map "
                f"drops: {listed}"
            )
        if self.no_results:
            out.append(f"{self.no_results} detections without results[] (no class), left out")
        if self.no_position:
            out.append(
                f"{self.no_position} 2-D detections without a pose in results[] (an image "
                "box is no position), left out"
            )
        if self.no_pose:
            out.append(f"{self.no_pose} detections before the first sensor pose, left out")
        if self.zero_covariance:
            out.append(
                f"{self.zero_covariance} detections with an all-zero covariance (not filled "
                "in): their class's measurement_noise used"
            )
        if self.bad_covariance:
            out.append(
                f"{self.bad_covariance} detections whose covariance is not positive "
                "definite: their class's measurement_noise used"
            )
        if self.other_scores:
            out.append(
                f"{self.other_scores} detections scored more than one known class: the "
                "best-scored one used (a semwm detection has one class)"
            )
        if self.out_of_order:
            out.append(
                f"{self.out_of_order} messages stamped before an earlier one (up to "
                f"{self.most_late:.3f} s); later than the reorder window they are refused"
            )
        if self.undecodable:
            out.append(f"{self.undecodable} messages could not be decoded, left out")
        if self.no_stamp:
            out.append(
                f"{self.no_stamp} messages without a header stamp (0): the bag's log time used"
            )
        return out

    def to_dict(self) -> dict[str, Any]:
        return {
            "messages": self.messages,
            "detections": self.detections,
            "used": self.used,
            "unknown_classes": dict(self.unknown_classes),
            "dropped_classes": dict(self.dropped_classes),
            "no_results": self.no_results,
            "no_position": self.no_position,
            "no_pose": self.no_pose,
            "zero_covariance": self.zero_covariance,
            "bad_covariance": self.bad_covariance,
            "other_scores": self.other_scores,
            "out_of_order": self.out_of_order,
            "most_late_s": self.most_late,
            "undecodable": self.undecodable,
            "no_stamp": self.no_stamp,
        }


def stamp_seconds(stamp: Any) -> float:
    """A ``builtin_interfaces/Time`` in seconds."""
    return float(stamp.sec) + 1e-9 * float(stamp.nanosec)


def rotation(q: Any) -> np.ndarray:
    """The rotation matrix of a unit quaternion ``(x, y, z, w)`` (normalised first;
    all zeros, an unfilled orientation, is the identity)."""
    x, y, z, w = float(q.x), float(q.y), float(q.z), float(q.w)
    norm = np.sqrt(x * x + y * y + z * z + w * w)
    if norm == 0.0:
        return np.eye(3)
    x, y, z, w = x / norm, y / norm, z / norm, w / norm
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def pose_of(pose: Any) -> Pose:
    """A ``geometry_msgs/Pose`` as ``(R, t)``."""
    p = pose.position
    return rotation(pose.orientation), np.array([float(p.x), float(p.y), float(p.z)])


def _choose(
    results: Any, known: set[str], class_map: ClassMap, report: BagReport
) -> tuple[Any, str] | None:
    """The best-scored result naming a known class, and that class."""
    candidates: list[tuple[float, int, Any, str]] = []
    unknown: list[tuple[float, str]] = []
    dropped: list[tuple[float, str]] = []
    for index, result in enumerate(results):
        class_id = str(result.hypothesis.class_id)
        score = float(result.hypothesis.score)
        mapped = class_map.get(class_id, class_id)
        if mapped is None:
            dropped.append((score, class_id))
        elif mapped in known:
            candidates.append((-score, index, result, mapped))
        else:
            unknown.append((score, class_id))
    if not candidates:
        if unknown:
            report.unknown_classes[max(unknown)[1]] += 1
        elif dropped:
            report.dropped_classes[max(dropped)[1]] += 1
        return None
    candidates.sort(key=lambda c: (c[0], c[1]))
    if len({c[3] for c in candidates}) > 1:
        report.other_scores += 1
    _, _, result, cls = candidates[0]
    return result, cls


def detections_of(
    message: Any,
    three_d: bool,
    known: set[str],
    class_map: ClassMap,
    dimension: int,
    report: BagReport,
    pose_at: PoseAt | None = None,
    log_time: float | None = None,
) -> list[dict[str, Any]]:
    """The semwm detections (``POST /detections`` dicts) of one detection array; an
    array without a stamp (0) takes ``log_time`` (the bag's, s) when given."""
    array_time = stamp_seconds(message.header.stamp)
    if array_time == 0.0 and log_time is not None:
        array_time = log_time
        report.no_stamp += 1
    array_frame = str(message.header.frame_id)
    out: list[dict[str, Any]] = []
    for detection in message.detections:
        report.detections += 1
        if not len(detection.results):
            report.no_results += 1
            continue
        chosen = _choose(detection.results, known, class_map, report)
        if chosen is None:
            continue
        result, cls = chosen
        own_time = stamp_seconds(detection.header.stamp)
        time = own_time if own_time > 0.0 else array_time
        source = array_frame or str(detection.header.frame_id) or "ros2"
        position = np.array(
            [
                float(result.pose.pose.position.x),
                float(result.pose.pose.position.y),
                float(result.pose.pose.position.z),
            ]
        )
        covariance = np.asarray(result.pose.covariance, dtype=float).reshape(6, 6)[:3, :3]
        if not position.any():
            if three_d and hasattr(detection.bbox.center, "position"):
                center = detection.bbox.center.position
                position = np.array([float(center.x), float(center.y), float(center.z)])
            elif not covariance.any():
                report.no_position += 1
                continue
        item: dict[str, Any] = {"time": time, "class": cls, "source": source}
        if pose_at is not None:
            pose = pose_at(time)
            if pose is None:
                report.no_pose += 1
                continue
            r, t = pose
            position = r @ position + t
            covariance = r @ covariance @ r.T
            item["sensor_position"] = [float(v) for v in t[:dimension]]
        item["position"] = [float(v) for v in position[:dimension]]
        block = covariance[:dimension, :dimension]
        if not block.any():
            report.zero_covariance += 1
        elif not _positive_definite(block):
            report.bad_covariance += 1
        else:
            block = (block + block.T) / 2.0
            item["covariance"] = [[float(v) for v in row] for row in block]
        report.used += 1
        out.append(item)
    return out


def _positive_definite(matrix: np.ndarray) -> bool:
    if not np.all(np.isfinite(matrix)) or not np.allclose(matrix, matrix.T, atol=1e-12):
        return False
    return bool(np.linalg.eigvalsh(matrix).min() > 0.0)
