"""The ``vision_msgs`` messages semwm reads and writes, and a ``rosbags`` typestore
that holds them beside ROS 2's standard messages.

The definitions are those of ``vision_msgs`` 4.x (ROS 2 Humble and later). A bag
carries its own definitions, which the reader uses; these serve bags without them
and the bags semwm writes.
"""

from __future__ import annotations

from functools import cache
from typing import Any

DETECTION3D_ARRAY = "vision_msgs/msg/Detection3DArray"
DETECTION2D_ARRAY = "vision_msgs/msg/Detection2DArray"
DETECTION_ARRAYS = (DETECTION3D_ARRAY, DETECTION2D_ARRAY)

POSE_TYPES = (
    "geometry_msgs/msg/PoseStamped",
    "geometry_msgs/msg/PoseWithCovarianceStamped",
    "nav_msgs/msg/Odometry",
)
"""The sensor pose topics semwm reads (each has ``header`` and a ``pose``)."""

VISION_MSGS: dict[str, str] = {
    "vision_msgs/msg/ObjectHypothesis": "string class_id\nfloat64 score\n",
    "vision_msgs/msg/ObjectHypothesisWithPose": (
        "vision_msgs/ObjectHypothesis hypothesis\ngeometry_msgs/PoseWithCovariance pose\n"
    ),
    "vision_msgs/msg/BoundingBox3D": "geometry_msgs/Pose center\ngeometry_msgs/Vector3 size\n",
    "vision_msgs/msg/Detection3D": (
        "std_msgs/Header header\nvision_msgs/ObjectHypothesisWithPose[] results\n"
        "vision_msgs/BoundingBox3D bbox\nstring id\n"
    ),
    "vision_msgs/msg/Detection3DArray": (
        "std_msgs/Header header\nvision_msgs/Detection3D[] detections\n"
    ),
    "vision_msgs/msg/Point2D": "float64 x\nfloat64 y\n",
    "vision_msgs/msg/Pose2D": "vision_msgs/Point2D position\nfloat64 theta\n",
    "vision_msgs/msg/BoundingBox2D": (
        "vision_msgs/Pose2D center\nfloat64 size_x\nfloat64 size_y\n"
    ),
    "vision_msgs/msg/Detection2D": (
        "std_msgs/Header header\nvision_msgs/ObjectHypothesisWithPose[] results\n"
        "vision_msgs/BoundingBox2D bbox\nstring id\n"
    ),
    "vision_msgs/msg/Detection2DArray": (
        "std_msgs/Header header\nvision_msgs/Detection2D[] detections\n"
    ),
}
"""Type name -> its ``.msg`` text (``vision_msgs`` 4.x)."""


@cache
def typestore() -> Any:
    """ROS 2 Humble's standard messages and :data:`VISION_MSGS` (a ``rosbags``
    ``Typestore``; built once)."""
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    store = get_typestore(Stores.ROS2_HUMBLE)
    types: dict[str, Any] = {}
    for name, text in VISION_MSGS.items():
        types.update(get_types_from_msg(text, name))
    store.register(types)
    return store
