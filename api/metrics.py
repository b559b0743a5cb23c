"""Prometheus metrics of the service (``GET /metrics``), one registry per app.

Counters move with every change the service applies (its listener) and every
refused ``POST /detections`` (:class:`DetectionMetricsMiddleware`); the world's
sizes are read at scrape time (:class:`WorldCollector`), so scraping costs one
lock acquisition and ingesting costs two counter increments.

Metric names (all prefixed ``semwm_``): ``detections_accepted_total``,
``detections_ignored_total{source,reason}``, ``detections_refused_total{reason}``,
``ingest_latency_seconds`` (the whole ``POST /detections`` request),
``ingest_apply_seconds`` (the world model's part, under the lock),
``ingest_stage_seconds{stage}`` (an accepted request's time by stage, a summary;
with ``stage_timing`` only: :mod:`api.stages`), ``objects``, ``stored_hypotheses``,
``joint_hypotheses_log10``, ``clusters``, ``tracks``, ``held_scans``,
``replayed_scans``, ``knowledge_version``, ``world_time_seconds``,
``stream_subscribers``.
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable, Iterable
from typing import Any

from prometheus_client import CollectorRegistry, Counter, Histogram
from prometheus_client.core import GaugeMetricFamily, InfoMetricFamily, Metric
from prometheus_client.registry import Collector
from starlette.types import ASGIApp, Message, Receive, Scope, Send

from api.service import WorldChange, WorldService
from api.stages import StageCollector, StageTotals, time_collections

LATENCY_BUCKETS = (0.0005, 0.001, 0.002, 0.005, 0.01, 0.02, 0.05, 0.1, 0.2, 0.5, 1.0, 2.0, 5.0)

REFUSAL_REASONS = {
    400: "malformed",
    401: "unauthorized",
    403: "forbidden",
    409: "out_of_order",
    413: "too_large",
    415: "unsupported_media_type",
    422: "invalid",
    429: "rate_limited",
    503: "unavailable",
}
"""HTTP status of a refused ``POST /detections`` -> the ``reason`` label."""


def refusal_reason(status: int) -> str:
    return REFUSAL_REASONS.get(status, f"http_{status}")


def detections_in(body: bytes) -> int:
    """How many detections a request body carried: a batch's length, else 1."""
    try:
        payload = json.loads(body)
    except (ValueError, UnicodeDecodeError):
        return 1
    if isinstance(payload, dict) and isinstance(payload.get("detections"), list):
        return max(len(payload["detections"]), 1)
    return 1


class WorldCollector(Collector):
    """Gauges of the world read at scrape time (nothing before the service exists)."""

    def __init__(
        self,
        service: Callable[[], WorldService | None],
        subscribers: Callable[[], int],
    ) -> None:
        self._service = service
        self._subscribers = subscribers

    def collect(self) -> Iterable[Metric]:
        service = self._service()
        if service is None:
            return
        yield InfoMetricFamily(
            "semwm_engine",
            "The engine running the world model's numeric kernels (python or rust)",
            value={"engine": service.engine},
        )
        stats = service.stats()
        gauges: list[tuple[str, str, Any]] = [
            ("objects", "Objects in the most probable hypothesis", stats["objects"]),
            ("stored_hypotheses", "Hypotheses stored (sum over clusters)", stats["hypotheses"]),
            ("joint_hypotheses_log10", "log10 of the global hypotheses (combinations of "
             "the clusters')", stats["hypotheses_log10_joint"]),
            ("clusters", "Independent clusters of objects", stats["clusters"]),
            ("tracks", "Distinct object versions stored", stats["tracks"]),
            ("held_scans", "Scans held by --hold, not yet processed", stats["held_scans"]),
            ("replayed_scans", "Scans processed again because an older one came after them "
             "(since start or reset; --hold avoids them)", stats["replayed_scans"]),
            ("arrival_order_scans", "Concurrent scans processed in arrival order instead "
             "of replayed (--order-tolerance; since start or reset)",
             stats["arrival_order_scans"]),
            ("knowledge_version", "Knowledge version: 1 at start, +1 per edit or reload",
             stats["knowledge_version"]),
            ("stream_subscribers", "Open GET /world/stream connections", self._subscribers()),
        ]  # fmt: skip
        damage = service.store_damage
        lost = damage[1] if damage else None
        gauges += [
            ("store_damaged", "1 when the data directory's last start found damage "
             "(docs/persistence.md)", 1 if damage else 0),
            ("store_lost_records", "Records the last start found lost",
             0 if lost is None else lost[1] - lost[0] + 1),
            ("store_write_refusals", "Writes refused since start because the store could "
             "not write (a full disk)", service.storage_refusals),
            ("writes_shed", "Writes answered 503 since start because more than "
             "--max-waiting were queued for the world", service.shed),
            ("late_scans_refused_behind", "Late scans answered 409 since start instead of "
             "replayed, because replays took more than --replay-limit of the service's "
             "time (docs/operations.md, overload)", service.shed_late),
            ("late_scans_dropped", "Late scans dropped since start for sources whose "
             "policy is late: drop", service.dropped_late),
            ("replay_share", "Share of the last second the world spent replaying scans "
             "(above --replay-limit late scans are refused)", service.replay_share()),
        ]  # fmt: skip
        if stats["time"] is not None:
            gauges.append(("world_time_seconds", "Latest accepted detection time", stats["time"]))
        for name, documentation, value in gauges:
            yield GaugeMetricFamily(f"semwm_{name}", documentation, value=float(value))

    def describe(self) -> Iterable[Metric]:
        return []


