"""Sources (robots, sensors): their clocks, their time guards and what they sent.

A :class:`SourceRegistry` keeps, per source, the offset of its clock
(:mod:`semwm.clock`), how many detections it sent, the latest time it reached, and
how many of its detections were refused as late (older than the world's reorder
window) or by a time guard.

Placing a batch (:meth:`SourceRegistry.place`) puts every detection of a synced
source at ``stamp + offset`` on the service clock (unsynced sources keep their
stamps) and applies two guards (issue 15: one absurd stamp must not become the
world's new time):

* ``max_ahead``: a placed time may be at most this far ahead of the service clock
  (``now``, read by the caller; skipped when ``now`` is ``None``, as in simulations);
* ``max_jump``: a source's time may advance at most this much more than the service
  clock did since its previous accepted detection.

A refused detection changes nothing but the counts and the source's last problem,
which ``GET /sources`` shows; a completed sync exchange resets the source's jump
reference (its clock may legitimately move to another epoch then).

Concurrent scans (``tolerance``): the world processes scans in time order, and a
scan older than the newest one it processed makes it go back and process the later
ones again (the reorder window's replay). Scans of different sources that are
closer in time than their clocks agree have no meaningful order, yet a team's
robots reporting the same instant arrive in any order, and each inversion costs a
replay (about 1.7x the CPU of the same stream in order on a team's load, issue 15).
So a scan of a source whose own earlier scans are all older, at most ``tolerance``
seconds older than the newest scan the world processed (``newest``), is placed just
after it (the next representable time): processed in arrival order, its time moved
by at most ``tolerance``. A scan a source sends out of its own order is not moved
(it is replayed, or merged with the scan of the same time and source), nor is one
more than ``tolerance`` late.

Pure: ``now`` is an argument; nothing here reads a clock.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from operator import methodcaller
from typing import Any

from semwm.clock import ClockEstimate, Exchange, ExchangeError
from semwm.detection import MAX_TIME_STD, Detection

DetectionLike = Detection | Mapping[str, Any]

LATE_POLICIES = ("replay", "drop")
"""What a source asks for its scans older than the newest processed one (issue 30)."""

DEFAULT_ORDER_TOLERANCE = 0.005
"""Seconds (the service's default): below a team's clock agreement (paper 003 syncs
clocks over a wireless network, with latencies of tens of milliseconds), so scans
this close have no meaningful order; a robot at 4 m/s moves 2 cm in it."""


@dataclass(frozen=True)
class TimeGuard:
    """Bounds on detection times (s); ``None`` turns a bound off.

    Attributes
    ----------
    max_ahead
        How far a placed detection time may be ahead of the service clock.
    max_jump
        How much further a source's time may advance than the service clock did
        since that source's previous accepted detection.
    """

    max_ahead: float | None = 10.0
    max_jump: float | None = 60.0

    def __post_init__(self) -> None:
        for name in ("max_ahead", "max_jump"):
            value = getattr(self, name)
            if value is not None and not (math.isfinite(value) and value >= 0.0):
                raise ValueError(f"{name} must be a finite number >= 0 or None; got {value}")


@dataclass(frozen=True)
class TimeProblem:
    """A detection refused by a time guard: its index in the batch and why."""

    index: int
    source: str | None
    kind: str  # "ahead" or "jump"
    message: str


class TimeGuardError(ValueError):
    """Detections refused by a time guard; nothing of the batch was applied."""

    def __init__(self, problems: Sequence[TimeProblem]) -> None:
        self.problems = tuple(problems)
        super().__init__("; ".join(f"{p.index}.time: {p.message}" for p in self.problems))


@dataclass(frozen=True)
class SourceStatus:
    """What ``GET /sources`` reports of one source (``name`` ``None``: no source given)."""

    name: str | None
    synced: bool
    clock_offset: float | None
    offset_std: float | None
    delay: float | None
    exchanges: int
    detections: int
    last_time: float | None
    late: int
    refused: int
    problem: str | None
    in_arrival_order: int = 0
    late_policy: str = "replay"
    dropped: int = 0

    def to_dict(self) -> dict[str, object]:
        return {
            "name": self.name,
            "synced": self.synced,
            "clock_offset": self.clock_offset,
            "offset_std": self.offset_std,
            "delay": self.delay,
            "exchanges": self.exchanges,
            "detections": self.detections,
            "last_time": self.last_time,
            "late": self.late,
            "refused": self.refused,
            "problem": self.problem,
            "in_arrival_order": self.in_arrival_order,
            "late_policy": self.late_policy,
            "dropped": self.dropped,
        }


@dataclass
class _Record:
    clock: ClockEstimate
    detections: int = 0
    last_time: float | None = None  # latest accepted placed time (service clock)
    last_at: float | None = None  # service clock when it was accepted
    late: int = 0
    refused: int = 0
    problem: str | None = None
    in_arrival_order: int = 0  # scans placed in arrival order (concurrent with another's)
    late_policy: str = "replay"  # or "drop": its scans older than the newest processed
    dropped: int = 0  # detections dropped as late (late_policy "drop")


@dataclass(frozen=True)
class Placement:
    """A batch placed on the service clock, not yet applied.

    ``detections`` are the batch with placed times, in its order; ``latest`` maps
    each source to its latest placed time in the batch and ``counts`` to how many
    detections it has there; ``moved`` maps each concurrent scan placed in arrival
    order, ``(source, time)``, to the time it was moved to; ``earliest`` is the
    earliest placed time (``inf`` for none).
    """

    detections: tuple[DetectionLike, ...]
    latest: dict[str | None, float] = field(default_factory=dict)
    counts: dict[str | None, int] = field(default_factory=dict)
    moved: dict[tuple[str | None, float], float] = field(default_factory=dict)
    earliest: float = math.inf


def _field(d: DetectionLike, name: str) -> Any:
    if isinstance(d, Detection):
        return getattr(d, name)
    return d.get(name)


def _place_words(source: str | None, stamp: float, time: float) -> tuple[str, str]:
    """Where and whose a refused time is, for the message (built only for a refusal)."""
    who = f"source {source!r}" if source is not None else "a detection without source"
    where = f"time {stamp:g} s" + (f" (placed at {time:.6g} s)" if time != stamp else "")
    return where, who


def _with_time(d: DetectionLike, time: float, offset_std: float | None) -> DetectionLike:
    """``d`` at ``time`` on the service clock; its ``time_std`` combines its own with the
    clock offset's uncertainty ``offset_std``."""
    update: dict[str, Any] = {"time": time}
    if offset_std:
        own = _field(d, "time_std")
        own = float(own) if isinstance(own, int | float) else 0.0
        update["time_std"] = min(math.hypot(own, offset_std), MAX_TIME_STD)
    if isinstance(d, Detection):
        return d.model_copy(update=update)
    return {**d, **update}


def _moved(d: DetectionLike, moved: Mapping[tuple[str | None, float], float]) -> DetectionLike:
    """``d`` at the time its scan was moved to, if it was."""
    time = _field(d, "time")
    if not isinstance(time, int | float) or isinstance(time, bool):
        return d
    to = moved.get((_field(d, "source") or None, float(time)))
    if to is None:
        return d
    if isinstance(d, Detection):
        return d.model_copy(update={"time": to})
    return {**d, "time": to}


Span = dict[str | None, list[float]]
"""Per source, a batch's earliest and latest time and its count (:func:`plain_span`)."""


_time_of = methodcaller("get", "time")
_source_of = methodcaller("get", "source")


def plain_span(detections: Sequence[DetectionLike]) -> Span | None:
    """Per source, the earliest and latest time and the count of a batch of plain dicts
    with finite numeric times (what placing and ordering it need); ``None`` for any
    other batch (the general path then says what is wrong).

    The common batch (float times, one source) is read with no Python code per
    detection; any other takes :func:`_span_each`, one detection at a time."""
    if not detections:
        return {}
    if set(map(type, detections)) != {dict}:
        return None
    times = list(map(_time_of, detections))
    if set(map(type, times)) != {float}:
        return _span_each(detections)  # ints, or not numbers: one by one
    total = sum(times)
    if total - total != 0:
        return _span_each(detections)  # an infinity or a NaN (or a sum beyond floats)
    sources = list(map(_source_of, detections))
    source = sources[0]
    if sources.count(source) != len(sources):
        return _span_each(detections)
    return {source: [min(times), max(times), len(times)]}


def _span_each(detections: Sequence[DetectionLike]) -> Span | None:
    """:func:`plain_span`, one detection at a time."""
    span: Span = {}  # source -> [earliest, latest, count]
    for d in detections:
        if type(d) is not dict:
            return None
        time: Any = d.get("time")
        kind = type(time)
        if kind is not float and kind is not int:
            return None  # bool, str, missing
        if time - time != 0:
            return None  # not finite
        source = d.get("source")
        known = span.get(source)
        if known is None:
            span[source] = [time, time, 1]
        else:
            if time < known[0]:
                known[0] = time
            elif time > known[1]:
                known[1] = time
            known[2] += 1
    return span


_Placed = tuple[list[DetectionLike], dict[str | None, float], dict[str | None, int], float]
"""A batch placed: detections, latest time and count per source, earliest time."""


class SourceRegistry:
    """Clocks, time guards and counts of every source.

    Parameters
    ----------
    guard
        The time guards (:class:`TimeGuard`).
    window, best
        The clock filter of :class:`semwm.clock.ClockEstimate`.
    """

    def __init__(self, guard: TimeGuard | None = None, *, window: int = 32, best: int = 16) -> None:
        self.guard = guard or TimeGuard()
        ClockEstimate(window, best)  # fail early on bad settings
        self._window, self._best = window, best
        self._records: dict[str | None, _Record] = {}

    def _new_clock(self) -> ClockEstimate:
        return ClockEstimate(self._window, self._best)

    def _record(self, name: str | None) -> _Record:
        record = self._records.get(name)
        if record is None:
            record = self._records[name] = _Record(self._new_clock())
        return record

    # -- clocks ---------------------------------------------------------------------------------

    def sync(self, name: str, exchange: Exchange) -> SourceStatus:
        """Add a finished exchange of source ``name``; its jump reference restarts.

        Raises :class:`~semwm.clock.ExchangeError` (nothing stored) when the estimate
        with it would not be finite numbers."""
        record = self._records.get(name)
        clock = (record.clock if record is not None else self._new_clock()).add(exchange)
        if not clock.finite:
            raise ExchangeError(
                "returned",
                "the exchange makes the clock offset or its uncertainty overflow; not stored",
            )
        record = self._record(name)
        record.clock = clock
        record.last_time = record.last_at = None
        record.problem = None
        return self._status(name, record)

    def clock(self, name: str | None) -> ClockEstimate | None:
        record = self._records.get(name)
        return record.clock if record is not None else None

    # -- detections -----------------------------------------------------------------------------

    def to_service_time(self, source: str | None, stamp: float) -> float:
        """``stamp`` of ``source``'s clock on the service clock (itself if not synced)."""
        record = self._records.get(source)
        if record is not None and record.clock.synced:
            return record.clock.to_service(float(stamp))
        return stamp

    def place(
        self,
        detections: Sequence[DetectionLike],
        now: float | None = None,
        newest: float | None = None,
        tolerance: float = 0.0,
        newest_source: str | None = None,
        span: Span | None = None,
    ) -> Placement:
        """Put ``detections`` on the service clock and check the time guards; with
        ``tolerance`` > 0, place concurrent scans after ``newest`` (the world's newest
        processed scan time) in arrival order (see the module docstring).
        ``newest_source``: the source of that scan (``""`` for none), when known: a
        scan of the same time whose source sorts after it comes after it in the world's
        own order (time, then source), so it keeps its time. ``span``: the batch's
        :func:`plain_span`, if the caller has it (it is not found again).

        Raises
        ------
        TimeGuardError
            A placed time breaks a guard; the refusal is counted for its source and
            nothing else changes.
        """
        plain = self._place_plain(detections, now, span)
        placed, latest, counts, earliest = plain or self._place_each(detections, now)
        moved: dict[tuple[str | None, float], float] = {}
        if tolerance > 0.0 and newest is not None and earliest <= newest:
            moved = self._concurrent(placed, newest, tolerance, newest_source)
        if moved:
            placed = [_moved(d, moved) for d in placed]
            earliest = math.inf
            for d in placed:
                source = _field(d, "source")
                time = _field(d, "time")
                if isinstance(time, float) and source in latest:
                    latest[source] = max(latest[source], time)
                if isinstance(time, int | float) and not isinstance(time, bool):
                    earliest = min(earliest, float(time))
        return Placement(tuple(placed), latest, counts, moved, earliest)

    def _place_plain(
        self,
        detections: Sequence[DetectionLike],
        now: float | None,
        span: Span | None = None,
    ) -> _Placed | None:
        """:meth:`_place_each`'s result for the common batch, computed per source: plain
        dicts with finite numeric times from sources that are not synced (their times
        stay as stamped) and that pass the guards. The guards grow with the time, so
        each source's latest time decides them. ``None`` for any other batch.
        ``span``: the batch's :func:`plain_span`, if the caller has it."""
        if span is None:
            span = plain_span(detections)
            if span is None:
                return None
        for index, (source, (_, last, _)) in enumerate(span.items()):
            record = self._records.get(source)
            if record is not None and record.clock.synced:
                return None
            if self._check(index, source, last, last, record, now) is not None:
                return None  # the general path finds every refused detection
        latest = {source: float(last) for source, (_, last, _) in span.items()}
        counts = {source: int(count) for source, (_, _, count) in span.items()}
        earliest = min((float(first) for first, _, _ in span.values()), default=math.inf)
        return list(detections), latest, counts, earliest

    def _place_each(self, detections: Sequence[DetectionLike], now: float | None) -> _Placed:
        """Every detection placed and checked one by one (raises :class:`TimeGuardError`)."""
        placed: list[DetectionLike] = []
        problems: list[TimeProblem] = []
        latest: dict[str | None, float] = {}
        counts: dict[str | None, int] = {}
        earliest = math.inf
        for index, d in enumerate(detections):
            source = _field(d, "source")
            stamp = _field(d, "time")
            record = self._records.get(source)
            time = stamp
            if record is not None and record.clock.synced and isinstance(stamp, int | float):
                time = record.clock.to_service(float(stamp))
            if isinstance(time, int | float) and not isinstance(time, bool):
                problem = self._check(index, source, float(stamp), float(time), record, now)
                if problem is not None:
                    problems.append(problem)
                latest[source] = max(latest.get(source, -math.inf), float(time))
                earliest = min(earliest, float(time))
            counts[source] = counts.get(source, 0) + 1
            placed.append(
                _with_time(d, time, record.clock.offset_std if record is not None else None)
                if time is not stamp
                else d
            )
        if problems:
            for p in problems:
                record = self._record(p.source)
                record.refused += 1
                record.problem = p.message
            raise TimeGuardError(problems)
        return placed, latest, counts, earliest

    def _concurrent(
        self,
        placed: Sequence[DetectionLike],
        newest: float,
        tolerance: float,
        newest_source: str | None = None,
    ) -> dict[tuple[str | None, float], float]:
        """The batch's scans ``(source, time)`` to place after ``newest``, in time order,
        each at the next representable time after the previous one. A scan at ``newest``
        whose source sorts after ``newest_source`` is in the world's order already (a
        team's synchronised sensors): it keeps its time, and the world processes it at
        that instant without another prediction step."""
        scans: set[tuple[float, str | None]] = set()
        for d in placed:
            time = _field(d, "time")
            number = isinstance(time, int | float) and not isinstance(time, bool)
            if number and newest - tolerance <= time <= newest:
                source = _field(d, "source") or None
                if time == newest and newest_source is not None and (source or "") > newest_source:
                    continue
                scans.add((float(time), source))
        moved: dict[tuple[str | None, float], float] = {}
        cursor = newest
        for time, source in sorted(scans, key=lambda scan: (scan[0], scan[1] or "")):
            record = self._records.get(source)
            if record is not None and record.last_time is not None and record.last_time >= time:
                continue  # out of the source's own order: replayed (or the same scan)
            cursor = math.nextafter(cursor, math.inf)
            moved[(source, time)] = cursor
        return moved

    def _check(
        self,
        index: int,
        source: str | None,
        stamp: float,
        time: float,
        record: _Record | None,
        now: float | None,
    ) -> TimeProblem | None:
        ahead = self.guard.max_ahead
        if now is not None and ahead is not None and time - now > ahead:
            where, who = _place_words(source, stamp, time)
            return TimeProblem(
                index,
                source,
                "ahead",
                f"{where} of {who} is {time - now:.6g} s ahead of the service clock "
                f"({now:.6g} s); the bound is max_ahead = {ahead:g} s: sync the source's clock "
                f"(POST /sources/NAME/sync) or fix its stamps",
            )
        jump = self.guard.max_jump
        if jump is not None and record is not None and record.last_time is not None:
            elapsed = (
                (now - record.last_at) if now is not None and record.last_at is not None else 0
            )
            advance = time - record.last_time
            if advance - max(elapsed, 0.0) > jump:
                where, who = _place_words(source, stamp, time)
                return TimeProblem(
                    index,
                    source,
                    "jump",
                    f"{where} of {who} jumps {advance:.6g} s past its previous time "
                    f"{record.last_time:.6g} s while the service clock moved {elapsed:.3g} s; "
                    f"the bound is max_jump = {jump:g} s: a sync exchange restarts the source's "
                    f"time reference",
                )
        return None

    def accepted(self, placement: Placement, now: float | None = None) -> None:
        """Count a placed batch that the world model applied."""
        for source, _ in placement.moved:
            self._record(source).in_arrival_order += 1
        for source, count in placement.counts.items():
            record = self._record(source)
            record.detections += count
            latest = placement.latest.get(source)
            if latest is not None and (record.last_time is None or latest > record.last_time):
                record.last_time = latest
                record.last_at = now
            record.problem = None

    def late(self, placement: Placement, message: str) -> None:
        """Count a placed batch refused as older than the world's reorder window."""
        for source, count in placement.counts.items():
            record = self._record(source)
            record.late += count
            record.problem = message

    def set_late_policy(self, name: str, late: str) -> SourceStatus:
        """What happens to ``name``'s late scans: ``replay`` or ``drop`` (see
        :meth:`dropped`)."""
        if late not in LATE_POLICIES:
            raise ValueError(f"late must be one of {', '.join(LATE_POLICIES)}; got {late!r}")
        record = self._record(name)
        record.late_policy = late
        return self._status(name, record)

    def drops_late(self, name: str | None) -> bool:
        record = self._records.get(name)
        return record is not None and record.late_policy == "drop"

    def dropped(self, placement: Placement) -> None:
        """Count a placed batch dropped as late (its sources asked for it)."""
        for source, count in placement.counts.items():
            self._record(source).dropped += count

    def forget_times(self) -> None:
        """Drop every source's time reference (the world was reset); clocks stay."""
        for record in self._records.values():
            record.last_time = record.last_at = None
            record.problem = None

    # -- report ---------------------------------------------------------------------------------

    def _status(self, name: str | None, record: _Record) -> SourceStatus:
        clock = record.clock
        finite = clock.finite  # a status is always reportable: a broken clock reads null
        return SourceStatus(
            name=name,
            synced=clock.synced,
            clock_offset=clock.offset if finite else None,
            offset_std=clock.offset_std if finite else None,
            delay=clock.delay if finite else None,
            exchanges=clock.count,
            detections=record.detections,
            last_time=record.last_time,
            late=record.late,
            refused=record.refused,
            problem=record.problem,
            in_arrival_order=record.in_arrival_order,
            late_policy=record.late_policy,
            dropped=record.dropped,
        )

    def status(self, name: str | None = None) -> SourceStatus | None:
        record = self._records.get(name)
        return self._status(name, record) if record is not None else None

    def statuses(self) -> list[SourceStatus]:
        """Every source seen, by name (the nameless one first)."""
        names = sorted(self._records, key=lambda n: (n is not None, n or ""))
        return [self._status(n, self._records[n]) for n in names]
