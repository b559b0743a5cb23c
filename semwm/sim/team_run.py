"""A team over a network: flat or two-level (paper 000), clocks offset (paper 003).

:func:`run_team` plays a scenario whose detections come from several sources
(RoboCup's peers) through a simulated team:

* every source has its own clock, ``offset`` s behind the service clock (uniform in
  ``±max_offset``), and stamps what it sends with it;
* every message takes ``latency`` s (uniform in ``[low, high]``) to the receiver;
* with ``sync`` the receiver estimates each clock with :mod:`semwm.clock` from
  simulated exchanges (five at start, then every ``sync_period`` s, each direction
  its own latency) and places stamps on its clock (:mod:`semwm.sources`);
* the receiver processes what arrives in time order (paper 001 sorts shared
  measurements by timestamp), in one of two ways (``Network.receiver``):

  - ``"reorder"`` (default, what the service does): every message is processed on
    arrival by a world with a reorder window of ``hold`` s, which replays the later
    scans when an older one arrives; older than the window is late and dropped;
  - ``"hold"``: a sorting buffer; a message is processed once its (placed) stamp is
    ``hold`` s old; what is older than the last processed time is late and dropped.

  ``"hold"`` makes accuracy depend on the phase of the stamps: the world evaluated
  at ``now`` holds a message stamped ``now - hold`` but not one stamped a
  microsecond later, which waits for the next evaluation. In the simulated
  scenarios scans, reports and truth frames share one time grid, so with ideal
  clocks every report lands exactly on that boundary, while any clock error (even
  1 µs, of either sign) makes half the sources' reports wait one more report period
  (docs/team.md, section 4);

``levels=1``: every detection is a message to one model. ``levels=2``: each robot
feeds its local model directly (its own clock) and every ``report_period`` sends a
report (:mod:`semwm.team`) to the global model, and reports at once, between
periods, when its local model has an object it has not reported yet or, with
``drift_gate``, one whose view on the global side has drifted out of the local
estimate's gate (send-on-delta, :meth:`semwm.team.LocalModel.due`), from a start
drawn per robot in the first period (robots do not report in step
with each other or with the evaluation times: in step, every report would be sent
exactly at an evaluation time and never be in the world evaluated then). The world
evaluated at every truth time is the receiver's (flat or global) model. CPU time
per level is :func:`time.process_time` around each level's work.
"""

from __future__ import annotations

import heapq
import math
import time as clock
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import Any, Literal

import numpy as np

from semwm.clock import Exchange
from semwm.detection import Detection, OutOfOrderError
from semwm.knowledge.model import Knowledge
from semwm.sim.metrics import compute_metrics
from semwm.sim.runner import RunResult, scans, taxonomy_of, truth_points, world_points
from semwm.sim.scenarios import Scenario, TruthFrame
from semwm.sources import SourceRegistry, TimeGuard
from semwm.team import (
    CONTINUITY_PROBABILITY,
    Continuity,
    LocalModel,
    Strategy,
    global_knowledge,
)
from semwm.world import WorldModel
from semwm.world_types import WorldState


@dataclass(frozen=True)
class Network:
    """Clocks and links of the team.

    ``max_offset``: clocks are off by up to this (s); ``latency``: one-way delay range
    (s); ``sync``: estimate the offsets; ``hold``: the receiver's reorder window or
    sorting delay (s), by default the largest latency plus 50 ms (0 without
    latency); ``receiver``: ``"reorder"`` (process on arrival, replay within
    ``hold``) or ``"hold"`` (sorting buffer; see the module docstring);
    ``model_hold``: the ``"reorder"`` receiver's :attr:`WorldModel.hold` (s): scans
    that newer ones overtook by less than it are processed in order, not replayed.
    """

    max_offset: float = 0.0
    latency: tuple[float, float] = (0.0, 0.0)
    sync: bool = True
    sync_period: float = 0.2
    hold: float | None = None
    receiver: Literal["reorder", "hold"] = "reorder"
    model_hold: float = 0.0

    def __post_init__(self) -> None:
        if self.receiver not in ("reorder", "hold"):
            raise ValueError(f"receiver must be 'reorder' or 'hold'; got {self.receiver!r}")

    @property
    def hold_time(self) -> float:
        if self.hold is not None:
            return self.hold
        return self.latency[1] + 0.05 if self.latency[1] > 0 else 0.0


