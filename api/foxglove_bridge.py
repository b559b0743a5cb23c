"""``semwm serve --foxglove PORT``: the world streamed live to Foxglove (``foxglove-sdk``).

Each ``world`` snapshot of the :class:`~api.feed.WorldFeed` becomes one
``foxglove.SceneUpdate`` on the topic ``/semwm/world`` (frame ``world``): it first
deletes every entity, then adds one entity per object (id ``object/<id>``) with
an ellipsoid (the 95 % position ellipse in x-y; its height the 95 % extent in
z for a 3-d world, else 5 cm), a text ``#<id> <class> <label>`` above it and,
for a moving object, an arrow of one second of its velocity. Opacity is the
object's existence probability. Open Foxglove, "Open connection", Foxglove
WebSocket, ``ws://127.0.0.1:PORT``, and add a 3D panel.

Needs the ``foxglove`` extra: ``pip install "semwm[foxglove]"``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import foxglove
from foxglove.channels import SceneUpdateChannel
from foxglove.messages import (
    ArrowPrimitive,
    Color,
    Pose,
    Quaternion,
    SceneEntity,
    SceneEntityDeletion,
    SceneEntityDeletionType,
    SceneUpdate,
    SpherePrimitive,
    TextPrimitive,
    Timestamp,
    Vector3,
)

TOPIC = "/semwm/world"
FRAME = "world"
ELLIPSE_SCALE = math.sqrt(5.991)  # 95 % of a 2-d Gaussian: chi-square(2) quantile 5.991
FLAT_HEIGHT = 0.05  # m: the ellipsoid's height in a 2-d world


def principal_axes(covariance: Sequence[Sequence[float]]) -> tuple[float, float, float]:
    """The x-y block's standard deviations along its principal axes and the first axis's angle.

    .. math:: \\lambda_{1,2} = \\tfrac{a+c}{2} \\pm \\sqrt{(\\tfrac{a-c}{2})^2 + b^2},
              \\quad \\theta = \\tfrac12 \\operatorname{atan2}(2b, a-c)

    for the block ``[[a, b], [b, c]]`` (m^2); returns ``(sqrt(l1), sqrt(l2), theta)``.
    """
    a, b, c = covariance[0][0], covariance[0][1], covariance[1][1]
    mean, spread = (a + c) / 2.0, math.hypot((a - c) / 2.0, b)
    theta = 0.5 * math.atan2(2.0 * b, a - c)
    return math.sqrt(max(mean + spread, 0.0)), math.sqrt(max(mean - spread, 0.0)), theta


def _yaw(angle: float) -> Quaternion:
    return Quaternion(x=0.0, y=0.0, z=math.sin(angle / 2.0), w=math.cos(angle / 2.0))


def _point(position: Sequence[float], dz: float = 0.0) -> Vector3:
    z = position[2] if len(position) > 2 else 0.0
    return Vector3(x=position[0], y=position[1], z=z + dz)


def object_entity(obj: Mapping[str, Any], stamp: Timestamp) -> SceneEntity:
    """One object of a ``GET /world`` answer as a Foxglove entity."""
    position: Sequence[float] = obj["position"]
    covariance: Sequence[Sequence[float]] = obj["covariance"]
    existence = float(obj.get("existence", 1.0))
    sigma_1, sigma_2, theta = principal_axes(covariance)
    height = (
        2.0 * ELLIPSE_SCALE * math.sqrt(max(covariance[2][2], 0.0))
        if len(covariance) > 2
        else FLAT_HEIGHT
    )
    colour = Color(r=0.12, g=0.47, b=0.71, a=max(0.15, min(existence, 1.0)))
    ellipse = SpherePrimitive(
        pose=Pose(position=_point(position), orientation=_yaw(theta)),
        size=Vector3(x=2.0 * ELLIPSE_SCALE * sigma_1, y=2.0 * ELLIPSE_SCALE * sigma_2, z=height),
        color=colour,
    )
    name = " ".join(
        part for part in (f"#{obj['id']}", str(obj.get("class")), obj.get("label") or "") if part
    )
    text = TextPrimitive(
        pose=Pose(position=_point(position, 0.3), orientation=_yaw(0.0)),
        billboard=True,
        font_size=14.0,
        scale_invariant=True,
        color=Color(r=1.0, g=1.0, b=1.0, a=1.0),
        text=name,
    )
    arrows = []
    velocity: Sequence[float] | None = obj.get("velocity")
    if velocity is not None and math.hypot(*velocity[:2]) > 1e-3:
        speed = math.hypot(*velocity[:2])
        arrows.append(
            ArrowPrimitive(
                pose=Pose(
                    position=_point(position),
                    orientation=_yaw(math.atan2(velocity[1], velocity[0])),
                ),
                shaft_length=speed,
                shaft_diameter=0.03,
                head_length=0.1,
                head_diameter=0.08,
                color=Color(r=0.85, g=0.33, b=0.1, a=1.0),
            )
        )
    return SceneEntity(
        timestamp=stamp,
        frame_id=FRAME,
        id=f"object/{obj['id']}",
        spheres=[ellipse],
        texts=[text],
        arrows=arrows,
    )


def scene_update(world: Mapping[str, Any]) -> SceneUpdate:
    """A ``world`` payload (or a ``GET /world`` answer) as a whole-scene update."""
    stamp = Timestamp.from_epoch_secs(max(float(world.get("time") or 0.0), 0.0))
    return SceneUpdate(
        deletions=[SceneEntityDeletion(timestamp=stamp, type=SceneEntityDeletionType.All)],
        entities=[object_entity(obj, stamp) for obj in world.get("objects", [])],
    )


class FoxgloveBridge:
    """A Foxglove WebSocket server on ``host:port`` publishing each world it is given.

    It has its own ``foxglove.Context``, so several bridges (tests) do not share channels.
    """

    def __init__(self, host: str = "127.0.0.1", port: int = 8765) -> None:
        self.context = foxglove.Context()
        self.server = foxglove.start_server(
            name="semwm", host=host, port=port, context=self.context
        )
        self.channel = SceneUpdateChannel(TOPIC, context=self.context)

    @property
    def port(self) -> int:
        """The port bound (useful with port 0)."""
        port: int = self.server.port
        return port

    def publish(self, world: Mapping[str, Any]) -> None:
        """Log ``world`` as a scene update (skipped while no client subscribes)."""
        if self.channel.has_sinks():
            self.channel.log(scene_update(world))

    def close(self) -> None:
        self.channel.close()
        self.server.stop()
