"""``POST /detections``: one detection or a batch, applied whole or not at all."""

from __future__ import annotations

from typing import Annotated, Any

from fastapi import APIRouter, Body, Header, Response
from pydantic import ValidationError

from api.deps import SettingsDep, WorldDep
from api.errors import InvalidError, validation_items
from api.schemas import (
    DETECTION_EXAMPLE,
    DetectionIn,
    IngestOut,
    MessageOut,
    SensorIn,
    ValidationErrorOut,
)
from api.service import COMMIT_HEADER, Committed, WorldService
from semwm import IngestResult

router = APIRouter(tags=["detections"])

MAX_KEY = 200
"""The longest idempotency key (``Idempotency-Key`` header or ``batch_id``)."""

_EXAMPLES: dict[str, Any] = {
    "single": {"summary": "One detection", "value": DETECTION_EXAMPLE},
    "batch": {
        "summary": "A batch (applied whole or not at all)",
        "value": {
            "detections": [
                DETECTION_EXAMPLE,
                {"time": 12.3, "class": "CokeCan", "position": [0.5, 1.5], "source": "robot1"},
            ]
        },
    },
}
_OPENAPI_BODY: dict[str, Any] = {
    "requestBody": {
        "content": {
            "application/json": {
                "schema": {
                    "anyOf": [
                        {"$ref": "#/components/schemas/DetectionIn"},
                        {"$ref": "#/components/schemas/DetectionBatch"},
                    ]
                }
            }
        }
    }
}


class Parsed:
    """A body checked against the wire schema: what passed, where, and every problem."""

    def __init__(self, batch: bool) -> None:
        self.batch = batch
        self.batch_id: str | None = None
        self.valid: list[DetectionIn] = []
        self.index: list[int] = []
        self.errors: list[dict[str, Any]] = []
        self.sensor: SensorIn | None = None

    def problem(self, loc: list[str | int], msg: str, type_: str) -> None:
        self.errors.append({"loc": loc, "msg": msg, "type": type_})

    def add(self, item: Any, i: int, prefix: tuple[str | int, ...]) -> None:
        try:
            self.valid.append(DetectionIn.model_validate(item))
            self.index.append(i)
        except ValidationError as error:
            self.errors += validation_items(error.errors(), prefix)


def parse_body(payload: Any, max_batch: int) -> Parsed:
    """Check one detection or ``{"detections": [...]}``, collecting every problem."""
    if not (isinstance(payload, dict) and "detections" in payload):
        parsed = Parsed(batch=False)
        parsed.add(payload, 0, ("body",))
        return parsed
    parsed = Parsed(batch=True)
    for key in sorted(set(payload) - {"detections", "batch_id", "sensor"}):
        parsed.problem(
            ["body", key],
            "unknown field: a batch has only 'detections', 'batch_id' and 'sensor'",
            "extra",
        )
    if payload.get("sensor") is not None:
        try:
            parsed.sensor = SensorIn.model_validate(payload["sensor"])
        except ValidationError as error:
            parsed.errors += validation_items(error.errors(), ("body", "sensor"))
    batch_id = payload.get("batch_id")
    if batch_id is not None:
        if isinstance(batch_id, str) and 1 <= len(batch_id) <= MAX_KEY:
            parsed.batch_id = batch_id
        else:
            parsed.problem(
                ["body", "batch_id"],
                f"batch_id must be text of 1 to {MAX_KEY} characters",
                "string_type",
            )
    items = payload["detections"]
    if not isinstance(items, list):
        parsed.problem(["body", "detections"], "must be a list of detections", "list_type")
    elif not items and "sensor" not in payload:
        parsed.problem(
            ["body", "detections"],
            "a batch needs at least one detection (or a 'sensor' saying where it looked)",
            "too_short",
        )
    elif len(items) > max_batch:
        parsed.problem(
            ["body", "detections"],
            f"a batch holds at most {max_batch} detections; found {len(items)}: split it",
            "too_long",
        )
    else:
        for i, item in enumerate(items):
            parsed.add(item, i, ("body", "detections", i))
    return parsed


@router.post(
    "/detections",
    response_model=IngestOut,
    summary="Add one detection or a batch",
    responses={
        409: {"model": MessageOut, "description": "Older than the reorder window allows"},
        422: {"model": ValidationErrorOut, "description": "Invalid; nothing was applied"},
    },
    openapi_extra=_OPENAPI_BODY,
)
def post_detections(
    world: WorldDep,
    settings: SettingsDep,
    payload: Annotated[Any, Body(openapi_examples=_EXAMPLES)],
    response: Response,
    idempotency_key: Annotated[
        str | None,
        Header(
            min_length=1,
            max_length=MAX_KEY,
            description="A client's id for this request: posted again (a retry), it is "
            "answered as the first time and not applied twice. Same as a batch's batch_id.",
        ),
    ] = None,
) -> IngestOut:
    """Add detections to the world.

    The body is one detection or ``{"detections": [...]}``. A batch is checked whole
    first: if any detection is invalid the answer is 422 with the field path of
    every problem (``["body", "detections", 3, "position"]``) and nothing is
    applied. A detection older than the latest processed time minus the reorder
    window gives 409. A repeated ``Idempotency-Key`` header or ``batch_id`` is
    answered as before and applied once.
    """
    committed = apply_body(world, payload, settings.max_batch, idempotency_key)
    response.headers[COMMIT_HEADER] = str(committed.commit)
    if committed.replayed:
        response.headers["Idempotent-Replayed"] = "true"
    result = committed.value
    return IngestOut(applied=result.applied, time=result.time, ignored=result.ignored)


def apply_body(
    world: WorldService, payload: Any, max_batch: int, idempotency_key: str | None = None
) -> Committed[IngestResult]:
    """Check and apply one ``POST /detections`` body (also what the MQTT bridge calls).

    Raises :class:`InvalidError` listing every problem, or the service's
    :class:`ConflictError`; either way nothing is applied. A key (the header's, else
    the body's ``batch_id``) seen recently is answered as before and not applied again.
    """
    parsed = parse_body(payload, max_batch)
    items = [d.to_domain() for d in parsed.valid]
    if parsed.errors:
        # Report the domain problems of the others too, so one answer lists them all.
        more = world.domain_problems(items, parsed.index, parsed.batch)
        raise InvalidError(sorted(parsed.errors + more, key=_loc_order))
    if idempotency_key is not None and parsed.batch_id not in (None, idempotency_key):
        raise InvalidError.one(
            ("body", "batch_id"), "batch_id differs from the Idempotency-Key header"
        )
    key = idempotency_key or parsed.batch_id
    if parsed.sensor is not None:  # paper 004: where the sensor looked
        return world.ingest(items, parsed.batch, key=key, sensor=parsed.sensor.to_domain())
    return world.ingest(items, parsed.batch, key=key)


def _loc_order(item: dict[str, Any]) -> tuple[int, str]:
    loc = item["loc"]
    first = loc[2] if len(loc) > 2 and isinstance(loc[2], int) else -1
    return first, ".".join(map(str, loc))