@dataclass
class TeamRun:
    """A finished team run: the evaluation (as :class:`RunResult`) and the team figures."""

    result: RunResult
    levels: int
    strategy: str | None
    cpu_local_s: float
    cpu_global_s: float
    messages: int
    bytes: int
    detections_sent: int
    late: int
    offsets: dict[str, float]
    offset_errors: dict[str, float]
    peer_label_rate: float | None
    nees: float | None
    extra: dict[str, Any] = field(default_factory=dict)

    def to_dict(self) -> dict[str, object]:
        n_det = max(self.result.n_detections, 1)
        errors = [abs(v) for v in self.offset_errors.values()]
        return {
            "levels": self.levels,
            "strategy": self.strategy,
            "cpu_s": {"local": self.cpu_local_s, "global": self.cpu_global_s},
            "cpu_per_detection_ms": {
                "local": 1e3 * self.cpu_local_s / n_det,
                "global": 1e3 * self.cpu_global_s / n_det,
            },
            "between_levels": {
                "messages": self.messages,
                "bytes": self.bytes,
                "detections": self.detections_sent,
            },
            "late_dropped": self.late,
            "clock_offsets": self.offsets,
            "offset_error_max_s": max(errors) if errors else None,
            "peer_label_rate": self.peer_label_rate,
            "mean_nees": self.nees,
            **self.extra,
        }


@dataclass(order=True)
class _Message:
    arrival: float
    seq: int
    source: str = field(compare=False)
    detections: list[Detection] = field(compare=False)
    local_ids: tuple[int, ...] | None = field(compare=False, default=None)


