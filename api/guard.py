"""Browser safety, tokens and body limits, checked before a request reaches a route.

One pure ASGI middleware, :class:`RequestGuard`, in this order:

1. ``OPTIONS`` (not a CORS preflight) is answered with the ``Allow`` header of every
   method the path has; a 405 lists them all too.
2. Tokens: with a write token, every write (POST, PUT, PATCH, DELETE) needs
   ``Authorization: Bearer <token>``; with a read token, every read but ``/health``,
   ``/ready`` and the docs needs the read or the write token. 401 with
   ``WWW-Authenticate`` otherwise. Tokens are compared in constant time.
3. Cross-site writes: a write whose ``Origin`` is neither the service itself nor an
   allowed origin is 403; a write with a body (or a ``Content-Type``) that is not
   ``application/json`` is 415. Together they refuse the "simple requests" a web
   page can send without a CORS preflight.
4. Body size: a ``Content-Length`` above the limit is 413 before anything is read; a
   body without one is counted as it arrives and cut off at the limit (413).

Each refusal is a JSON ``{"detail": message}`` and reaches no route, so it changes
nothing.
"""

from __future__ import annotations

import hmac
import json
from collections.abc import Iterable, Iterator, Sequence

from starlette.exceptions import HTTPException
from starlette.routing import BaseRoute
from starlette.types import ASGIApp, Message, Receive, Scope, Send

WRITE_METHODS = frozenset({"POST", "PUT", "PATCH", "DELETE"})
OPEN_PATHS = frozenset({"/health", "/ready", "/docs", "/redoc", "/openapi.json"})
OPEN_PREFIX = "/static/"
"""Packaged assets (the docs pages' and the live page's scripts): no data, always open."""


def bearer(headers: dict[str, str]) -> str | None:
    """The token of an ``Authorization: Bearer <token>`` header, or ``None``."""
    scheme, _, token = headers.get("authorization", "").partition(" ")
    return token.strip() if scheme.lower() == "bearer" and token.strip() else None


def token_matches(given: str | None, expected: Iterable[str]) -> bool:
    """Constant-time comparison of ``given`` with each expected token."""
    if given is None:
        return False
    found = False
    for token in expected:
        found |= hmac.compare_digest(given.encode(), token.encode())
    return found


def is_json(content_type: str) -> bool:
    media = content_type.split(";", 1)[0].strip().lower()
    return media == "application/json" or (
        media.startswith("application/") and media.endswith("+json")
    )


def _flat(routes: Sequence[BaseRoute]) -> Iterator[BaseRoute]:
    """Every route, including those of routers FastAPI keeps as one included entry."""
    for route in routes:
        inner = getattr(route, "original_router", None)
        if inner is not None:
            yield from _flat(inner.routes)
        else:
            yield route


def allowed_methods(routes: Sequence[BaseRoute], scope: Scope) -> list[str]:
    """Every method some route serves at the request's path."""
    path = scope["path"]
    methods: set[str] = set()
    for route in _flat(routes):
        regex = getattr(route, "path_regex", None)
        route_methods = getattr(route, "methods", None)
        if regex is not None and route_methods and regex.match(path):
            methods |= set(route_methods)
    if methods:
        methods.add("OPTIONS")
        if "GET" in methods:
            methods.add("HEAD")
    return sorted(methods)


