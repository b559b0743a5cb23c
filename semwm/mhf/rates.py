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
* the fraction :math:`\hat p_{s,d}` of the objects it detected in one scan of the
  source that it detects again in the next (discounted counts with a Beta(1, 1)
  prior): its per-scan detection probability for an object in view.

Its observed rate is :math:`g_{s,d} = \hat p_{s,d} / \bar\Delta_s` (Hz). A stream
*sees* an object while its last detection of it is at most
``WINDOW_DETECTIONS / g`` old (a few expected detection intervals: an object that
leaves its view stops counting soon after). With the class rate :math:`f_c`:

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
    """When a source last scanned, its mean interval between scans (s), and where its
    sensor was at that scan (``None``: its detections did not say)."""

    last_time: float
    interval: float | None = None
    position: tuple[float, ...] | None = None


@dataclass(frozen=True, slots=True)
class StreamCounts:
    """A stream's discounted counts: of the objects it detected in one scan of its
    source that still existed at the next (``expected``), how many it detected again
    (``hits``); and the lineages it detected in its source's last scan."""

    hits: float = 0.0
    expected: float = 0.0
    detected: frozenset[int] = frozenset()

    @property
    def detection_probability(self) -> float:
        return (self.hits + 1.0) / (self.expected + 2.0)


@dataclass(frozen=True)
class ObservedRates:
    """What the sources' streams say about detection rates; immutable, one per state.

    ``seen``: lineage -> stream -> time of the stream's last detection of it.
    """

    sources: Mapping[str, SourceClock] = field(default_factory=dict)
    streams: Mapping[StreamKey, StreamCounts] = field(default_factory=dict)
    seen: Mapping[int, Mapping[StreamKey, float]] = field(default_factory=dict)

    def rate(self, stream: StreamKey) -> float:
        """``g``: the stream's observed rate per object in view (Hz); 0 until its
        source has scanned twice."""
        clock = self.sources.get(stream[0])
        counts = self.streams.get(stream)
        if clock is None or counts is None or not clock.interval:
            return 0.0
        return counts.detection_probability / clock.interval

    def covered(self, positions: FloatArray, reach: float | None, time: float) -> FloatArray:
        """``(N,)``: 1 where an object at ``positions`` ``(N, d)`` may be seen by some
        source at ``time``, else 0 (the class rate applies only there).

        Coverage is known only when every detector has a ``range`` (``reach``: the
        largest) and every source that scanned within :data:`STALE_INTERVALS` of its
        intervals gave its sensor position: then an object farther than ``reach`` from
        every such source's last position is out of view. Otherwise every object may
        be seen (all ones).
        """
        count = positions.shape[0]
        everywhere = np.ones(count)
        if reach is None or count == 0:
            return everywhere
        sensors = []
        for clock in self.sources.values():
            stale = STALE_INTERVALS * (clock.interval or 0.0)
            if clock.interval is None or time - clock.last_time > stale:
                continue
            if clock.position is None:
                return everywhere
            sensors.append(clock.position)
        if not sensors:
            return everywhere
        at = np.asarray(sensors, dtype=float)[:, : positions.shape[1]]
        offset = positions[:, None, :] - at[None, :, :]
        near = np.einsum("nsd,nsd->ns", offset, offset) <= reach * reach
        result: FloatArray = near.any(axis=1).astype(float)
        return result

    def from_stream(
        self, stream: StreamKey, lineages: Sequence[int], class_rates: FloatArray, time: float
    ) -> FloatArray:
        """:math:`f_{s,d}(o)` of each object (Hz) for a detection of ``stream`` at
        ``time``."""
        g = self.rate(stream)
        if g <= 0.0:
            return class_rates
        window = WINDOW_DETECTIONS / g
        sees = np.fromiter(
            (
                time - self.seen.get(lineage, {}).get(stream, -np.inf) <= window
                for lineage in lineages
            ),
            dtype=bool,
            count=len(lineages),
        )
        result: FloatArray = np.where(sees, np.maximum(class_rates, g), class_rates)
        return result

    def over(
        self, lineages: Sequence[int], class_rates: FloatArray, start: float, end: float
    ) -> FloatArray:
        """:math:`f(o)` of each object averaged over ``[start, end]`` (Hz): a stream
        counts for the part of the interval in which it still sees the object."""
        result = np.array(class_rates, dtype=float, copy=True)
        span = end - start
        if not self.seen or span <= 0.0:
            return result
        base = result.tolist()
        rates: dict[StreamKey, float] = {}
        done: dict[tuple[int, float], float] = {}  # versions of one object share it
        for i, lineage in enumerate(lineages):
            entries = self.seen.get(lineage)
            if not entries:
                continue
            extra = done.get((lineage, base[i]))
            if extra is None:
                extra = 0.0
                for stream, last in entries.items():
                    g = rates.get(stream)
                    if g is None:
                        g = rates[stream] = self.rate(stream)
                    if g <= base[i]:
                        continue
                    until = last + WINDOW_DETECTIONS / g
                    if until > start:
                        extra += (g - base[i]) * min((until - start) / span, 1.0)
                done[(lineage, base[i])] = extra
            result[i] += extra
        return result

    def after_scan(
        self,
        source: str,
        time: float,
        detected: Mapping[str, Iterable[int]],
        born: Mapping[str, Iterable[int]],
        alive: frozenset[int] | set[int],
        position: tuple[float, ...] | None = None,
    ) -> ObservedRates:
        """The rates after one scan of ``source`` at ``time``.

        ``detected``: per detector, the lineages (that existed before the scan) whose
        version in the most probable hypothesis took one of its detections; ``born``:
        per detector, the new lineages it started; ``alive``: every lineage the state
        holds after the scan; ``position``: where the source's sensor was.
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
            sources[source] = SourceClock(time, interval, position)
        else:
            sources[source] = SourceClock(clock.last_time, clock.interval, position)
        streams = dict(self.streams)
        detectors = {d for (s, d) in streams if s == source} | set(detected) | set(born)
        for detector in detectors:
            key = (source, detector)
            old = streams.get(key, StreamCounts())
            now = frozenset(detected.get(detector, ()))
            expected = old.detected & alive
            streams[key] = StreamCounts(
                DISCOUNT * old.hits + len(expected & now),
                DISCOUNT * old.expected + len(expected),
                now | frozenset(born.get(detector, ())),
            )
        seen = {lineage: streams_ for lineage, streams_ in self.seen.items() if lineage in alive}
        for detector in set(detected) | set(born):
            key = (source, detector)
            for lineage in (*detected.get(detector, ()), *born.get(detector, ())):
                if lineage in alive:
                    seen[lineage] = {**seen.get(lineage, {}), key: time}
        return ObservedRates(sources, streams, seen)
