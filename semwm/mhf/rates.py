r"""Detection rates observed on the sources' own streams (the ``mht`` model).

A class's ``detection_frequency`` is the rate (Hz) at which *one* detector reports
an object of the class while it sees it. A team breaks that figure: five robots
that each report every object in view at 30 Hz detect a cup at 100 Hz or more,
where a knowledge file written for one camera says 2 Hz. With the knowledge's
rate an object that nobody reports again for a tenth of a second is "normal", so
a detection that falls just outside its gate starts a duplicate that lives for
seconds, and hypotheses grow (the team-load defect of issue 15). The rate at which
a source reports an object it sees is something the service can count instead.

Each detector of each source (a *stream*, ``(source, detector)``) keeps:

* the source's mean interval between scans :math:`\bar\Delta_s` (an exponential
  moving average over its scans);
* per class :math:`c`, the fraction :math:`\hat p_{s,d,c}` of the objects of the
  class it detected in one scan of the source that it detects again in the next
  (discounted counts with a Beta prior of two pseudo-counts whose mean is the
  knowledge's per-scan probability :math:`\min(1, f_c \bar\Delta_s)`): its per-scan
  detection probability for an object of the class in view.

Its observed rate is :math:`g_{s,d,c} = \hat p_{s,d,c} / \bar\Delta_s` (Hz), written
:math:`g_{s,d}` below for the object's class. Counted per class because one detector
sees classes at very different rates (a camera that reports a cup in 80% of its
frames reports a table in 20%): one figure for all would make a rarely detected
object look missed at the frequent classes' rate and drop it before its next
detection. A stream
*sees* an object while its last detection of it is at most
``WINDOW_DETECTIONS / g`` old (a few expected detection intervals: an object that
leaves its view stops counting soon after). An object that has had no detection but
the one that started it (in any hypothesis) is seen by the stream that started it
for as long as that source keeps scanning within its sensor's reach: reported once
and never again where the stream keeps looking, it is most likely the stream's
false alarm, and it goes at the stream's rate rather than lingering for seconds at
the class's. With the class rate :math:`f_c`:

.. math::
   f_{s,d}(o) = \max(f_c, g_{s,d}) \text{ if } (s, d) \text{ sees } o, \text{ else } f_c

   f(o) = f_c + \sum_{(s,d) \text{ sees } o} (g_{s,d} - f_c)^+

:math:`f_{s,d}(o)` is the rate of an existing object in the association weight of a
detection from ``(s, d)`` (:mod:`semwm.mhf.association`) and :math:`f(o)` the rate
in the missed-detection term (:mod:`semwm.mhf.existence`), so the two stay one
Poisson model. With one source that reports at the knowledge's rate this is the
knowledge's model (``g = f_c``); the knowledge's rate is a floor, never lowered.
World setting ``observed_detection_rates: false`` turns this off.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

from semwm.filters.motion import FloatArray

StreamKey = tuple[str, str]
"""``(source, detector)``; the source ``""`` for detections that name none."""

CountKey = tuple[str, str, str]
"""``(source, detector, class)``; the class ``""`` when the caller gave none."""

PRIOR_COUNTS = 2.0
"""Strength (pseudo-counts) of the prior of a stream's per-scan detection probability."""

WINDOW_DETECTIONS = 3.0
"""A stream sees an object for this many of its expected detection intervals after
its last detection of it."""

INTERVAL_WEIGHT = 0.1
"""Weight of the newest interval in a source's mean interval between scans."""

STALE_INTERVALS = 10.0
"""A source that has not scanned for this many of its mean intervals no longer counts
for coverage."""

DISCOUNT = 0.98
"""Per scan of its source, the weight kept by a stream's hit and miss counts."""


