"""MCAP recordings: every accepted change and each published world, in the robotics format.

Channels (all ``json`` message encoding with ``jsonschema`` schemas):

========================  ======================  ==========================================
topic                     schema                  message
========================  ======================  ==========================================
``/semwm/detections``     ``semwm.DetectionBatch`` ``{"detections": [...]}``, an accepted batch
``/semwm/control``        ``semwm.Change``         ``{"kind": "knowledge"|"reset"|"config",
                                                  "payload": ...}``
``/semwm/world``          ``semwm.World``          the world published after the change
``/semwm/scene``          ``foxglove.SceneUpdate`` the same world for Foxglove's 3D panel
========================  ======================  ==========================================

``/semwm/detections`` and ``/semwm/control`` together are the journal's records
(their ``sequence`` is the record number), so a recording replays exactly like a
journal. Messages are written unchunked and flushed after each change: a
recording cut short by a crash still reads up to its last whole message.
Needs the ``mcap`` package (``pip install "semwm[mcap]"``).
"""

from __future__ import annotations

import json
import struct
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import IO, Any

from semwm.knowledge.model import Knowledge
from semwm.persistence.records import (
    ReadReport,
    Record,
    batch_parts,
    batch_record,
    config_record,
    knowledge_record,
    payload_text,
)
from semwm.world import WorldModel
from semwm.world_types import WorldState

DETECTIONS = "/semwm/detections"
CONTROL = "/semwm/control"
WORLD = "/semwm/world"
SCENE = "/semwm/scene"

_NUMBER_LIST = {"type": "array", "items": {"type": "number"}}
_DETECTION = {
    "type": "object",
    "properties": {
        "time": {"type": "number"},
        "class": {"type": "string"},
        "position": _NUMBER_LIST,
        "covariance": {"type": "array", "items": _NUMBER_LIST},
        "source": {"type": "string"},
        "detector": {"type": "string"},
        "label": {"type": "string"},
        "sensor_position": _NUMBER_LIST,
        "time_std": {"type": "number"},
    },
    "required": ["time", "class", "position"],
}
_VEC3 = {
    "type": "object",
    "properties": {k: {"type": "number"} for k in "xyz"},
}
_POSE = {
    "type": "object",
    "properties": {
        "position": _VEC3,
        "orientation": {"type": "object", "properties": {k: {"type": "number"} for k in "xyzw"}},
    },
}
_COLOR = {"type": "object", "properties": {k: {"type": "number"} for k in "rgba"}}
_TIME = {
    "type": "object",
    "properties": {"sec": {"type": "integer"}, "nsec": {"type": "integer"}},
}
SCHEMAS: dict[str, dict[str, Any]] = {
    "semwm.DetectionBatch": {
        "title": "semwm.DetectionBatch",
        "description": "Detections accepted together by POST /detections",
        "type": "object",
        "properties": {
            "detections": {"type": "array", "items": _DETECTION},
            "sensor": {"type": "object", "description": "where the scan's sensor looked"},
        },
        "required": ["detections"],
    },
    "semwm.Change": {
        "title": "semwm.Change",
        "description": "A knowledge replacement, a reset, a reorder-window change or an action",
        "type": "object",
        "properties": {
            "kind": {"type": "string", "enum": ["knowledge", "reset", "config", "action"]},
            "payload": {},
        },
        "required": ["kind", "payload"],
    },
    "semwm.World": {
        "title": "semwm.World",
        "description": "The published world, as GET /world answers",
        "type": "object",
        "properties": {
            "time": {"type": ["number", "null"]},
            "objects": {"type": "array", "items": {"type": "object"}},
        },
        "required": ["time", "objects"],
    },
    # The fields of Foxglove's SceneUpdate (docs.foxglove.dev, "SceneUpdate") that
    # semwm fills: one entity per object, a sphere and a text label.
    "foxglove.SceneUpdate": {
        "title": "foxglove.SceneUpdate",
        "description": "An update to the entities displayed in a 3D scene",
        "type": "object",
        "properties": {
            "deletions": {
                "type": "array",
                "items": {
                    "type": "object",
                    "properties": {
                        "timestamp": _TIME,
                        "type": {"type": "integer"},
                        "id": {"type": "string"},
                    },
                },
            },
            "entities": {
                "type": "array",
                "items": {
                    "type": "object",
                    "properties": {
                        "timestamp": _TIME,
                        "frame_id": {"type": "string"},
                        "id": {"type": "string"},
                        "lifetime": _TIME,
                        "frame_locked": {"type": "boolean"},
                        "metadata": {
                            "type": "array",
                            "items": {
                                "type": "object",
                                "properties": {
                                    "key": {"type": "string"},
                                    "value": {"type": "string"},
                                },
                            },
                        },
                        "spheres": {
                            "type": "array",
                            "items": {
                                "type": "object",
                                "properties": {"pose": _POSE, "size": _VEC3, "color": _COLOR},
                            },
                        },
                        "texts": {
                            "type": "array",
                            "items": {
                                "type": "object",
                                "properties": {
                                    "pose": _POSE,
                                    "billboard": {"type": "boolean"},
                                    "font_size": {"type": "number"},
                                    "scale_invariant": {"type": "boolean"},
                                    "color": _COLOR,
                                    "text": {"type": "string"},
                                },
                            },
                        },
                    },
                },
            },
        },
    },
}
TOPICS: dict[str, str] = {
    DETECTIONS: "semwm.DetectionBatch",
    CONTROL: "semwm.Change",
    WORLD: "semwm.World",
    SCENE: "foxglove.SceneUpdate",
}
FRAME = "world"


