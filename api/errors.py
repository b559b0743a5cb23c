"""Errors the service raises and how each becomes an HTTP response.

Every refusal is a 4xx whose body says what was wrong and where; the state of
the world is unchanged when one is raised. Only a bug gives a 500.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Sequence
from typing import Any

from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from starlette.exceptions import HTTPException as StarletteHTTPException
from starlette.types import ASGIApp, Message, Receive, Scope, Send

Loc = tuple[str | int, ...]

logger = logging.getLogger("api")


class ApiError(Exception):
    """A request refused with ``status`` and a message."""

    status = 400
    headers: dict[str, str] | None = None  # response headers (Retry-After...)

    def __init__(self, message: str) -> None:
        super().__init__(message)
        self.message = message

    def body(self) -> dict[str, Any]:
        return {"detail": self.message}


class NotFoundError(ApiError):
    """404: the thing named in the path does not exist."""

    status = 404


class ConflictError(ApiError):
    """409: the request is well formed but conflicts with the state (e.g. too old)."""

    status = 409


class StorageUnavailable(ApiError):
    """507 (the disk is full) or 503 (another store failure) with ``Retry-After``: the
    change was neither stored nor applied; reads are served and writes go through
    again once the store can take them."""

    def __init__(self, message: str, *, full: bool, retry_after: int) -> None:
        super().__init__(message)
        self.status = 507 if full else 503
        self.headers = {"Retry-After": str(retry_after)}


class Overloaded(ApiError):
    """503 with ``Retry-After``: the service is behind (too many requests wait for the
    world); nothing was applied, the request may be sent again as it is."""

    status = 503

    def __init__(self, message: str, retry_after: int) -> None:
        super().__init__(message)
        self.headers = {"Retry-After": str(retry_after)}


class TooManyStreams(ApiError):
    """429 (this client holds its share of streams) or 503 (the service holds all it
    serves) with ``Retry-After``: no stream was opened."""

    def __init__(self, message: str, *, per_client: bool, retry_after: int) -> None:
        super().__init__(message)
        self.status = 429 if per_client else 503
        self.headers = {"Retry-After": str(retry_after)}


class InvalidError(ApiError):
    """422 with one ``{"loc", "msg", "type"}`` item per problem, like FastAPI's own."""

    status = 422

    def __init__(self, errors: Sequence[dict[str, Any]]) -> None:
        self.errors = list(errors)
        super().__init__("; ".join(f"{_dotted(e['loc'])}: {e['msg']}" for e in self.errors))

    @classmethod
    def one(cls, loc: Loc, msg: str, type_: str = "value_error") -> InvalidError:
        return cls([{"loc": list(loc), "msg": msg, "type": type_}])

    def body(self) -> dict[str, Any]:
        return {"detail": self.errors}


class KnowledgeFileError(ApiError):
    """422 of a knowledge file that cannot be used: one ``FILE:LINE: message`` per problem."""

    status = 422

    def __init__(self, message: str, problems: Sequence[str]) -> None:
        super().__init__(message)
        self.problems = list(problems)

    def body(self) -> dict[str, Any]:
        return {"detail": self.message, "problems": self.problems}


def _dotted(loc: Sequence[object]) -> str:
    return ".".join(str(part) for part in loc)


def json_safe(value: Any) -> Any:
    """``value`` with anything JSON cannot hold (NaN, infinities, objects) made a string.

    Error bodies echo the input; an input ``NaN`` (which Python's JSON parser
    accepts) must not turn a 422 into a 500 when the response is rendered.
    """
    if isinstance(value, float):
        return value if math.isfinite(value) else str(value)
    if isinstance(value, str):
        return _utf8_safe(value)
    if value is None or isinstance(value, int | bool):
        return value
    if isinstance(value, dict):
        return {_utf8_safe(str(k)): json_safe(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [json_safe(v) for v in value]
    return _utf8_safe(str(value))


def _utf8_safe(text: str) -> str:
    """``text``, with a lone surrogate (``"\\ud800"``, which JSON parsers accept but UTF-8
    cannot encode) written as its escape: echoed in a 422, it must not make it a 500."""
    try:
        text.encode("utf-8")
    except UnicodeEncodeError:
        return text.encode("utf-8", "backslashreplace").decode("utf-8")
    return text


def validation_items(errors: Sequence[Any], prefix: Loc = ()) -> list[dict[str, Any]]:
    """Pydantic/FastAPI error dicts as JSON-safe ``{"loc", "msg", "type", "input"}`` items."""
    items = []
    for error in errors:
        item: dict[str, Any] = {
            "loc": [*prefix, *error.get("loc", ())],
            "msg": _utf8_safe(str(error.get("msg", ""))),
            "type": str(error.get("type", "value_error")),
        }
        if "input" in error:
            item["input"] = json_safe(error["input"])
        items.append(item)
    return items


def json_invalid_item() -> dict[str, Any]:
    """The 422 item of a body that is not JSON."""
    return {
        "loc": ["body"],
        "msg": "the body is not valid JSON (send UTF-8 JSON with Content-Type: application/json)",
        "type": "json_invalid",
    }


def install_error_handlers(app: FastAPI) -> None:
    """Map :class:`ApiError`, request validation errors and bugs to responses."""

    async def on_api_error(request: Request, exc: Exception) -> JSONResponse:
        assert isinstance(exc, ApiError)
        return JSONResponse(status_code=exc.status, content=exc.body(), headers=exc.headers)

    async def on_validation_error(request: Request, exc: Exception) -> JSONResponse:
        assert isinstance(exc, RequestValidationError)
        return JSONResponse(status_code=422, content={"detail": validation_items(exc.errors())})

    async def on_bug(request: Request, exc: Exception) -> JSONResponse:
        logger.exception("unhandled error in %s %s", request.method, request.url.path)
        return JSONResponse(
            status_code=500,
            content={"detail": f"internal error ({type(exc).__name__}); see the server log"},
        )

    async def on_http_error(request: Request, exc: Exception) -> JSONResponse:
        """FastAPI answers a body it cannot decode (not UTF-8 JSON) with 400; the API's
        contract for a body that is not valid JSON is 422 with the field path."""
        assert isinstance(exc, StarletteHTTPException)
        if exc.status_code == 400 and exc.detail == "There was an error parsing the body":
            return JSONResponse(status_code=422, content={"detail": [json_invalid_item()]})
        headers = getattr(exc, "headers", None)
        return JSONResponse(
            status_code=exc.status_code, content={"detail": exc.detail}, headers=headers
        )

    app.add_exception_handler(ApiError, on_api_error)
    app.add_exception_handler(RequestValidationError, on_validation_error)
    app.add_exception_handler(StarletteHTTPException, on_http_error)
    app.add_exception_handler(Exception, on_bug)


class BugBarrier:
    """Answer a bug with a 500 and keep the connection.

    Starlette's outermost error handler sends the 500 and then re-raises, and uvicorn
    answers a re-raised error by closing the connection (clients saw "connection
    reset"). This middleware, inside it, logs the bug and answers it instead.
    """

    def __init__(self, app: ASGIApp) -> None:
        self.app = app

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        started = False

        async def watched(message: Message) -> None:
            nonlocal started
            started = started or message["type"] == "http.response.start"
            await send(message)

        try:
            await self.app(scope, receive, watched)
        except Exception as exc:
            logger.exception("unhandled error in %s %s", scope["method"], scope["path"])
            if started:
                raise
            detail = f"internal error ({type(exc).__name__}); see the server log"
            await JSONResponse(status_code=500, content={"detail": detail})(scope, receive, send)
