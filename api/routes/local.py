"""Two levels (paper 000): ``POST /local/{robot}/detections``, ``GET /local/{robot}/world``.

A robot's detections posted here feed its local world model (stamped by its own
clock); after each batch the local model reports the objects it updated to the
global model, which is the one ``GET /world`` shows (docs/team.md).
"""

from __future__ import annotations

from typing import Annotated, Any

from fastapi import APIRouter, Body, Path
from pydantic import BaseModel, Field

from api.deps import SettingsDep, WorldDep
from api.errors import InvalidError
from api.routes.detections import parse_body
from api.routes.world import TimeQuery
from api.schemas import DETECTION_EXAMPLE, MessageOut, ValidationErrorOut, WorldOut

router = APIRouter(tags=["two levels"])

_EXAMPLES: dict[str, Any] = {
    "batch": {"summary": "A batch", "value": {"detections": [DETECTION_EXAMPLE]}}
}
Robot = Annotated[str, Path(min_length=1, max_length=200, description="The robot's name.")]


class LocalIngestOut(BaseModel):
    """What ``POST /local/{robot}/detections`` acknowledges."""

    applied: int = Field(description="Detections applied to the local model.")
    reported: int = Field(description="Local objects reported to the global model.")


@router.post(
    "/local/{robot}/detections",
    response_model=LocalIngestOut,
    summary="Add detections to a robot's local model (reported to the global one)",
    responses={
        409: {"model": MessageOut, "description": "Older than the local model allows"},
        422: {"model": ValidationErrorOut, "description": "Invalid; nothing was applied"},
    },
)
def post_local_detections(
    world: WorldDep,
    settings: SettingsDep,
    robot: Robot,
    payload: Annotated[Any, Body(openapi_examples=_EXAMPLES)],
) -> LocalIngestOut:
    """The body is one detection or ``{"detections": [...]}``, as ``POST /detections``."""
    parsed = parse_body(payload, settings.max_batch)
    if parsed.errors:
        raise InvalidError(parsed.errors)
    items = [d.to_domain() for d in parsed.valid]
    reported = world.local_ingest(robot, items, parsed.batch)
    return LocalIngestOut(applied=len(items), reported=reported)


@router.get(
    "/local/{robot}/world",
    response_model=WorldOut,
    summary="A robot's local world model",
    responses={404: {"model": MessageOut, "description": "No such robot"}},
)
def get_local_world(world: WorldDep, robot: Robot, time: TimeQuery = None) -> WorldOut:
    """The local model's MAP objects, predicted to ``time`` (the robot's clock)."""
    return WorldOut.model_validate(world.local_world(robot, time).to_dict())
