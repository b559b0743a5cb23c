"""The FastAPI application: ``create_app(settings)``.

Nothing heavy happens at import or in :func:`create_app`: the knowledge file is
read and the world model built in the lifespan, when the server starts.
"""

from __future__ import annotations

import gc
import logging
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from typing import TYPE_CHECKING, Any

from fastapi import FastAPI
from fastapi.middleware.cors import CORSMiddleware
from fastapi.openapi.utils import get_openapi
from fastapi.staticfiles import StaticFiles
from pydantic import BaseModel
from starlette.middleware.trustedhost import TrustedHostMiddleware

from api.deps import get_world
from api.errors import BugBarrier, install_error_handlers
from api.feed import StreamSlots, WorldFeed
from api.guard import RequestGuard
from api.ingest_fast import FastIngest
from api.logs import RequestIdMiddleware
from api.metrics import DetectionMetricsMiddleware, Metrics
from api.offline_docs import install_offline_docs
from api.openapi_links import add_links, operation_id
from api.persistence import attach_persistence
from api.routes import (
    actions,
    detections,
    knowledge,
    live,
    local,
    metrics,
    persistence,
    sources,
    system,
    world,
)
from api.schemas import DetectionBatch, DetectionIn
from api.service import WorldService
from api.settings import Settings
from semwm.sources import TimeGuard

if TYPE_CHECKING:
    from api.mqtt_bridge import MqttBridge

logger = logging.getLogger("api")

DESCRIPTION = """\
A semantic world model for robots: post detections, ask for the objects.

Times are in seconds, positions in metres, covariances in square metres. A batch of
detections is applied whole or not at all; refusals are 4xx with the field path of
every problem, and leave the world as it was.
"""


def create_app(settings: Settings, *, fast_ingest: bool = True) -> FastAPI:
    """Build the application.

    The world model is built from ``settings.knowledge`` when the app starts
    (lifespan). Tests may instead override :func:`api.deps.get_world`.
    ``fast_ingest``: accepted ``POST /detections`` batches are answered by
    :class:`api.ingest_fast.FastIngest`; ``False`` sends every one through the route
    (the tests compare the two).
    """

    @asynccontextmanager
    async def lifespan(app: FastAPI) -> AsyncIterator[None]:
        if get_world not in app.dependency_overrides:
            if settings.knowledge is None:
                raise RuntimeError(
                    "no knowledge file: pass --knowledge FILE or set SEMWM_KNOWLEDGE"
                )
            app.state.world = WorldService.from_file(
                settings.knowledge,
                engine=settings.engine,
                reorder_window=settings.reorder_window,
                hold=settings.hold,
                order_tolerance=settings.order_tolerance,
                write_back=settings.write_back,
                time_guard=TimeGuard(settings.max_ahead, settings.max_jump),
                max_sources=settings.max_sources,
                idempotency_keys=settings.idempotency_keys,
                stuck_after=settings.stuck_after,
            )
            app.state.world.max_waiting = settings.max_waiting
            app.state.world.replay_limit = settings.replay_limit
            logger.info(
                "world model built from %s (engine %s)",
                settings.knowledge,
                app.state.world.engine,
            )
        with attach_persistence(app, settings):
            async with _live(app, settings, _service(app)):
                # The bridge starts on the restored model (queued batches apply at once and
                # are journaled) and stops before the journal closes.
                bridge = _start_mqtt(app, settings) if settings.mqtt is not None else None
                # What start-up built lives as long as the process: keep it out of the
                # collector's full passes, which the world's many short-lived objects
                # trigger (about 15 % of the server's CPU on a team's load).
                gc.freeze()
                try:
                    yield
                finally:
                    if bridge is not None:
                        bridge.stop()

    app = FastAPI(
        title="semwm",
        version="0.1.0",
        description=DESCRIPTION,
        lifespan=lifespan,
        docs_url=None,
        redoc_url=None,
        generate_unique_id_function=operation_id,
    )
    app.state.settings = settings
    app.state.feed = None
    app.state.metrics = Metrics()
    if settings.stage_timing:
        app.state.metrics.time_stages()
    app.state.metrics.watch(
        lambda: app.state.feed.service if app.state.feed else None,
        lambda: app.state.feed.subscriber_count if app.state.feed else 0,
    )
    install_error_handlers(app)
    routers = (
        detections,
        actions,
        world,
        knowledge,
        system,
        persistence,
        sources,
        local,
        live,
        metrics,
    )
    for module in routers:
        app.include_router(module.router)
    install_offline_docs(app)
    app.mount("/static", StaticFiles(directory=live.STATIC_DIR), name="static")
    _add_guards(app, settings, fast_ingest)
    # Outside the guards: refused requests are counted and get a request id too.
    app.add_middleware(DetectionMetricsMiddleware, metrics=app.state.metrics)
    app.add_middleware(RequestIdMiddleware)

    def openapi() -> dict[str, Any]:
        if app.openapi_schema is None:
            schema = get_openapi(
                title=app.title,
                version=app.version,
                description=app.description,
                routes=app.routes,
            )
            _add_schemas(schema, (DetectionIn, DetectionBatch))
            add_links(schema)
            app.openapi_schema = schema
        return app.openapi_schema

    app.openapi = openapi  # type: ignore[method-assign]
    return app


