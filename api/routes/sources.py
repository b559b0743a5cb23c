"""``POST /sources/{name}/sync`` (paper 003 clock exchange) and ``GET /sources``."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Annotated, Any, Literal

from fastapi import APIRouter, Body, Path
from pydantic import BaseModel, ConfigDict, Field

from api.deps import WorldDep
from api.errors import InvalidError
from api.schemas import ValidationErrorOut
from semwm.clock import MAX_CLOCK, Exchange, ExchangeError
from semwm.mhf.rates import StreamReport
from semwm.sources import SourceStatus

router = APIRouter(tags=["sources"])

_EXAMPLES: dict[str, Any] = {
    "request": {"summary": "1. The source's request (t1, its clock)", "value": {"sent": 5.1}},
    "finished": {
        "summary": "2. The finished exchange (t4 when the answer came back)",
        "value": {"sent": 5.1, "received": 1763880000.02, "replied": 1763880000.021,
                  "returned": 5.14},
    },
}  # fmt: skip

Seconds = Annotated[
    float, Field(strict=True, allow_inf_nan=False, ge=-MAX_CLOCK, le=MAX_CLOCK)
]  # bounded: the offset and its uncertainty stay finite (issue 30)
_TIMES = ("received", "replied", "returned")


class SyncIn(BaseModel):
    """A sync request (``sent`` only) or a finished exchange (all four times)."""

    model_config = ConfigDict(extra="forbid")

    sent: Seconds = Field(description="t1: when the source sent the request, by its clock (s)")
    received: Seconds | None = Field(None, description="t2: from the service's answer (s)")
    replied: Seconds | None = Field(None, description="t3: from the service's answer (s)")
    returned: Seconds | None = Field(
        None, description="t4: when the answer reached the source, by its clock (s)"
    )


class SyncReplyOut(BaseModel):
    """The service's half of an exchange (service clock, s)."""

    sent: float = Field(description="t1: when the source sent the request, by its clock (s)")
    received: float = Field(description="t2: when the service received it (s)")
    replied: float = Field(description="t3: when the service answered (s)")


class StreamRatesOut(BaseModel):
    """One detector of a source: what its data shows beside the knowledge."""

    detector: str = Field(description="the detector")
    seconds: float = Field(description="how long (s) the rates were observed over")
    clutter_hz: float | None = Field(
        description="false alarms per second: objects it started that died unconfirmed"
    )
    knowledge_clutter_hz: float = Field(description="the detector's clutter_frequency (Hz)")
    detection_hz: dict[str, float] = Field(
        description="per class, the rate (Hz) at which it reports an object of the class in view"
    )
    knowledge_detection_hz: dict[str, float] = Field(
        description="per class, the knowledge's detection_frequency (Hz)"
    )
    warnings: list[str] = Field(
        description="where the data and the knowledge differ by more than 3x (after 10 s, or "
        "20 expected detections)"
    )

    @classmethod
    def of(cls, report: StreamReport) -> StreamRatesOut:
        return cls.model_validate(report.to_dict())


class SourceOut(BaseModel):
    """One source: its clock offset (service clock = source clock + offset) and counts."""

    name: str | None = Field(description="the source's name; null for detections without one")
    synced: bool = Field(description="whether at least one sync exchange has been made")
    clock_offset: float | None = Field(description="service clock minus source clock (s)")
    offset_std: float | None = Field(description="standard uncertainty of the offset (s)")
    delay: float | None = Field(description="smallest round-trip delay kept (s)")
    exchanges: int = Field(description="sync exchanges made (kept or not)")
    detections: int = Field(description="detections accepted from it")
    last_time: float | None = Field(description="latest accepted time, service clock (s)")
    late: int = Field(description="detections refused as older than the reorder window")
    refused: int = Field(description="detections refused by a time guard")
    problem: str | None = Field(description="why its last detections were refused, if they were")
    late_policy: Literal["replay", "drop"] = Field(
        default="replay",
        description="its scans older than the newest processed one: replayed, or dropped "
        "(PUT /sources/NAME/policy)",
    )
    dropped: int = Field(default=0, description="detections dropped as late (policy drop)")
    in_arrival_order: int = Field(
        default=0,
        description="scans processed in arrival order: at most --order-tolerance older than "
        "another source's newest processed scan (docs/operations.md)",
    )

    rates: list[StreamRatesOut] = Field(
        default_factory=list,
        description="per detector: the clutter and detection rates its data shows beside the "
        "knowledge's, with a warning where they differ by more than 3x",
    )

    @classmethod
    def of(cls, status: SourceStatus, rates: Sequence[StreamReport] = ()) -> SourceOut:
        return cls.model_validate(
            {**status.to_dict(), "rates": [StreamRatesOut.of(r) for r in rates]}
        )


