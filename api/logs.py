"""Logging of the service: text or JSON lines, and an access log with request ids.

Every request gets an id: the client's ``X-Request-ID`` when it sends a usable one
(1-128 visible ASCII characters), else a new random one. The id is echoed in
the response's ``X-Request-ID`` header, written on the request's access-log line
(logger ``semwm.access``) and on every other record logged while the request
runs (attribute ``request_id``).

``--log-format json`` writes one JSON object per line: ``time`` (ISO 8601, UTC),
``level``, ``logger``, ``message``, ``request_id`` when there is one, the access
fields (``method``, ``path``, ``status``, ``duration_ms``, ``client``) on access
lines, and ``exception`` with the traceback when one was logged.
"""

from __future__ import annotations

import contextvars
import json
import logging
import re
import time
import uuid
from datetime import UTC, datetime
from typing import Any, Literal

from starlette.types import ASGIApp, Message, Receive, Scope, Send

LogFormat = Literal["text", "json"]
LOG_FORMATS: tuple[LogFormat, ...] = ("text", "json")
LOG_LEVELS = ("critical", "error", "warning", "info", "debug")

REQUEST_ID_HEADER = "x-request-id"
_USABLE_ID = re.compile(r"^[\x21-\x7e]{1,128}$")
_ACCESS_FIELDS = ("method", "path", "status", "duration_ms", "client")

request_id_var: contextvars.ContextVar[str | None] = contextvars.ContextVar(
    "semwm_request_id", default=None
)
access_logger = logging.getLogger("semwm.access")


class RequestIdFilter(logging.Filter):
    """Give every record the ``request_id`` of the request it was logged in (or None)."""

    def filter(self, record: logging.LogRecord) -> bool:
        if not hasattr(record, "request_id"):
            record.request_id = request_id_var.get()
        return True


class JsonFormatter(logging.Formatter):
    """One JSON object per record (see the module docstring for the fields)."""

    def format(self, record: logging.LogRecord) -> str:
        entry: dict[str, Any] = {
            "time": datetime.fromtimestamp(record.created, UTC).isoformat(timespec="milliseconds"),
            "level": record.levelname.lower(),
            "logger": record.name,
            "message": record.getMessage(),
        }
        request_id = getattr(record, "request_id", None)
        if request_id is not None:
            entry["request_id"] = request_id
        for name in _ACCESS_FIELDS:
            if hasattr(record, name):
                entry[name] = getattr(record, name)
        if record.exc_info:
            entry["exception"] = self.formatException(record.exc_info)
        return json.dumps(entry, default=str)


def logging_config(log_format: LogFormat = "text", level: str = "info") -> dict[str, Any]:
    """A :func:`logging.config.dictConfig` for uvicorn, the service and the access log."""
    if log_format not in LOG_FORMATS:
        raise ValueError(f"log format must be one of {', '.join(LOG_FORMATS)}; got {log_format!r}")
    if level.lower() not in LOG_LEVELS:
        raise ValueError(f"log level must be one of {', '.join(LOG_LEVELS)}; got {level!r}")
    formatter: dict[str, Any] = (
        {"()": JsonFormatter}
        if log_format == "json"
        else {"format": "%(asctime)s %(levelname)s %(name)s: %(message)s"}
    )
    handler = {
        "class": "logging.StreamHandler",
        "formatter": "default",
        "filters": ["request_id"],
        "stream": "ext://sys.stderr",
    }
    loggers = ("uvicorn", "uvicorn.error", "api", "semwm", "semwm.access")
    return {
        "version": 1,
        "disable_existing_loggers": False,
        "filters": {"request_id": {"()": RequestIdFilter}},
        "formatters": {"default": formatter},
        "handlers": {"default": handler},
        "loggers": {
            name: {"handlers": ["default"], "level": level.upper(), "propagate": False}
            for name in loggers
        },
    }


def usable_request_id(value: str | None) -> str:
    """The client's id when usable, else a new one (32 hex digits)."""
    if value is not None and _USABLE_ID.match(value):
        return value
    return uuid.uuid4().hex


class RequestIdMiddleware:
    """Give each HTTP request an id, echo it as ``X-Request-ID`` and log an access line."""

    def __init__(self, app: ASGIApp) -> None:
        self.app = app

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        given = next(
            (v.decode("latin-1") for k, v in scope["headers"] if k == REQUEST_ID_HEADER.encode()),
            None,
        )
        request_id = usable_request_id(given)
        token = request_id_var.set(request_id)
        started = time.perf_counter()
        status = 500

        async def send_with_id(message: Message) -> None:
            nonlocal status
            if message["type"] == "http.response.start":
                status = int(message["status"])
                headers = [(k, v) for k, v in message.get("headers", []) if k != b"x-request-id"]
                headers.append((b"x-request-id", request_id.encode("latin-1")))
                message = {**message, "headers": headers}
            await send(message)

        try:
            await self.app(scope, receive, send_with_id)
        finally:
            duration_ms = round((time.perf_counter() - started) * 1000.0, 3)
            client = scope.get("client")
            query = scope.get("query_string", b"").decode("latin-1")
            path = scope["path"] + (f"?{query}" if query else "")
            access_logger.info(
                '%s "%s %s" %d %.1f ms id=%s',
                f"{client[0]}:{client[1]}" if client else "-",
                scope["method"],
                path,
                status,
                duration_ms,
                request_id,
                extra={
                    "request_id": request_id,
                    "method": scope["method"],
                    "path": path,
                    "status": status,
                    "duration_ms": duration_ms,
                    "client": f"{client[0]}:{client[1]}" if client else None,
                },
            )
            request_id_var.reset(token)
