"""Where a ``POST /detections`` request's time goes, stage by stage (issue 29).

Once the world model's scan takes microseconds, the service around it is most of a
request's cost. With ``stage_timing`` on (``SEMWM_STAGE_TIMING=1``; off by default),
every request :class:`api.ingest_fast.FastIngest` answers 200 (every accepted batch:
a refusal or a body the route has to check is not counted) is timed by stage, and
``GET /metrics`` exports the sums as ``semwm_ingest_stage_seconds``, a summary with a
``stage`` label (``_sum``: seconds, ``_count``: requests timed, the same for every
stage; a stage a request did not pass through counts 0 s for it).

The stages are exclusive: time spent in a stage nested in another (``model`` within
``service``) counts for the inner one only, so a request's stages add up to its time
in :class:`~api.ingest_fast.FastIngest` (after the guards, the request id and the
metrics middleware, which ``semwm_ingest_latency_seconds`` counts too):

``read``
    The body off the socket: the app's ``receive`` calls until the whole body is in
    (uvicorn hands over what it has read; a large body's later chunks are waited for).
``parse``
    The body's JSON parsed and checked against the wire schema: one pydantic-core
    call (a body it refuses is parsed again to say what is wrong, also counted here).
``handoff``
    The hand-over to an ingest thread and back (bodies above ``INLINE_BODY``, or when
    the world was busy); 0 for a body applied on the event loop.
``lock``
    Waiting for the world's lock (other requests' changes and reads).
``sources``
    Placing the batch on the sources' clocks and in time order (:mod:`semwm.sources`),
    the late scans' policies, the bound on sources, and counting the batch for its
    sources after.
``save``
    The copy of the world model's tables that undoes a change that fails.
``model``
    :meth:`semwm.WorldModel.ingest`: the knowledge checks, the MHF scan, publishing
    ids and the world. (``benchmarks/bench_http.py`` times its parts in its servers.)
``notify``
    The listeners (metrics, the live feed) and the summary ``/health`` answers.
``service``
    The rest of the service's work on the batch: the overload check, the journal's
    hooks (with ``--data-dir``), the ignored detections' warnings, the idempotency keys.
``respond``
    The answer's JSON and its send.
``gc``
    Python's cyclic garbage collector, wherever it ran during the request (its time
    is taken from the stage it interrupted). The world model pauses it while it
    ingests (:mod:`semwm.collector`), so it tends to run just after.
``other``
    What is left of the request in :class:`~api.ingest_fast.FastIngest` (reading its
    headers, finding the service).

Cost, measured on a 2-core x86_64 box shared with other jobs (CPU time, the best of
5 x 20,000): a request's 13 stages and their sums about 10 µs when timed, 2-3 µs when
not (a no-op each), against 100-1,000 µs of a request over loopback: hence off by
default. Prometheus histograms per stage would cost about 2.5 µs more per stage and
request (``Histogram.observe``), hence sums and counts only.
"""

from __future__ import annotations

import gc
import threading
import time
from collections import defaultdict
from collections.abc import Callable, Iterable, Mapping
from contextvars import ContextVar, Token
from types import TracebackType

from prometheus_client.core import Metric, SummaryMetricFamily
from prometheus_client.registry import Collector

STAGES = (
    "read",
    "parse",
    "handoff",
    "lock",
    "sources",
    "save",
    "model",
    "notify",
    "service",
    "respond",
    "gc",
    "other",
)
"""The stages the service times, in a request's order (see the module docstring)."""

OUTER = "other"
"""The stage of a request's time outside every named stage."""

clock: Callable[[], float] = time.perf_counter
"""The clock of the stages (s); tests replace it."""

_CURRENT: ContextVar[RequestStages | None] = ContextVar("semwm_request_stages", default=None)


class RequestStages:
    """One request's seconds by stage, each exclusive of the stages nested in it."""

    __slots__ = ("_collecting", "_since", "_stack", "seconds")

    def __init__(self) -> None:
        self.seconds: defaultdict[str, float] = defaultdict(float)
        self._stack = [OUTER]
        self._since = clock()
        self._collecting = 0.0

    def enter(self, name: str) -> None:
        """Stop the current stage's clock and start ``name``'s."""
        now = clock()
        self.seconds[self._stack[-1]] += now - self._since
        self._stack.append(name)
        self._since = now

    def leave(self) -> None:
        """Stop the current stage's clock and go on with the one it is nested in."""
        now = clock()
        self.seconds[self._stack.pop()] += now - self._since
        self._since = now

    def finish(self) -> dict[str, float]:
        """Stop every clock; the seconds by stage."""
        while self._stack:
            self.leave()
        return dict(self.seconds)


