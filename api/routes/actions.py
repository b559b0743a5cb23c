"""``POST /actions``: a robot's action on an object (paper 004 IV-B: a kick)."""

from __future__ import annotations

from typing import Annotated, Any, Literal

from fastapi import APIRouter, Body, Response
from pydantic import BaseModel, ConfigDict, Field

from api.deps import WorldDep
from api.schemas import MessageOut, ValidationErrorOut
from api.service import COMMIT_HEADER
from semwm.detection import MAX_TIME

router = APIRouter(tags=["actions"])

_KICK: dict[str, Any] = {
    "time": 12.3,
    "type": "kick",
    "source": "robot1",
    "near": [1.0, 0.0],
    "direction": [0.0, 1.0],
    "speed": 2.0,
}
_EXAMPLES: dict[str, Any] = {
    "near": {"summary": "Kick the ball nearest to a point", "value": _KICK},
    "object": {
        "summary": "Kick an object by id",
        "value": {**{k: v for k, v in _KICK.items() if k != "near"}, "object": 4},
    },
}


class ActionIn(BaseModel):
    """A kick: the object (by id, or the nearest passive object within ``radius`` of
    ``near``) may now move at ``speed`` along ``direction``. Every hypothesis holding it
    splits into kicked (the class's ``kick_probability``) and not kicked; later
    detections decide."""

    model_config = ConfigDict(
        extra="forbid",
        json_schema_extra={"examples": [_KICK]},
    )

    time: float = Field(
        allow_inf_nan=False,
        ge=-MAX_TIME,
        le=MAX_TIME,
        description="s; not before the latest detection",
    )
    type: Literal["kick"] = "kick"
    source: str | None = Field(default=None, max_length=256)
    object: int | None = Field(default=None, description="the id of the object kicked")
    near: list[float] | None = Field(default=None, description="or a position near it (m)")
    radius: float = Field(default=1.0, gt=0.0, le=1e6, description="m, with near")
    direction: list[float] = Field(description="the direction it is kicked in")
    speed: float = Field(ge=0.0, le=1e3, description="m/s")


class ActionOut(BaseModel):
    """What ``POST /actions`` acknowledges."""

    objects: list[int] = Field(description="ids of the objects the action may have moved")
    hypotheses: int = Field(description="hypotheses stored after it")


@router.post(
    "/actions",
    response_model=ActionOut,
    summary="Report an action on an object (a kick)",
    responses={
        409: {"model": MessageOut, "description": "Older than the latest detection"},
        422: {"model": ValidationErrorOut, "description": "Invalid; nothing was applied"},
    },
)
def post_action(
    world: WorldDep,
    action: Annotated[ActionIn, Body(openapi_examples=_EXAMPLES)],
    response: Response,
) -> ActionOut:
    """Spawn action hypotheses (paper 004 IV-B): kicked with the stated speed and the
    class's spreads, or not kicked."""
    committed = world.act(action.model_dump(exclude_none=True))
    response.headers[COMMIT_HEADER] = str(committed.commit)
    objects, count = committed.value
    return ActionOut(objects=objects, hypotheses=count)