def _stamp(seconds: float) -> dict[str, int]:
    whole = int(seconds // 1)
    return {"sec": max(whole, 0), "nsec": max(round((seconds - whole) * 1e9), 0) % 10**9}


def scene_update(state: WorldState) -> dict[str, Any]:
    """``state`` as a Foxglove ``SceneUpdate``: delete all, then one entity per object
    (a sphere sized by the position standard deviation, a text with id and class)."""
    stamp = _stamp(state.time or 0.0)
    entities = []
    for obj in state.objects:
        x, y, *rest = obj.position
        z = rest[0] if rest else 0.0
        sigma = max(max(obj.covariance[i][i] for i in range(len(obj.position))) ** 0.5, 0.05)
        pose = {
            "position": {"x": x, "y": y, "z": z},
            "orientation": {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0},
        }
        text = f"{obj.id} {obj.cls}" + (f" [{obj.label}]" if obj.label else "")
        entities.append(
            {
                "timestamp": stamp,
                "frame_id": FRAME,
                "id": str(obj.id),
                "lifetime": {"sec": 0, "nsec": 0},
                "frame_locked": False,
                "metadata": [
                    {"key": "class", "value": obj.cls},
                    {"key": "existence", "value": f"{obj.existence:.3f}"},
                ],
                "spheres": [
                    {
                        "pose": pose,
                        "size": {"x": 2 * sigma, "y": 2 * sigma, "z": 2 * sigma},
                        "color": {"r": 0.2, "g": 0.5, "b": 1.0, "a": 0.3 + 0.7 * obj.existence},
                    }
                ],
                "texts": [
                    {
                        "pose": pose,
                        "billboard": True,
                        "font_size": 14.0,
                        "scale_invariant": True,
                        "color": {"r": 1.0, "g": 1.0, "b": 1.0, "a": 1.0},
                        "text": text,
                    }
                ],
            }
        )
    return {"deletions": [{"timestamp": stamp, "type": 1, "id": ""}], "entities": entities}


class McapRecorder:
    """Writes changes and published worlds to an MCAP file; a change hook of the service.

    Parameters
    ----------
    handle
        The binary file to write.
    model
        Returns the world model (called after each change, with the service's lock held).
    clock
        Log time of each message (s); wall time by default, scenario time for
        ``semwm record SCENARIO``. Log times are made strictly increasing.
    """

    def __init__(
        self,
        handle: IO[bytes],
        model: Callable[[], WorldModel],
        clock: Callable[[], float] = time.time,
    ) -> None:
        from mcap.writer import Writer

        self._handle = handle
        self._model = model
        self._clock = clock
        self._writer = Writer(handle, use_chunking=False)
        self._writer.start(profile="", library="semwm")
        self._channels: dict[str, int] = {}
        for topic, schema_name in TOPICS.items():
            schema_id = self._writer.register_schema(
                name=schema_name,
                encoding="jsonschema",
                data=json.dumps(SCHEMAS[schema_name]).encode(),
            )
            self._channels[topic] = self._writer.register_channel(
                topic=topic, message_encoding="json", schema_id=schema_id
            )
        self._last_ns = 0
        self._sequence = 0
        self._closed = False

    @classmethod
    def create(
        cls,
        path: Path,
        model: Callable[[], WorldModel],
        clock: Callable[[], float] = time.time,
    ) -> McapRecorder:
        return cls(Path(path).open("wb"), model, clock)

    def start(self, knowledge: Knowledge, reorder_window: float, hold: float = 0.0) -> None:
        """Write the settings and knowledge the recording starts from."""
        for record in (config_record(reorder_window, hold), knowledge_record(knowledge)):
            self.write_change(record)
        self._handle.flush()

    def _write(self, topic: str, data: Any, at: float | None = None) -> None:
        now = int((at if at is not None else self._clock()) * 1e9)
        self._last_ns = max(now, self._last_ns + 1)
        self._writer.add_message(
            channel_id=self._channels[topic],
            log_time=self._last_ns,
            data=payload_text(data).encode(),
            publish_time=self._last_ns,
            sequence=self._sequence,
        )

    def write_change(self, record: Record) -> None:
        """Write one change (a journal record) on its channel."""
        self._sequence += 1
        if record.kind == "batch":
            detections, sensor = batch_parts(record.payload)
            batch = {"detections": detections} | ({"sensor": sensor} if sensor else {})
            self._write(DETECTIONS, batch)
        else:
            self._write(CONTROL, {"kind": record.kind, "payload": record.payload})

    def write_world(self, state: WorldState) -> None:
        """Write the published world on ``/semwm/world`` and ``/semwm/scene``."""
        self._write(WORLD, state.to_dict())
        self._write(SCENE, scene_update(state))

    @contextmanager
    def applying(self, record: Record) -> Iterator[None]:
        """Change hook: after an accepted change, write it and the world it published."""
        yield
        self.write_change(record)
        if record.kind != "config":
            self.write_world(self._model().world())
        self._handle.flush()

    def close(self) -> None:
        if not self._closed:
            self._closed = True
            self._writer.finish()  # type: ignore[no-untyped-call]
            self._handle.close()


def read_recording(path: Path, report: ReadReport | None = None) -> Iterator[Record]:
    """The changes of a recording as journal records, in order.

    Stops at a torn or damaged end (a recording cut by a crash) and says so in
    ``report.problem``.
    """
    from mcap.exceptions import McapError
    from mcap.records import Channel, Message
    from mcap.stream_reader import StreamReader

    report = report if report is not None else ReadReport()
    topics: dict[int, str] = {}
    with Path(path).open("rb") as handle:
        reader = StreamReader(handle, skip_magic=False)
        try:
            for item in reader.records:
                if isinstance(item, Channel):
                    topics[item.id] = item.topic
                elif isinstance(item, Message):
                    topic = topics.get(item.channel_id)
                    if topic not in (DETECTIONS, CONTROL):
                        continue
                    data = json.loads(item.data)
                    report.records += 1
                    if topic == DETECTIONS:
                        sensor = data.get("sensor")
                        payload = batch_record(data["detections"], sensor).payload
                        yield Record(item.sequence, "batch", payload)
                    else:
                        yield Record(item.sequence, data["kind"], data["payload"])
        except (McapError, EOFError, ValueError, KeyError, struct.error) as error:
            report.problem = (
                f"{path}: recording ends early after {report.records} change(s) "
                f"({type(error).__name__}: {error}); read up to there"
            )


def recording_summary(path: Path) -> dict[str, str]:
    """Topic -> schema name of each channel, from the file's summary (``mcap`` reader)."""
    from mcap.reader import make_reader

    with Path(path).open("rb") as handle:
        summary = make_reader(handle).get_summary()
    if summary is None:
        return {}
    return {c.topic: summary.schemas[c.schema_id].name for c in summary.channels.values()}
