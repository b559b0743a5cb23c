"""``GET /world``, ``GET /world/objects/{id}``, ``GET /hypotheses``: what the filter believes."""

from __future__ import annotations

import math
from typing import Annotated, Any, Literal

from fastapi import APIRouter, Path, Query, Response

from api.deps import WorldDep
from api.errors import InvalidError
from api.schemas import (
    HypothesesOut,
    HypothesisOut,
    MessageOut,
    ValidationErrorOut,
    WorldObjectOut,
    WorldOut,
)
from api.world_json import object_json, world_json

router = APIRouter(tags=["world"])

TimeQuery = Annotated[
    float | None,
    Query(
        allow_inf_nan=False,
        description="Predict the objects to this time (s); default: the latest detection's.",
    ),
]
_INVALID: dict[int | str, dict[str, Any]] = {
    422: {"model": ValidationErrorOut, "description": "Invalid query"}
}


_PAST: dict[int | str, dict[str, Any]] = {
    **_INVALID,
    409: {
        "model": MessageOut,
        "description": "time is before the newest scan and older than the reorder history "
        "remembers: the world as it was then is not known",
    },
}


def parse_near(near: str) -> tuple[float, ...]:
    """``"x,y,r"`` or ``"x,y,z,r"`` as numbers (422 on anything else)."""
    parts = [p.strip() for p in near.split(",")]
    try:
        values = tuple(float(p) for p in parts)
    except ValueError:
        raise InvalidError.one(
            ("query", "near"),
            f"near must be comma-separated numbers x,y,r or x,y,z,r; got {near!r}",
        ) from None
    if len(values) not in (3, 4):
        raise InvalidError.one(
            ("query", "near"), f"near must be x,y,r or x,y,z,r; got {len(values)} numbers"
        )
    if not all(math.isfinite(v) for v in values):
        raise InvalidError.one(("query", "near"), f"near must hold finite numbers; got {near!r}")
    if values[-1] < 0:
        raise InvalidError.one(("query", "near"), f"the radius must be >= 0; got {values[-1]:g}")
    return values


@router.get("/world", response_model=WorldOut, summary="The objects of the world", responses=_PAST)
def get_world(
    world: WorldDep,
    time: TimeQuery = None,
    cls: Annotated[
        str | None,
        Query(
            alias="class",
            min_length=1,
            max_length=256,
            description="Only objects of this class or its subclasses ('Can' includes 'CokeCan').",
        ),
    ] = None,
    near: Annotated[
        str | None,
        Query(description="Only objects within r metres of a point: 'x,y,r' or 'x,y,z,r'."),
    ] = None,
    label: Annotated[str | None, Query(description="Only objects with this label.")] = None,
    min_existence: Annotated[
        float | None,
        Query(
            gt=0.0,
            le=1.0,
            description="Only objects at least this likely to exist (default: the knowledge's "
            "world.min_existence, 0.5).",
        ),
    ] = None,
    confidence: Annotated[
        list[Literal["valid", "suspicious", "invalid"]] | None,
        Query(
            description="Only objects in this confidence state (paper 004); repeat it for "
            "several (confidence=valid&confidence=suspicious)."
        ),
    ] = None,
) -> Response:
    """The objects of the world (each at least ``min_existence`` likely to exist over the
    whole hypothesis set), predicted to ``time``."""
    centre = parse_near(near) if near is not None else None
    state = world.world(
        time=time,
        cls=cls,
        near=centre,
        label=label,
        min_existence=min_existence,
        confidence=confidence,
    )
    return Response(world_json(state), media_type="application/json")  # as WorldOut


@router.get(
    "/world/objects/{object_id}",
    response_model=WorldObjectOut,
    summary="One object of the world",
    responses={404: {"model": MessageOut, "description": "No such object"}, **_PAST},
)
def get_object(
    world: WorldDep,
    object_id: Annotated[int, Path(description="The object's id as in GET /world.")],
    time: TimeQuery = None,
) -> Response:
    """One object, predicted to ``time``; 404 naming the id when it is not in the world."""
    obj = world.object(object_id, time=time)
    return Response(object_json(obj), media_type="application/json")  # as WorldObjectOut


@router.get(
    "/hypotheses", response_model=HypothesesOut, summary="The best hypotheses", responses=_INVALID
)
def get_hypotheses(
    world: WorldDep,
    limit: Annotated[int, Query(ge=1, le=1000, description="How many, best first.")] = 10,
) -> HypothesesOut:
    """The ``limit`` most probable global hypotheses, best first, with their
    probabilities and objects. An object's ``id`` is its public id if a published
    world ever held it, else ``null``; ``track`` is the filter's internal lineage
    number, the same in every hypothesis that holds the same object."""
    counts, summaries = world.hypotheses(limit)
    return HypothesesOut(
        **counts, hypotheses=[HypothesisOut.model_validate(h.to_dict()) for h in summaries]
    )
