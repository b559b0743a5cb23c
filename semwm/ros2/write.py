"""Published worlds -> a ROS 2 bag of ``vision_msgs/msg/Detection3DArray``.

One message per published world on ``/semwm/world`` (log time and stamp = the
world's time; frame ``world``), one ``Detection3D`` per object:

* ``id``: the object's id (text);
* ``results[]``: one hypothesis per class, ``score`` = existence x class
  probability (the scores sum to the existence; an object without class
  probabilities has one result, its class), each with the object's ``pose``
  (position; the 6 x 6 covariance holds the position covariance, the rest 0);
* ``bbox``: centred on the object, ``size`` = 2 sigma per axis (0 for an axis
  the world has not).

Written as a rosbag2 folder with MCAP storage (``rosbags``), which ROS 2 tools
(``ros2 bag info``/``play``) and Foxglove open.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from semwm.ros2.messages import DETECTION3D_ARRAY, typestore
from semwm.world_types import WorldObject, WorldState

WORLD_TOPIC = "/semwm/world"


class Ros2WorldWriter:
    """Writes each world given to :meth:`write` as one ``Detection3DArray``."""

    def __init__(self, path: Path, topic: str = WORLD_TOPIC, frame_id: str = "world") -> None:
        from rosbags.rosbag2 import StoragePlugin, Writer

        self.store = typestore()
        self.frame_id = frame_id
        self.writer = Writer(path, version=9, storage_plugin=StoragePlugin.MCAP)
        self.writer.open()
        self.connection = self.writer.add_connection(topic, DETECTION3D_ARRAY, typestore=self.store)
        self.count = 0

    def write(self, state: WorldState) -> None:
        """The world as one message (a world without a time yet is not written)."""
        if state.time is None:
            return
        message = self.message(state)
        data = self.store.serialize_cdr(message, DETECTION3D_ARRAY)
        self.writer.write(self.connection, round(state.time * 1e9), data)
        self.count += 1

    def message(self, state: WorldState) -> Any:
        assert state.time is not None
        types = self.store.types
        sec = math.floor(state.time)
        stamp = types["builtin_interfaces/msg/Time"](
            sec=int(sec), nanosec=min(round((state.time - sec) * 1e9), 999_999_999)
        )
        header = types["std_msgs/msg/Header"](stamp=stamp, frame_id=self.frame_id)
        detections = [self._detection(obj, header) for obj in state.objects]
        return types[DETECTION3D_ARRAY](header=header, detections=detections)

    def _detection(self, obj: WorldObject, header: Any) -> Any:
        types = self.store.types
        xyz = [*obj.position[:3], *[0.0] * (3 - len(obj.position[:3]))]
        d = min(len(obj.position), 3)
        covariance = np.zeros((6, 6))
        covariance[:d, :d] = np.asarray(obj.covariance, dtype=float)[:d, :d]
        point = types["geometry_msgs/msg/Point"](x=xyz[0], y=xyz[1], z=xyz[2])
        identity = types["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0)
        pose = types["geometry_msgs/msg/Pose"](position=point, orientation=identity)
        with_covariance = types["geometry_msgs/msg/PoseWithCovariance"](
            pose=pose, covariance=covariance.reshape(36)
        )
        classes = obj.class_probabilities or {obj.cls: 1.0}
        results = [
            types["vision_msgs/msg/ObjectHypothesisWithPose"](
                hypothesis=types["vision_msgs/msg/ObjectHypothesis"](
                    class_id=cls, score=float(obj.existence * p)
                ),
                pose=with_covariance,
            )
            for cls, p in sorted(classes.items(), key=lambda item: -item[1])
        ]
        sigma = [2.0 * math.sqrt(max(covariance[i, i], 0.0)) for i in range(3)]
        size = types["geometry_msgs/msg/Vector3"](x=sigma[0], y=sigma[1], z=sigma[2])
        bbox = types["vision_msgs/msg/BoundingBox3D"](center=pose, size=size)
        return types["vision_msgs/msg/Detection3D"](
            header=header, results=results, bbox=bbox, id=str(obj.id)
        )

    def close(self) -> None:
        self.writer.close()