class RequestGuard:
    """The checks of this module around ``app`` (see the module docstring).

    Parameters
    ----------
    routes
        The application's routes (for ``Allow``).
    token, read_token
        The write and read bearer tokens (``None``: open).
    origins
        Browser origins allowed to write, besides the service's own.
    max_body
        The largest body in bytes.
    """

    def __init__(
        self,
        app: ASGIApp,
        routes: Sequence[BaseRoute],
        token: str | None,
        read_token: str | None,
        origins: Sequence[str],
        max_body: int,
    ) -> None:
        self.app = app
        self.routes = routes
        self.token = token
        self.read_token = read_token
        self.origins = {o.rstrip("/").lower() for o in origins}
        self.max_body = max_body

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        headers = {k.decode("latin-1").lower(): v.decode("latin-1") for k, v in scope["headers"]}
        method: str = scope["method"]
        refusal = self.refusal(scope, method, headers)
        if refusal is not None:
            status, message, extra = refusal
            await _respond(send, status, message, extra)
            return
        if method == "OPTIONS" and "access-control-request-method" not in headers:
            methods = allowed_methods(self.routes, scope)
            if methods:
                await _respond(send, 204, None, {"allow": ", ".join(methods)})
                return
        await self.app(scope, self.limited(receive), self.allow_on_405(scope, send))

    def refusal(
        self, scope: Scope, method: str, headers: dict[str, str]
    ) -> tuple[int, str, dict[str, str]] | None:
        """Why the request is refused before a route sees it: status, message, headers."""
        write = method in WRITE_METHODS
        given = bearer(headers)
        challenge = {"www-authenticate": 'Bearer realm="semwm"'}
        if write and self.token is not None and not token_matches(given, [self.token]):
            why = "a missing" if given is None else "an invalid"
            return (
                401,
                f"{method} needs the write token (Authorization: Bearer ...); got {why} token",
                challenge,
            )
        path: str = scope["path"]
        if (
            not write
            and method != "OPTIONS"
            and self.read_token is not None
            and path not in OPEN_PATHS
            and not path.startswith(OPEN_PREFIX)
            and not token_matches(given, [t for t in (self.read_token, self.token) if t])
        ):
            why = "a missing" if given is None else "an invalid"
            return (
                401,
                f"reading needs the read token (Authorization: Bearer ...); got {why} token",
                challenge,
            )
        if not write:
            return None
        origin = headers.get("origin")
        if origin is not None and not self.same_or_allowed(origin, scope, headers):
            return (
                403,
                f"a write from the web origin {origin!r} is refused (cross-site request); "
                "allow the origin with --cors-origin",
                {},
            )
        content_type = headers.get("content-type")
        has_body = (
            headers.get("content-length", "0") not in ("", "0") or "transfer-encoding" in headers
        )
        if (has_body or content_type is not None) and not is_json(content_type or ""):
            found = content_type or "no Content-Type"
            return (
                415,
                f"send the body as JSON with Content-Type: application/json; found {found}",
                {},
            )
        length = headers.get("content-length")
        if length is not None and length.isdigit() and int(length) > self.max_body:
            return 413, self.too_large(int(length)), {"connection": "close"}
        return None

    def same_or_allowed(self, origin: str, scope: Scope, headers: dict[str, str]) -> bool:
        origin = origin.rstrip("/").lower()
        own = f"{scope.get('scheme', 'http')}://{headers.get('host', '')}".lower()
        return origin == own or origin in self.origins

    def too_large(self, size: int | None) -> str:
        found = f"{size} bytes" if size is not None else "more"
        return f"the request body is limited to {self.max_body} bytes; found {found}"

    def limited(self, receive: Receive) -> Receive:
        """``receive`` that stops a body at ``max_body`` bytes with a 413."""
        received = 0

        async def receive_limited() -> Message:
            nonlocal received
            message = await receive()
            if message["type"] == "http.request":
                received += len(message.get("body", b""))
                if received > self.max_body:
                    raise HTTPException(413, self.too_large(None))
            return message

        return receive_limited

    def allow_on_405(self, scope: Scope, send: Send) -> Send:
        """``send`` that lists every method of the path in a 405's ``Allow``."""

        async def send_with_allow(message: Message) -> None:
            if message["type"] == "http.response.start" and message["status"] == 405:
                methods = ", ".join(allowed_methods(self.routes, scope)).encode()
                headers = [(k, v) for k, v in message.get("headers", []) if k.lower() != b"allow"]
                message = {**message, "headers": [*headers, (b"allow", methods)]}
            await send(message)

        return send_with_allow


async def _respond(send: Send, status: int, message: str | None, headers: dict[str, str]) -> None:
    body = b"" if message is None else json.dumps({"detail": message}).encode()
    raw: list[tuple[bytes, bytes]] = [(k.encode(), v.encode()) for k, v in headers.items()]
    if message is not None:
        raw.append((b"content-type", b"application/json"))
    raw.append((b"content-length", str(len(body)).encode()))
    await send({"type": "http.response.start", "status": status, "headers": raw})
    await send({"type": "http.response.body", "body": body})