class _Stage:
    """``with stage(name):`` for a timed request (:meth:`RequestStages.enter` and
    :meth:`~RequestStages.leave` written out: this runs a dozen times per request)."""

    __slots__ = ("_name", "_stages")

    def __init__(self, stages: RequestStages, name: str) -> None:
        self._stages = stages
        self._name = name

    def __enter__(self) -> None:
        stages, now = self._stages, clock()
        stack = stages._stack
        stages.seconds[stack[-1]] += now - stages._since
        stack.append(self._name)
        stages._since = now

    def __exit__(
        self,
        kind: type[BaseException] | None,
        error: BaseException | None,
        traceback: TracebackType | None,
    ) -> None:
        stages, now = self._stages, clock()
        stages.seconds[stages._stack.pop()] += now - stages._since
        stages._since = now


class _Untimed:
    """``with stage(name):`` outside a timed request: nothing."""

    __slots__ = ()

    def __enter__(self) -> None:
        return None

    def __exit__(
        self,
        kind: type[BaseException] | None,
        error: BaseException | None,
        traceback: TracebackType | None,
    ) -> None:
        return None


_UNTIMED = _Untimed()


def stage(name: str) -> _Stage | _Untimed:
    """A context manager timing ``name`` for the request being timed (in this thread's
    context: an ingest thread runs with the request's), nothing outside one."""
    stages = _CURRENT.get()
    return _UNTIMED if stages is None else _Stage(stages, name)


def start() -> tuple[RequestStages, Token[RequestStages | None]]:
    """Time a request from now: its stages, and the token :func:`stop` takes."""
    stages = RequestStages()
    return stages, _CURRENT.set(stages)


def stop(token: Token[RequestStages | None]) -> None:
    """End the timing :func:`start` began (its seconds stay in its :class:`RequestStages`)."""
    _CURRENT.reset(token)


def _collection(phase: str, info: dict[str, int]) -> None:
    """``gc.callbacks``: a collection during a timed request counts as its ``gc`` stage,
    taken from the stage it interrupted (the collection runs in the thread, and so in
    the context, of the code that triggered it)."""
    stages = _CURRENT.get()
    if stages is None:
        return
    if phase == "start":
        stages._collecting = clock()
        return
    took = clock() - stages._collecting
    stages.seconds["gc"] += took
    stages.seconds[stages._stack[-1]] -= took


def time_collections() -> None:
    """Count the garbage collector's runs in timed requests (once per process)."""
    if _collection not in gc.callbacks:
        gc.callbacks.append(_collection)


class StageTotals:
    """The seconds of every timed request by stage, and how many requests (thread-safe)."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._seconds: dict[str, float] = {}
        self._count = 0

    def add(self, seconds: Mapping[str, float]) -> None:
        """Count one request's seconds by stage."""
        with self._lock:
            self._count += 1
            for name, value in seconds.items():
                self._seconds[name] = self._seconds.get(name, 0.0) + value

    def totals(self) -> tuple[int, dict[str, float]]:
        """The requests counted, and their seconds by stage (every stage of :data:`STAGES`
        first, in order; others a benchmark times after)."""
        with self._lock:
            seconds = {name: self._seconds.get(name, 0.0) for name in STAGES}
            seconds.update(self._seconds)
            return self._count, seconds


class StageCollector(Collector):
    """``semwm_ingest_stage_seconds{stage}``: a summary of :class:`StageTotals`."""

    def __init__(self, totals: StageTotals) -> None:
        self._totals = totals

    def collect(self) -> Iterable[Metric]:
        count, seconds = self._totals.totals()
        family = SummaryMetricFamily(
            "semwm_ingest_stage_seconds",
            "Accepted POST /detections requests: seconds by stage (read, parse, handoff, "
            "lock, sources, save, model, notify, service, respond, gc, other; exclusive, "
            "they add up to the request's time in the app), count: requests",
            labels=["stage"],
        )
        for name, value in seconds.items():
            family.add_metric([name], count_value=count, sum_value=value)
        yield family

    def describe(self) -> Iterable[Metric]:
        return []