class Metrics:
    """The registry of one app and the instruments the service's changes move."""

    def __init__(self) -> None:
        self.registry = CollectorRegistry()
        self.accepted = Counter(
            "semwm_detections_accepted",
            "Detections applied to the world",
            registry=self.registry,
        )
        self.ignored = Counter(
            "semwm_detections_ignored",
            "Detections accepted but not used, by source and reason: out_of_range (beyond "
            "their detector's range) or outside_region (clearly outside the region)",
            ["source", "reason"],
            registry=self.registry,
        )
        self.refused = Counter(
            "semwm_detections_refused",
            "Detections refused (every detection of a refused batch), by reason",
            ["reason"],
            registry=self.registry,
        )
        self.request_seconds = Histogram(
            "semwm_ingest_latency_seconds",
            "POST /detections: time from request to response (s), accepted or refused",
            buckets=LATENCY_BUCKETS,
            registry=self.registry,
        )
        self.apply_seconds = Histogram(
            "semwm_ingest_apply_seconds",
            "Time the world model took to apply an accepted batch (s)",
            buckets=LATENCY_BUCKETS,
            registry=self.registry,
        )
        self.stages: StageTotals | None = None
        """Accepted requests' seconds by stage, once :meth:`time_stages` is called."""

    def time_stages(self) -> StageTotals:
        """Time accepted requests by stage (:mod:`api.stages`) and export the sums
        (``semwm_ingest_stage_seconds``); :class:`api.ingest_fast.FastIngest` adds them."""
        if self.stages is None:
            self.stages = StageTotals()
            self.registry.register(StageCollector(self.stages))
            time_collections()
        return self.stages

    def watch(
        self, service: Callable[[], WorldService | None], subscribers: Callable[[], int]
    ) -> None:
        """Report the world's sizes, read at scrape time."""
        self.registry.register(WorldCollector(service, subscribers))

    def on_change(self, change: WorldChange) -> None:
        """The service's listener: count applied detections and time the apply."""
        if change.kind == "detections":
            self.accepted.inc(change.applied)
            for item in change.ignored_detections:
                self.ignored.labels(source=item.source or "", reason=item.reason).inc()
            self.apply_seconds.observe(change.seconds)


class DetectionMetricsMiddleware:
    """Time every ``POST /detections`` and count the detections of refused ones by reason.

    The body chunks the route reads are kept (no copy); only a refused request's
    body is parsed again, to count its detections.
    """

    def __init__(self, app: ASGIApp, metrics: Metrics, path: str = "/detections") -> None:
        self.app = app
        self.metrics = metrics
        self.path = path

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http" or scope["method"] != "POST" or scope["path"] != self.path:
            await self.app(scope, receive, send)
            return
        started = time.perf_counter()
        chunks: list[bytes] = []
        status = 500

        async def receive_kept() -> Message:
            message = await receive()
            if message["type"] == "http.request":
                chunks.append(message.get("body", b""))
            return message

        async def send_seen(message: Message) -> None:
            nonlocal status
            if message["type"] == "http.response.start":
                status = int(message["status"])
            await send(message)

        try:
            await self.app(scope, receive_kept, send_seen)
        finally:
            self.metrics.request_seconds.observe(time.perf_counter() - started)
            if status >= 400:
                count = detections_in(b"".join(chunks))
                self.metrics.refused.labels(reason=refusal_reason(status)).inc(count)
