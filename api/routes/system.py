"""``GET /health``, ``GET /ready`` and ``POST /reset``."""

from __future__ import annotations

from pathlib import Path

from fastapi import APIRouter, Request, Response
from fastapi.responses import JSONResponse

from api.deps import SettingsDep, WorldDep
from api.guard import bearer, token_matches
from api.schemas import HealthOut, MessageOut, ReadyOut, ResetOut
from api.service import COMMIT_HEADER

router = APIRouter(tags=["system"])


@router.get("/health", response_model=HealthOut, summary="Liveness and a summary")
def health(world: WorldDep, settings: SettingsDep, request: Request) -> HealthOut:
    """``ok`` while the process serves requests; it never waits for the world.

    The summary (the engine running the world model, knowledge file, world time,
    hypothesis and object counts as of the last accepted change) is given to readers:
    everyone when reads are open, else only with the read (or write) token. The
    knowledge file's full path is given only with a token; without one, its name.
    """
    secrets = [s.get_secret_value() for s in (settings.read_token, settings.token) if s]
    has_token = token_matches(bearer(_headers(request)), secrets)
    if settings.read_token is not None and not has_token:
        return HealthOut(status="ok")
    summary = world.health()
    if not has_token and summary["knowledge"] is not None:
        # where the file lies tells a stranger about the host: its name only (issue 30)
        summary["knowledge"] = Path(summary["knowledge"]).name
    return HealthOut.model_validate(summary)


@router.get(
    "/ready",
    response_model=ReadyOut,
    summary="Readiness: can the world take requests now",
    responses={503: {"model": ReadyOut, "description": "Not ready, with the reasons"}},
)
def ready(world: WorldDep) -> JSONResponse:
    """200 when the world can take requests; 503 with the reasons while one request
    has held it longer than ``stuck_after`` or the last change failed internally."""
    reasons = world.readiness()
    body = ReadyOut(status="not ready" if reasons else "ready", reasons=reasons)
    return JSONResponse(body.model_dump(), status_code=503 if reasons else 200)


@router.post(
    "/reset",
    response_model=ResetOut,
    summary="Forget every object",
    responses={401: {"model": MessageOut, "description": "Missing or invalid write token"}},
)
def reset(world: WorldDep, response: Response) -> ResetOut:
    """Empty the world: every hypothesis and object is dropped; the knowledge stays."""
    committed = world.reset()
    response.headers[COMMIT_HEADER] = str(committed.commit)
    return ResetOut(time=committed.value)


def _headers(request: Request) -> dict[str, str]:
    return {k.lower(): v for k, v in request.headers.items()}