def run_team(
    scenario: Scenario,
    knowledge: Knowledge,
    *,
    levels: int = 1,
    network: Network | None = None,
    strategy: Strategy | str = Strategy.SCANS,
    report_period: float = 0.1,
    drift_gate: float | None = 0.95,
    seed: int = 0,
    gospa_c: float | None = None,
    horizon: float | None = None,
    continuity: float | None = CONTINUITY_PROBABILITY,
) -> TeamRun:
    """Play ``scenario`` through a flat (``levels=1``) or two-level team.

    ``drift_gate`` (two levels): between periods a robot also reports when the
    global side's view of one of its objects is outside this probability's gate of
    the local estimate (:meth:`semwm.team.LocalModel.due`); ``None``: only when it
    has a new object. ``horizon`` (s): how far ahead the gate compares the global
    view with the local estimate (:meth:`~semwm.team.LocalModel.due`); by default the
    report period. ``continuity`` (two levels, a probability): the receiver keeps a
    robot's report on the global object its local object went to before
    (:class:`semwm.team.Continuity` with this probability; by default
    :data:`~semwm.team.CONTINUITY_PROBABILITY`); ``None``: every report is associated
    afresh. The defaults, ``scans`` with continuity, are the two-level
    configuration closest to flat (docs/team.md)."""
    if levels not in (1, 2):
        raise ValueError(f"levels must be 1 or 2; got {levels}")
    net = network or Network()
    rng = np.random.default_rng(10_000 + seed)
    sources = sorted({d.source or "" for d in scenario.detections})
    offsets = {s: float(rng.uniform(-net.max_offset, net.max_offset)) for s in sources}
    low, high = net.latency

    def latency() -> float:
        return float(rng.uniform(low, high)) if high > 0 else 0.0

    strategy = Strategy(strategy)
    if horizon is None:
        horizon = report_period
    reorder = net.receiver == "reorder"
    receiver = WorldModel(
        global_knowledge(knowledge) if levels == 2 else knowledge,
        reorder_window=net.hold_time if reorder else 0.0,
        hold=net.model_hold if reorder else 0.0,
    )
    locals_ = {s: LocalModel(s, knowledge, strategy) for s in sources} if levels == 2 else {}
    keep = (
        Continuity(knowledge.world.dimension, continuity, knowledge.world.gate_probability)
        if levels == 2 and continuity is not None
        else None
    )
    phase_rng = np.random.default_rng(20_000 + seed)
    phase = {s: float(phase_rng.uniform(0.0, report_period)) for s in sources}
    next_report: dict[str, float] = {}
    cpu_local = 0.0
    messages: list[_Message] = []
    seq = 0
    sent_bytes = sent_detections = n_messages = 0

    # 1. what the sources send (in their clocks), with arrival times on the service clock
    for scan in scans(scenario.detections):
        t = scan[0].time
        source = scan[0].source or ""
        stamped = [d.model_copy(update={"time": t - offsets[source]}) for d in scan]
        if levels == 1:
            messages.append(_Message(t + latency(), seq, source, stamped))
            seq += 1
            continue
        start = clock.process_time()
        local = locals_[source]
        local.ingest(stamped)
        next_report.setdefault(source, t + phase[source])
        report = None
        if t >= next_report[source] - 1e-9:
            next_report[source] = t + report_period
            report = local.report()
        elif local.due(drift_gate=drift_gate, horizon=horizon):
            report = local.report()  # the whole report, between periods
        cpu_local += clock.process_time() - start
        if report is not None:
            n_messages += 1
            sent_bytes += report.size
            sent_detections += len(report.detections)
            detections = [Detection.model_validate(d) for d in report.detections]
            messages.append(_Message(t + latency(), seq, source, detections, report.local_ids))
            seq += 1
    if levels == 1:
        n_messages = len(messages)
        sent_detections = sum(len(m.detections) for m in messages)
        sent_bytes = sum(
            len(
                ('{"detections":[' + ",".join(d.model_dump_json(by_alias=True, exclude_none=True)
                                              for d in m.detections) + "]}").encode()
            )
            for m in messages
        )  # fmt: skip

    # 2. sync exchanges (service clock time of the reply, the exchange)
    syncs: list[tuple[float, str, Exchange]] = []
    if net.sync and net.max_offset > 0:
        for s in sources:
            starts = [-0.5 + 0.1 * i for i in range(5)]
            starts += list(np.arange(net.sync_period, scenario.duration + 1e-9, net.sync_period))
            for t in starts:
                out, back = latency(), latency()
                t2 = t + out
                t3 = t2 + 0.0005
                syncs.append((t3, s, Exchange(t - offsets[s], t2, t3, t3 + back - offsets[s])))
    syncs.sort(key=lambda e: (e[0], e[1]))

    # 3. the receiver: syncs and messages in arrival order; place, then process on
    #    arrival (reorder) or once held (hold); evaluate at truth times
    registry = SourceRegistry(TimeGuard(max_ahead=None, max_jump=None))
    messages.sort()
    buffer: list[tuple[float, str, int, list[Detection], tuple[int, ...] | None]] = []
    worlds: list[WorldState] = []
    cpu_global = 0.0
    late = 0
    last_processed = -math.inf
    m_i = s_i = 0
    hold = net.hold_time

    def process(scan: list[Detection], local_ids: tuple[int, ...] | None = None) -> int:
        """Ingest ``scan`` (a report with its ``local_ids``: kept on the global objects
        they went to before, :class:`~semwm.team.Continuity`); the detections dropped as
        late."""
        nonlocal last_processed
        at = scan[0].time
        if not reorder and at < last_processed - 1e-9:
            return len(scan)
        source = scan[0].source or ""
        if local_ids is not None and len(local_ids) != len(scan):
            local_ids = None  # placement left some out: which is which is not known
        try:
            if keep is not None and local_ids is not None:
                keep.ingest(receiver, source, scan, local_ids)
            else:
                receiver.ingest(scan)
        except OutOfOrderError:
            return len(scan)
        last_processed = max(last_processed, at)
        return 0

    for frame in scenario.truth:
        now = frame.time
        start = clock.process_time()
        while True:
            sync_at = syncs[s_i][0] if s_i < len(syncs) else math.inf
            arrival = messages[m_i].arrival if m_i < len(messages) else math.inf
            if min(sync_at, arrival) > now:
                break
            if sync_at <= arrival:
                registry.sync(syncs[s_i][1], syncs[s_i][2])
                s_i += 1
                continue
            m = messages[m_i]
            m_i += 1
            placement = registry.place(m.detections)
            placed = [d for d in placement.detections if isinstance(d, Detection)]
            if reorder:
                late += process(placed, m.local_ids)
            else:
                # the buffer sorts scans: a report of several (``scans``) is split
                for at, scan, ids in _by_time(placed, m.local_ids):
                    heapq.heappush(buffer, (at, m.source, m.seq, scan, ids))
        while buffer and buffer[0][0] <= now - hold + 1e-9:
            _, _, _, held, ids = heapq.heappop(buffer)
            late += process(held, ids)
        worlds.append(_world_at(receiver, now))
        cpu_global += clock.process_time() - start

    c = gospa_c if gospa_c is not None else float(str(scenario.metadata.get("gospa_c", 1.0)))
    metrics = compute_metrics(
        [truth_points(f) for f in scenario.truth],
        [world_points(w) for w in worlds],
        c=c,
        compatible=taxonomy_of(knowledge).compatible,
    )
    total = cpu_local + cpu_global
    metrics = replace(
        metrics,
        time_per_detection={
            "mean_s": total / max(len(scenario.detections), 1),
            "total_ingest_s": total,
        },
    )
    result = RunResult(scenario, knowledge, worlds, metrics, [total], [len(scenario.detections)])
    estimated = {s: registry.clock(s) for s in sources}
    errors = {
        s: (est.offset - offsets[s])
        for s, est in estimated.items()
        if est is not None and est.offset is not None
    }
    return TeamRun(
        result=result,
        levels=levels,
        strategy=strategy.value if levels == 2 else None,
        cpu_local_s=cpu_local,
        cpu_global_s=cpu_global,
        messages=n_messages,
        bytes=sent_bytes,
        detections_sent=sent_detections,
        late=late,
        offsets=offsets,
        offset_errors=errors,
        peer_label_rate=peer_label_rate(scenario.truth, worlds),
        nees=mean_nees(scenario.truth, worlds),
        extra={
            "replayed_scans": receiver.replayed_scans,
            "continuity_widened": keep.widened if keep is not None else None,
        },
    )