@dataclass(frozen=True, slots=True)
class SourceClock:
    """When a source last scanned, its mean interval between scans (s), where its
    sensor was at that scan (``None``: its detections did not say), and how fast the
    sensor moved between its last two scans (m/s; 0 for a sensor that stands still
    or has given one position so far)."""

    last_time: float
    interval: float | None = None
    position: tuple[float, ...] | None = None
    speed: float = 0.0

    def in_view_until(self, distances: FloatArray, reach: float) -> FloatArray:
        """Until when objects ``distances`` (m) from the sensor's last position are
        surely in its view (``-inf``: not in it).

        The last position holds for one mean interval, when the next scan is due.
        Past it, a silent source may have moved on at its speed in any direction, so
        only objects within ``reach - speed * (t - last_time - interval)`` are surely
        in view: a patrolling robot whose detector reports nothing in some frames
        does not deny what it has left behind. A sensor that stands still keeps its
        view.
        """
        due = self.last_time + (self.interval or 0.0)
        inside = distances <= reach
        if self.speed <= 0.0:
            return np.where(inside, np.inf, -np.inf)
        result: FloatArray = np.where(inside, due + (reach - distances) / self.speed, -np.inf)
        return result


@dataclass(frozen=True, slots=True)
class StreamCounts:
    """A stream's discounted counts: of the objects it detected in one scan of its
    source that still existed at the next (``expected``), how many it detected again
    (``hits``); and the lineages it detected in its source's last scan."""

    hits: float = 0.0
    expected: float = 0.0
    detected: frozenset[int] = frozenset()

    def detection_probability(self, prior: float = 0.5) -> float:
        """Posterior mean per-scan detection probability, prior mean ``prior``."""
        return (self.hits + PRIOR_COUNTS * prior) / (self.expected + PRIOR_COUNTS)


