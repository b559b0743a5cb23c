"""A ROS 2 bag's detection topic (and sensor pose topic) as replay records.

The bag is a rosbag2 folder (``metadata.yaml`` and its ``.mcap`` or ``.db3``) or
one ``.mcap`` file, read with ``rosbags`` (no ROS installation). Messages are
decoded with the definitions the bag carries (else :mod:`semwm.ros2.messages`').
"""

from __future__ import annotations

import bisect
import math
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from semwm.knowledge.model import Knowledge
from semwm.persistence.records import Record, batch_record, config_record
from semwm.ros2.classmap import ClassMap
from semwm.ros2.convert import BagReport, Pose, detections_of, pose_of, stamp_seconds
from semwm.ros2.messages import DETECTION3D_ARRAY, DETECTION_ARRAYS, POSE_TYPES, typestore


class BagError(ValueError):
    """The bag cannot be read as asked (no such topic, another type, not a bag)."""


def _open(path: Path) -> Any:
    from rosbags.highlevel import AnyReader, AnyReaderError

    if not path.exists():
        raise BagError(f"{path}: no such file or directory")
    if path.is_file() and path.suffix not in (".mcap", ".db3"):
        raise BagError(f"{path}: not a ROS 2 bag (a rosbag2 folder, .mcap or .db3)")
    try:
        reader = AnyReader([path], default_typestore=typestore())
        reader.open()
    except (AnyReaderError, OSError) as error:
        raise BagError(f"{path}: not a readable ROS 2 bag: {error}") from None
    return reader


def _connections(reader: Any, topic: str, types: tuple[str, ...], path: Path) -> list[Any]:
    found = [c for c in reader.connections if c.topic == topic]
    if not found:
        listed = ", ".join(sorted(f"{c.topic} ({c.msgtype})" for c in reader.connections))
        raise BagError(f"{path}: no topic {topic}; the bag has {listed or 'no topics'}")
    wrong = [c.msgtype for c in found if c.msgtype not in types]
    if wrong:
        raise BagError(f"{path}: {topic} is {wrong[0]}; expected one of {', '.join(types)}")
    return found


def ros2_topics(path: Path) -> list[str] | None:
    """``TOPIC (TYPE)`` of each topic when ``path`` is a ROS 2 bag (a rosbag2 folder, or
    an MCAP file of CDR messages), else ``None``; read without ``rosbags`` (the
    folder's ``metadata.yaml``, the MCAP file's summary), to tell a user who gave a
    bag without ``--ros2-detections`` what it holds."""
    if path.is_dir():
        metadata = path / "metadata.yaml"
        if not metadata.is_file():
            return None
        import yaml

        try:
            info = yaml.safe_load(metadata.read_text(encoding="utf-8"))
            topics = info["rosbag2_bagfile_information"]["topics_with_message_count"]
            return sorted(
                f"{t['topic_metadata']['name']} ({t['topic_metadata']['type']})" for t in topics
            )
        except (yaml.YAMLError, KeyError, TypeError):
            return None
    if path.suffix != ".mcap" or not path.is_file():
        return None
    try:
        from mcap.reader import make_reader

        with path.open("rb") as handle:
            summary = make_reader(handle).get_summary()
    except Exception:  # not MCAP, or no mcap library: not for us to say
        return None
    if summary is None:
        return None
    cdr = [c for c in summary.channels.values() if c.message_encoding == "cdr"]
    if not cdr:
        return None
    schemas = summary.schemas
    return sorted(
        f"{c.topic} ({schemas[c.schema_id].name if c.schema_id in schemas else '?'})" for c in cdr
    )


class PoseTrack:
    """A sensor's poses in time order; :meth:`at` gives the latest at or before a time."""

    def __init__(self, stamped: list[tuple[float, Pose]]) -> None:
        stamped.sort(key=lambda item: item[0])
        self.times = [t for t, _ in stamped]
        self.poses = [p for _, p in stamped]

    def at(self, time: float) -> Pose | None:
        index = bisect.bisect_right(self.times, time) - 1
        return self.poses[index] if index >= 0 else None


def _poses(reader: Any, topic: str, path: Path, report: BagReport) -> PoseTrack:
    stamped: list[tuple[float, Pose]] = []
    for connection, _, raw in reader.messages(_connections(reader, topic, POSE_TYPES, path)):
        try:
            message = reader.deserialize(raw, connection.msgtype)
        except Exception:  # a damaged message: counted, the rest is read
            report.undecodable += 1
            continue
        pose = message.pose.pose if hasattr(message.pose, "pose") else message.pose
        stamped.append((stamp_seconds(message.header.stamp), pose_of(pose)))
    return PoseTrack(stamped)


def bag_records(
    path: Path,
    detections_topic: str,
    knowledge: Knowledge,
    report: BagReport,
    class_map: ClassMap | None = None,
    pose_topic: str | None = None,
    reorder_window: float = 0.5,
) -> Iterator[Record]:
    """A ``config`` record, then one ``batch`` record per detection array with
    detections semwm can use (in the bag's order); ``report`` counts the rest.

    Raises
    ------
    BagError
        When the bag or a topic cannot be read as asked (before any record).
    """
    reader = _open(path)
    try:
        connections = _connections(reader, detections_topic, DETECTION_ARRAYS, path)
        poses = _poses(reader, pose_topic, path, report) if pose_topic else None
        known = set(knowledge.classes)
        dimension = knowledge.world.dimension
        yield config_record(reorder_window)
        newest = -math.inf
        for connection, log_ns, raw in reader.messages(connections):
            try:
                message = reader.deserialize(raw, connection.msgtype)
            except Exception:  # a damaged message: counted, the rest is read
                report.undecodable += 1
                continue
            report.messages += 1
            stamp = stamp_seconds(message.header.stamp) or 1e-9 * log_ns
            if stamp < newest:
                report.out_of_order += 1
                report.most_late = max(report.most_late, newest - stamp)
            newest = max(newest, stamp)
            detections = detections_of(
                message,
                connection.msgtype == DETECTION3D_ARRAY,
                known,
                class_map or {},
                dimension,
                report,
                poses.at if poses is not None else None,
                1e-9 * log_ns,
            )
            if detections:
                yield batch_record(detections)
    finally:
        reader.close()