def _add_guards(app: FastAPI, settings: Settings, fast_ingest: bool) -> None:
    """Tokens, browser safety and body limits (:mod:`api.guard`), CORS, allowed hosts.

    The last added runs first: the ``Host`` check, then CORS (preflights), then the
    guard, then the barrier that answers a bug with a 500.
    """
    # Innermost: after every guard, accepted batches skip the framework (api.ingest_fast).
    if fast_ingest:
        app.add_middleware(
            FastIngest,
            service=lambda: _service(app),
            max_batch=settings.max_batch,
            stages=app.state.metrics.stages,  # stage_timing: each accepted request's stages
        )
    app.add_middleware(BugBarrier)
    app.add_middleware(
        RequestGuard,
        routes=app.router.routes,
        token=settings.token.get_secret_value() if settings.token else None,
        read_token=settings.read_token.get_secret_value() if settings.read_token else None,
        origins=settings.cors_origins,
        max_body=settings.max_body,
    )
    if settings.cors_origins:
        app.add_middleware(
            CORSMiddleware,
            allow_origins=list(settings.cors_origins),
            allow_methods=["GET", "POST", "PUT"],
            allow_headers=["Authorization", "Content-Type", "Idempotency-Key"],
            expose_headers=["X-Semwm-Commit", "Idempotent-Replayed"],
        )
    app.add_middleware(TrustedHostMiddleware, allowed_hosts=settings.hosts())


def _start_mqtt(app: FastAPI, settings: Settings) -> MqttBridge:
    """Join the broker of ``settings.mqtt`` with the app's world service (docs/mqtt.md)."""
    from api.mqtt_bridge import start_bridge

    service = getattr(app.state, "world", None) or app.dependency_overrides[get_world]()
    return start_bridge(service, settings)


def _service(app: FastAPI) -> WorldService:
    """The service the routes use: the lifespan's, or a test's override of ``get_world``."""
    override = app.dependency_overrides.get(get_world)
    service: WorldService = override() if override is not None else app.state.world
    return service


@asynccontextmanager
async def _live(app: FastAPI, settings: Settings, service: WorldService) -> AsyncIterator[None]:
    """Metrics counting, the push feed of ``/world/stream`` and the optional Foxglove bridge."""
    stop_counting = service.add_listener(app.state.metrics.on_change)
    feed = WorldFeed(service)
    await feed.start()
    app.state.feed = feed
    app.state.stream_slots = StreamSlots(settings.max_streams, settings.max_client_streams)
    bridge = None
    if settings.foxglove_port is not None:
        from api.foxglove_bridge import FoxgloveBridge

        bridge = FoxgloveBridge(settings.host, settings.foxglove_port)
        app.state.foxglove = bridge
        feed.add_consumer(bridge.publish)
        logger.info("Foxglove WebSocket on ws://%s:%d", settings.host, bridge.port)
    try:
        yield
    finally:
        await feed.stop()
        app.state.feed = None
        stop_counting()
        if bridge is not None:
            bridge.close()


def end_streams(app: FastAPI) -> None:
    """End every open ``/world/stream`` response (before a server shuts down). In the loop."""
    feed: WorldFeed | None = getattr(app.state, "feed", None)
    if feed is not None:
        feed.close_streams()


def _add_schemas(schema: dict[str, Any], models: tuple[type[BaseModel], ...]) -> None:
    """Add models a route validates by hand (``POST /detections``) to the components."""
    components = schema.setdefault("components", {}).setdefault("schemas", {})
    for model in models:
        json_schema = model.model_json_schema(ref_template="#/components/schemas/{model}")
        components.update(json_schema.pop("$defs", {}))
        components[model.__name__] = json_schema
