"""Write a small ROS 2 bag like a robot's, for docs/ros2.md's worked example.

A robot drives along y = 0.5 m at 0.2 m/s for 10 s, facing +x, with a camera whose
detector publishes ``vision_msgs/msg/Detection3DArray`` on ``/camera/detections``
(frame ``camera``, positions in the camera's frame, class ids of its own: ``47`` a
cup, ``soda_can``, ``chair``) at 5 Hz, and its pose on ``/robot/pose``
(``geometry_msgs/msg/PoseStamped``, frame ``map``) at 10 Hz. In the room: a cup at
(1.0, 2.0) and a soda can at (3.0, 1.0); a chair the knowledge has no class for.

    python examples/ros2_demo_bag.py demo_bag      # a rosbag2 folder (MCAP)

Needs ``pip install "semwm[ros2]"`` (``rosbags``); no ROS installation.
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
from rosbags.rosbag2 import StoragePlugin, Writer

from semwm.ros2.messages import typestore

ROOM = {"47": (1.0, 2.0), "soda_can": (3.0, 1.0), "chair": (2.0, 2.6)}
T0 = 1_764_066_000.0  # the robot's clock: Unix time


def main(path: Path) -> None:
    store = typestore()
    T = store.types
    rng = np.random.default_rng(7)

    def stamp(t: float) -> object:
        sec = math.floor(t)
        return T["builtin_interfaces/msg/Time"](sec=sec, nanosec=round((t - sec) * 1e9))

    def pose(x: float, y: float) -> object:
        return T["geometry_msgs/msg/Pose"](
            position=T["geometry_msgs/msg/Point"](x=x, y=y, z=0.0),
            orientation=T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0),
        )

    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        poses = writer.add_connection(
            "/robot/pose", "geometry_msgs/msg/PoseStamped", typestore=store
        )
        detections = writer.add_connection(
            "/camera/detections", "vision_msgs/msg/Detection3DArray", typestore=store
        )
        for k in range(101):  # 10 s at 10 Hz
            t = T0 + 0.1 * k
            robot = (0.2 * 0.1 * k, 0.5)
            header = T["std_msgs/msg/Header"](stamp=stamp(t), frame_id="map")
            message = T["geometry_msgs/msg/PoseStamped"](header=header, pose=pose(*robot))
            ns = round(t * 1e9)
            writer.write(poses, ns, store.serialize_cdr(message, "geometry_msgs/msg/PoseStamped"))
            if k % 2:
                continue  # the detector runs at 5 Hz
            header = T["std_msgs/msg/Header"](stamp=stamp(t), frame_id="camera")
            found = []
            for class_id, (x, y) in ROOM.items():
                seen = (x - robot[0] + rng.normal(0, 0.03), y - robot[1] + rng.normal(0, 0.03))
                covariance = np.zeros(36)
                covariance[0] = covariance[7] = covariance[14] = 0.03**2
                hypothesis = T["vision_msgs/msg/ObjectHypothesisWithPose"](
                    hypothesis=T["vision_msgs/msg/ObjectHypothesis"](class_id=class_id, score=0.9),
                    pose=T["geometry_msgs/msg/PoseWithCovariance"](
                        pose=pose(*seen), covariance=covariance
                    ),
                )
                bbox = T["vision_msgs/msg/BoundingBox3D"](
                    center=pose(*seen), size=T["geometry_msgs/msg/Vector3"](x=0.1, y=0.1, z=0.1)
                )
                found.append(
                    T["vision_msgs/msg/Detection3D"](
                        header=header, results=[hypothesis], bbox=bbox, id=""
                    )
                )
            array = T["vision_msgs/msg/Detection3DArray"](header=header, detections=found)
            writer.write(
                detections, ns, store.serialize_cdr(array, "vision_msgs/msg/Detection3DArray")
            )
    print(f"wrote {path}")


if __name__ == "__main__":
    if len(sys.argv) != 2:
        sys.exit("usage: python examples/ros2_demo_bag.py OUT_FOLDER")
    main(Path(sys.argv[1]))
