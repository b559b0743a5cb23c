"""``POST /detections``: one detection or a batch, applied whole or not at all.

The hot path (:func:`apply_json`): the body's bytes are validated in one call into
pydantic-core (:data:`api.schemas.BATCH_ADAPTER`), giving the dicts the world model
takes; the checks and the world model's work run in a worker thread, so the event
loop keeps serving other requests. A body that fails there is parsed again by
:func:`parse_body`, which collects every problem with its field path (the 422).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from typing import Annotated, Any, cast

import anyio.to_thread
from fastapi import APIRouter, Header, Request, Response
from pydantic import ValidationError

from api.deps import SettingsDep, WorldDep
from api.errors import InvalidError, json_invalid_item, validation_items
from api.schemas import (
    BATCH_ADAPTER,
    DETECTION_ADAPTER,
    DETECTION_EXAMPLE,
    MAX_KEY,
    DetectionIn,
    IngestOut,
    MessageOut,
    SensorIn,
    ValidationErrorOut,
    ingest_out,
)
from api.service import COMMIT_HEADER, Committed, WorldBusy, WorldService
from api.stages import stage
from semwm import IngestResult

router = APIRouter(tags=["detections"])

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
        "required": True,
        "content": {
            "application/json": {
                "schema": {
                    "title": "Payload",
                    "anyOf": [
                        {"$ref": "#/components/schemas/DetectionIn"},
                        {"$ref": "#/components/schemas/DetectionBatch"},
                    ],
                },
                "examples": _EXAMPLES,
            }
        },
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
    if isinstance(payload, list):  # a bare array: say how a batch is sent
        parsed = Parsed(batch=False)
        parsed.problem(
            ["body"],
            'a batch is an object: send {"detections": [...]}, not a bare JSON array',
            "model_type",
        )
        return parsed
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
async def post_detections(
    world: WorldDep,
    settings: SettingsDep,
    request: Request,
    idempotency_key: Annotated[
        str | None,
        Header(
            min_length=1,
            max_length=MAX_KEY,
            description="A client's id for this request: posted again (a retry), it is "
            "answered as the first time and not applied twice. Same as a batch's batch_id.",
        ),
    ] = None,
) -> Response:
    """Add detections to the world.

    The body is one detection or ``{"detections": [...]}``. A batch is checked whole
    first: if any detection is invalid the answer is 422 with the field path of
    every problem (``["body", "detections", 3, "position"]``) and nothing is
    applied. A detection older than the latest processed time minus the reorder
    window gives 409. A repeated ``Idempotency-Key`` header or ``batch_id`` is
    answered as before and applied once.
    """
    raw = await request.body()
    committed = await anyio.to_thread.run_sync(
        apply_json, world, raw, settings.max_batch, idempotency_key
    )
    headers = {COMMIT_HEADER: str(committed.commit)}
    if committed.replayed:
        headers["Idempotent-Replayed"] = "true"
    if committed.dropped:  # a late scan of a 'late: drop' source (issue 30)
        headers["X-Semwm-Dropped"] = "late"
    result = committed.value
    answer = ingest_out(result)
    return Response(answer.model_dump_json(), media_type="application/json", headers=headers)


@dataclass(frozen=True)
class Accepted:
    """A body that passed the wire schema: the detections as the world model takes them."""

    detections: list[dict[str, Any]]
    batch: bool
    batch_id: str | None = None
    sensor: dict[str, Any] | None = None  # paper 004: where the scan's sensor looked


def parse_json(raw: bytes, max_batch: int) -> Accepted | None:
    """``raw`` validated in one call (no model per detection), or ``None`` if it fails.

    ``None`` means: ask :func:`parse_body`, which says what is wrong and where. The
    shape tried first is a guess from the bytes; a wrong guess costs a second try.
    A batch with a sensor view (paper 004) takes :func:`parse_body`'s path.
    """
    if b'"sensor"' in raw:
        return None
    batch_first = b'"detections"' in raw
    for batch in (batch_first, not batch_first):
        try:
            if batch:
                body = BATCH_ADAPTER.validate_json(raw)
                items = body["detections"]
                if not items or len(items) > max_batch:
                    return None
                # a body without a null has no null field: no pass over its detections
                plain = (
                    cast(list[dict[str, Any]], items)
                    if b"null" not in raw
                    else _without_nulls(items)
                )
                return Accepted(plain, True, body.get("batch_id"))
            return Accepted(_without_nulls([DETECTION_ADAPTER.validate_json(raw)]), False)
        except ValidationError:
            continue
    return None


def _without_nulls(items: list[Any]) -> list[dict[str, Any]]:
    """Detections without their ``null`` fields (as :meth:`DetectionIn.to_domain` gives)."""
    return [
        d if None not in d.values() else {k: v for k, v in d.items() if v is not None}
        for d in items
    ]


def decode_body(raw: bytes) -> Any:
    """The JSON value of a body; 422 at ``["body"]`` if it is empty or not JSON."""
    if not raw:
        raise InvalidError.one(
            ("body",),
            'the body is empty: send one detection or {"detections": [...]}',
            "missing",
        )
    try:
        return json.loads(raw)
    except (ValueError, RecursionError):  # RecursionError: nested too deep
        raise InvalidError([json_invalid_item()]) from None


def apply_json(
    world: WorldService,
    raw: bytes,
    max_batch: int,
    idempotency_key: str | None = None,
    wait: bool = True,
) -> Committed[IngestResult]:
    """:func:`apply_body` of a body's bytes: one validation of the whole body on the way in.

    Blocks (the world's lock, the world model): call it in a worker thread. ``wait``
    false: :class:`~api.service.WorldBusy` (nothing applied) if the world's lock is
    taken, and a body that is not plainly valid raises it too (its problems are
    collected where waiting is allowed).
    """
    with stage("parse"):
        accepted = parse_json(raw, max_batch)
    if accepted is None:
        if not wait:
            raise WorldBusy
        with stage("parse"):
            payload = decode_body(raw)
        return apply_body(world, payload, max_batch, idempotency_key)
    return _ingest(world, accepted, idempotency_key, wait)


def apply_body(
    world: WorldService, payload: Any, max_batch: int, idempotency_key: str | None = None
) -> Committed[IngestResult]:
    """Check and apply one ``POST /detections`` body (also what the MQTT bridge calls).

    Raises :class:`InvalidError` listing every problem, or the service's
    :class:`ConflictError`; either way nothing is applied. A key (the header's, else
    the body's ``batch_id``) seen recently is answered as before and not applied again.
    """
    with stage("parse"):
        parsed = parse_body(payload, max_batch)
        items = [d.to_domain() for d in parsed.valid]
    if parsed.errors:
        # Report the domain problems of the others too, so one answer lists them all.
        more = world.domain_problems(items, parsed.index, parsed.batch)
        raise InvalidError(sorted(parsed.errors + more, key=_loc_order))
    sensor = parsed.sensor.to_domain() if parsed.sensor is not None else None
    accepted = Accepted(items, parsed.batch, parsed.batch_id, sensor)
    return _ingest(world, accepted, idempotency_key)


def _ingest(
    world: WorldService, accepted: Accepted, idempotency_key: str | None, wait: bool = True
) -> Committed[IngestResult]:
    if idempotency_key is not None and accepted.batch_id not in (None, idempotency_key):
        raise InvalidError.one(
            ("body", "batch_id"), "batch_id differs from the Idempotency-Key header"
        )
    key = idempotency_key or accepted.batch_id
    options: dict[str, Any] = {} if wait else {"wait": False}  # the default call unchanged
    if accepted.sensor is not None:
        options["sensor"] = accepted.sensor
    # the body's dicts, made by parsing it: the service keeps them without a copy
    return world.ingest(accepted.detections, accepted.batch, key=key, owned=True, **options)


def _loc_order(item: dict[str, Any]) -> tuple[int, str]:
    loc = item["loc"]
    first = loc[2] if len(loc) > 2 and isinstance(loc[2], int) else -1
    return first, ".".join(map(str, loc))