def _by_time(
    detections: list[Detection], local_ids: tuple[int, ...] | None
) -> list[tuple[float, list[Detection], tuple[int, ...] | None]]:
    """``detections`` (one message) as its scans in time order, each with its local ids
    (``None`` when the message has none or placement left some detections out)."""
    if local_ids is not None and len(local_ids) != len(detections):
        local_ids = None
    times = sorted({d.time for d in detections})
    result = []
    for at in times:
        part = [i for i, d in enumerate(detections) if d.time == at]
        ids = tuple(local_ids[i] for i in part) if local_ids is not None else None
        result.append((at, [detections[i] for i in part], ids))
    return result


def peer_label_rate(truth: Sequence[TruthFrame], worlds: Sequence[WorldState]) -> float | None:
    """Share of (frame, labeled truth object) pairs where an object within 1 m carries
    the true label."""
    hits = total = 0
    for frame, state in zip(truth, worlds, strict=True):
        for obj in frame.objects:
            if obj.label is None:
                continue
            total += 1
            hits += any(
                o.label == obj.label
                and float(np.linalg.norm(np.subtract(o.position, obj.position))) <= 1.0
                for o in state.objects
            )
    return hits / total if total else None


def mean_nees(truth: Sequence[TruthFrame], worlds: Sequence[WorldState]) -> float | None:
    """Mean normalised estimation error squared ``δᵀ P⁻¹ δ`` of each truth object and
    the nearest world object within 1 m (2 for a consistent 2-d estimate; far above 2
    when information is counted twice and the covariance is too small)."""
    values: list[float] = []
    for frame, state in zip(truth, worlds, strict=True):
        if not state.objects:
            continue
        positions = np.array([o.position for o in state.objects])
        for obj in frame.objects:
            distance = np.linalg.norm(positions - np.asarray(obj.position), axis=1)
            i = int(np.argmin(distance))
            if distance[i] > 1.0:
                continue
            delta = positions[i] - np.asarray(obj.position)
            P = np.asarray(state.objects[i].covariance)
            values.append(float(delta @ np.linalg.solve(P, delta)))
    return float(np.mean(values)) if values else None


def _world_at(model: WorldModel, now: float) -> WorldState:
    """The receiver's world for the frame at ``now``: predicted to ``now``, or, when its
    newest scan is later (an unsynced clock stamped it in the future), as it stands,
    scored at ``now`` (the past before the history is not known)."""
    if model.latest_time is None:
        return WorldState(time=now, objects=())
    processed = model.processed_time
    if processed is not None and processed > now:
        return WorldState(time=now, objects=model.world(time=processed).objects)
    return model.world(time=now)