class SourcesOut(BaseModel):
    """Every source seen, with its clock and counts."""

    sources: list[SourceOut] = Field(description="one per source, by name (the nameless one first)")


@router.post(
    "/sources/{name}/sync",
    response_model=SyncReplyOut | SourceOut,
    summary="Clock sync exchange (paper 003, NTP-style)",
    responses={422: {"model": ValidationErrorOut, "description": "Not one round trip"}},
)
async def sync(
    world: WorldDep,
    name: Annotated[str, Path(min_length=1, max_length=200)],
    body: Annotated[SyncIn, Body(openapi_examples=_EXAMPLES)],
) -> SyncReplyOut | SourceOut:
    """Two calls make one exchange.

    1. ``{"sent": t1}`` (source clock) answers ``{"sent": t1, "received": t2,
       "replied": t3}`` (service clock).
    2. ``{"sent", "received", "replied", "returned": t4}`` updates the source's offset
       (``((t2 - t1) + (t3 - t4)) / 2``, smoothed over the smallest-delay exchanges)
       and answers the source as ``GET /sources`` shows it.
    """
    received = world.clock()
    given = [t for t in _TIMES if getattr(body, t) is not None]
    if not given:
        return SyncReplyOut(sent=body.sent, received=received, replied=world.clock())
    if len(given) < len(_TIMES):
        missing = [t for t in _TIMES if t not in given]
        raise InvalidError.one(
            ("body", missing[0]),
            f"a finished exchange needs sent, received, replied and returned; "
            f"missing {', '.join(missing)}",
            "missing",
        )
    try:
        exchange = Exchange(body.sent, body.received, body.replied, body.returned)  # type: ignore[arg-type]
    except ExchangeError as error:
        raise InvalidError.one(("body", error.field), str(error)) from error
    return SourceOut.of(world.sync(name, exchange))


_POLICY_EXAMPLES: dict[str, Any] = {
    "drop": {"summary": "Drop late scans (the next supersedes them)", "value": {"late": "drop"}},
    "replay": {"summary": "Replay late scans (the default)", "value": {"late": "replay"}},
}


class PolicyIn(BaseModel):
    """What the service does with a source's late scans."""

    model_config = ConfigDict(extra="forbid")

    late: Literal["replay", "drop"] = Field(
        description="A scan older than the newest the world processed: 'replay' it (the "
        "default: the world goes back and processes the later scans again; older than the "
        "reorder window: 409), or 'drop' it (200 with nothing applied and the header "
        "X-Semwm-Dropped: late): a source whose next scan supersedes a late one."
    )


@router.put(
    "/sources/{name}/policy",
    response_model=SourceOut,
    summary="A source's policy for late scans (replay or drop)",
    responses={422: {"model": ValidationErrorOut, "description": "Not a policy"}},
)
def put_policy(
    world: WorldDep,
    name: Annotated[str, Path(min_length=1, max_length=200)],
    body: Annotated[PolicyIn, Body(openapi_examples=_POLICY_EXAMPLES)],
) -> SourceOut:
    """Set what happens to the source's late scans; answers the source as ``GET
    /sources`` shows it."""
    return SourceOut.of(world.set_late_policy(name, body.late))


@router.get("/sources", response_model=SourcesOut, summary="Sources: clocks, counts, problems")
def sources(world: WorldDep) -> SourcesOut:
    """Every source seen: clock offset and uncertainty, exchanges, detections, latest
    time, late and guard-refused counts and the last problem (``null`` when fine)."""
    reports: dict[str, list[StreamReport]] = {}
    for report in world.rate_report():
        reports.setdefault(report.source, []).append(report)
    return SourcesOut(
        sources=[SourceOut.of(s, reports.get(s.name or "", [])) for s in world.source_statuses()]
    )