@dataclass(frozen=True)
class ObservedRates:
    """What the sources' streams say about detection rates; immutable, one per state.

    ``streams``: per ``(source, detector, class)``, its counts; ``seen``: lineage ->
    stream -> time of the stream's last detection of it (in the most probable
    hypothesis), or of the detection with which it started it (in any hypothesis).
    """

    sources: Mapping[str, SourceClock] = field(default_factory=dict)
    streams: Mapping[CountKey, StreamCounts] = field(default_factory=dict)
    seen: Mapping[int, Mapping[StreamKey, float]] = field(default_factory=dict)

    def rate(self, stream: StreamKey, cls: str = "", class_rate: float | None = None) -> float:
        """``g``: the stream's observed rate per object of class ``cls`` in view (Hz); 0
        until its source has scanned twice. ``class_rate``: the class's knowledge rate
        (Hz), the prior's mean (``min(1, f_c * interval)`` per scan); else 1/2 per scan."""
        clock = self.sources.get(stream[0])
        counts = self.streams.get((stream[0], stream[1], cls))
        if clock is None or counts is None or not clock.interval:
            return 0.0
        prior = 0.5 if class_rate is None else min(1.0, class_rate * clock.interval)
        return counts.detection_probability(prior) / clock.interval

    def covered(
        self, positions: FloatArray, reach: float | None, start: float, end: float | None = None
    ) -> FloatArray:
        """``(N,)``: the part of ``[start, end]`` (default: the instant ``start``) in
        which an object at ``positions`` ``(N, d)`` is surely in some source's view
        (the class rate applies only then).

        Coverage is known only when every detector has a ``range`` (``reach``: the
        largest) and every source gave its sensor position (one without a position
        that scanned within :data:`STALE_INTERVALS` of its intervals makes every
        object count as seen: all ones, as before any source has scanned twice). A
        source that gave positions never goes stale: standing still, it keeps its view
        (silence there means it saw nothing); moving, its view shrinks to nothing.
        Then an object is in a source's view while it is within ``reach`` of the
        source's last position, shrinking once the source is overdue at the speed it
        moved (:meth:`SourceClock.in_view_until`); in nobody's view, it gets 0.
        """
        count = positions.shape[0]
        everywhere = np.ones(count)
        if reach is None or count == 0:
            return everywhere
        clocks = []
        for clock in self.sources.values():
            if clock.interval is None:
                continue
            if clock.position is None:
                if start - clock.last_time <= STALE_INTERVALS * clock.interval:
                    return everywhere
                continue
            clocks.append(clock)
        if not clocks:  # no source has scanned twice yet
            return everywhere
        until = np.full(count, -np.inf)
        for clock in clocks:
            at = np.asarray(clock.position, dtype=float)[: positions.shape[1]]
            offset = positions[:, : at.shape[0]] - at
            distances = np.sqrt(np.einsum("nd,nd->n", offset, offset))
            until = np.maximum(until, clock.in_view_until(distances, reach))
        if end is None or end <= start:
            result: FloatArray = (until >= start).astype(float)
            return result
        fraction: FloatArray = np.clip((until - start) / (end - start), 0.0, 1.0)
        return fraction

    def from_stream(
        self,
        stream: StreamKey,
        lineages: Sequence[int],
        class_rates: FloatArray,
        time: float,
        classes: Sequence[str] | None = None,
        unconfirmed: Sequence[bool] | None = None,
    ) -> FloatArray:
        """:math:`f_{s,d}(o)` of each object (Hz) for a detection of ``stream`` at
        ``time``; ``classes``: each object's class (else one count for all);
        ``unconfirmed``: objects with no detection but the one that started them (the
        stream that started one sees it while it scans, see :meth:`over`)."""
        clock = self.sources.get(stream[0])
        if clock is None or not clock.interval:
            return class_rates  # every g is 0 until the source has scanned twice
        base = np.asarray(class_rates, dtype=float).tolist()
        by_class: dict[str, float] = {}  # the first object of a class sets its prior
        values = []
        for i in range(len(lineages)):
            cls = "" if classes is None else classes[i]
            rate = by_class.get(cls)
            if rate is None:
                rate = by_class[cls] = self.rate(stream, cls, base[i] if cls else None)
            values.append(rate)
        g = np.array(values)
        if not np.any(g > 0.0):
            return class_rates
        window = WINDOW_DETECTIONS / np.where(g > 0.0, g, 1.0)
        seen = self.seen
        never: dict[StreamKey, float] = {}
        last = np.fromiter(
            (seen.get(lineage, never).get(stream, -np.inf) for lineage in lineages),
            dtype=float,
            count=len(lineages),
        )
        recent = time - last <= window
        if unconfirmed is not None:
            recent |= np.asarray(unconfirmed, dtype=bool) & (last > -np.inf)
        sees = (g > 0.0) & recent
        result: FloatArray = np.where(sees, np.maximum(class_rates, g), class_rates)
        return result

    def over(
        self,
        lineages: Sequence[int],
        class_rates: FloatArray,
        start: float,
        end: float,
        classes: Sequence[str] | None = None,
        unconfirmed: Sequence[bool] | None = None,
        positions: FloatArray | None = None,
        reach: float | None = None,
    ) -> FloatArray:
        """:math:`f(o)` of each object averaged over ``[start, end]`` (Hz): a stream
        counts for the part of the interval in which it still sees the object.
        ``classes``: each object's class (else one count for all).

        ``unconfirmed``: objects that have had no detection but the one that started
        them. The stream that started one sees it for as long as its source keeps
        scanning and the object is within ``reach`` (m) of the source's sensor
        (``positions``: the objects' ``(N, d)``; unknown reach or sensor position:
        anywhere), not only for the window: an object that it reported once and never
        again where it keeps looking is most likely its false alarm (a team's 4-sigma
        outlier), and would otherwise fade at the class's rate for seconds."""
        result = np.array(class_rates, dtype=float, copy=True)
        span = end - start
        if not self.seen or span <= 0.0:
            return result
        base = result.tolist()
        rates: dict[tuple[str, str, str], float] = {}
        done: dict[tuple[int, str, float], float] = {}
        seen = self.seen
        for i, lineage in enumerate(lineages):
            entries = seen.get(lineage)
            if not entries:
                continue
            cls = "" if classes is None else classes[i]
            rate = base[i]
            single = unconfirmed is not None and bool(unconfirmed[i])
            # versions of one object share it; not an unconfirmed one, whose reach is
            # judged from its own position
            extra = None if single else done.get((lineage, cls, rate))
            if extra is None:
                extra = 0.0
                for stream, last in entries.items():
                    key = (stream[0], stream[1], cls)
                    g = rates.get(key)
                    if g is None:
                        g = rates[key] = self.rate(stream, cls, rate if cls else None)
                    if g <= rate:
                        continue
                    until = last + WINDOW_DETECTIONS / g
                    if single and self._in_reach(stream[0], positions, i, reach):
                        until = max(until, self.scanning_until(stream[0]))
                    if until > start:
                        extra += (g - rate) * min((until - start) / span, 1.0)
                if not single:
                    done[(lineage, cls, rate)] = extra
            if extra:
                result[i] += extra
        return result

    def _in_reach(
        self, source: str, positions: FloatArray | None, row: int, reach: float | None
    ) -> bool:
        """Whether object ``row`` (of ``positions``) is within ``reach`` of ``source``'s
        sensor as it last scanned (true when either is unknown)."""
        clock = self.sources.get(source)
        if reach is None or positions is None or clock is None or clock.position is None:
            return True
        at = np.asarray(clock.position[: positions.shape[1]], dtype=float)
        offset = positions[row, : at.shape[0]] - at
        return float(offset @ offset) <= reach * reach

    def scanning_until(self, source: str) -> float:
        """Until when ``source`` counts as scanning: :data:`STALE_INTERVALS` of its mean
        intervals after its last scan (``-inf`` before its second scan)."""
        clock = self.sources.get(source)
        if clock is None or not clock.interval:
            return -np.inf
        return clock.last_time + STALE_INTERVALS * clock.interval

    def after_scan(
        self,
        source: str,
        time: float,
        detected: Mapping[str, Iterable[int]],
        born: Mapping[str, Iterable[int]],
        alive: frozenset[int] | set[int],
        position: tuple[float, ...] | None = None,
        classes: Mapping[int, str] | None = None,
        born_elsewhere: Mapping[str, Iterable[int]] | None = None,
    ) -> ObservedRates:
        """The rates after one scan of ``source`` at ``time``.

        ``detected``: per detector, the lineages (that existed before the scan) whose
        version in the most probable hypothesis took one of its detections; ``born``:
        per detector, the new lineages it started; ``alive``: every lineage the state
        holds after the scan; ``position``: where the source's sensor was;
        ``classes``: the class of each lineage detected or started (counts are kept
        per class; without it, one count for all); ``born_elsewhere``: per detector,
        new lineages it started in other hypotheses than the most probable one (the
        stream sees them, but they are not counted: the counts follow the most
        probable account of what it detects). A lineage that only such a hypothesis
        holds (an outlier that the best one calls clutter) would otherwise be seen by
        no stream and fade at the class's rate for seconds.
        """
        sources = dict(self.sources)
        clock = sources.get(source)
        if clock is None:
            sources[source] = SourceClock(time, None, position)
        elif time > clock.last_time:
            step = time - clock.last_time
            interval = (
                step
                if clock.interval is None
                else (1.0 - INTERVAL_WEIGHT) * clock.interval + INTERVAL_WEIGHT * step
            )
            speed = clock.speed
            if position is not None and clock.position is not None:
                moved = np.subtract(position, clock.position)
                speed = float(np.sqrt(moved @ moved)) / step
            sources[source] = SourceClock(time, interval, position, speed)
        else:
            sources[source] = SourceClock(clock.last_time, clock.interval, position, clock.speed)
        streams = dict(self.streams)

        def class_of(lineage: int) -> str:
            return "" if classes is None else classes.get(lineage, "")

        keys = {k for k in streams if k[0] == source}
        for detector in set(detected) | set(born):
            for lineage in (*detected.get(detector, ()), *born.get(detector, ())):
                keys.add((source, detector, class_of(lineage)))
        for key in keys:
            detector, cls = key[1], key[2]
            old = streams.get(key, StreamCounts())
            # a hit is any detection of the object by the stream, whatever class it now has
            every = frozenset(detected.get(detector, ()))
            now = frozenset(lineage for lineage in every if class_of(lineage) == cls)
            started = frozenset(
                lineage for lineage in born.get(detector, ()) if class_of(lineage) == cls
            )
            expected = old.detected & alive
            streams[key] = StreamCounts(
                DISCOUNT * old.hits + len(expected & every),
                DISCOUNT * old.expected + len(expected),
                now | started,
            )
        seen = {lineage: streams_ for lineage, streams_ in self.seen.items() if lineage in alive}
        elsewhere = born_elsewhere or {}
        for detector in set(detected) | set(born) | set(elsewhere):
            stream: StreamKey = (source, detector)
            for lineage in (
                *detected.get(detector, ()),
                *born.get(detector, ()),
                *elsewhere.get(detector, ()),
            ):
                if lineage in alive:
                    seen[lineage] = {**seen.get(lineage, {}), stream: time}
        return ObservedRates(sources, streams, seen)
