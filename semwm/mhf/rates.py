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

   f_s(o) = \max\big(f_c, \max_{d:\,(s,d) \text{ detected } o} g_{s,d}\big)

:math:`f_{s,d}(o)` is the rate of an existing object in the association weight of a
detection from ``(s, d)`` (:mod:`semwm.mhf.association`) and :math:`f_s(o)` the rate
at which a scan of source ``s`` that could have seen the object misses it
(:meth:`ObservedRates.watched`, :meth:`ObservedRates.source_rates`; issue 28: absence
is evidence only from a scan that could have seen the object), so the two stay one
Poisson model. With one source that reports at the knowledge's rate this is the
knowledge's model (``g = f_c``); the knowledge's rate is a floor, never lowered.
World setting ``observed_detection_rates: false`` turns the observed rates off (the
sources' clocks, which say when they look, are kept).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Collection, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np
from scipy.special import ndtr

from semwm.filters.motion import FloatArray

if TYPE_CHECKING:
    from semwm.knowledge.model import Knowledge

RangeCoverage = Callable[[FloatArray, FloatArray, float, "FloatArray | None"], FloatArray]
"""The signature of :func:`range_coverage`."""

HullDistance = Callable[[FloatArray, FloatArray], FloatArray]
"""The signature of :func:`hull_distance`."""

StreamKey = tuple[str, str]
"""``(source, detector)``; the source ``""`` for detections that name none."""

CountKey = tuple[str, str, str]
"""``(source, detector, class)``; the class ``""`` when the caller gave none."""

PRIOR_COUNTS = 10.0
"""Strength (pseudo-counts) of the prior of a stream's per-scan detection probability:
the knowledge's figure counts as ten chances to detect, a tenth of what the stream
remembers (:data:`DISCOUNT`). With 2, a class detected now and then (a table in one
frame in five: about a dozen chances in 20 s) took its rate from a handful of chances,
and a lucky run (4 of 11) made every miss count nearly twice (sim1_edge, seed 7: the
table left the world twice)."""

WINDOW_DETECTIONS = 3.0
"""A stream sees an object for this many of its expected detection intervals after
its last detection of it."""

INTERVAL_WEIGHT = 0.1
"""Weight of the newest interval in a source's mean interval between scans."""

DISCOUNT = 0.99
"""Per chance to detect again (an expected detection), the weight kept by a stream's hit
and miss counts: its recall is learnt over its last hundred or so chances. Forgetting
by chances, not by scans: a class the stream sees now and then keeps what it learnt
while out of view (per scan, its counts went back to the prior after 60 s unseen, and
the first few hits of the next view made its recall 0.9 or more for a camera of 0.8)."""

MAX_MISS_INTERVALS = 2.0
"""A scan counts as a miss for at most this many of its source's mean intervals since
the source's previous scan: a source that was silent longer did not keep looking."""


@dataclass(frozen=True, slots=True)
class ScanCoverage:
    """What one scan without a sensor view tells about where its source looked.

    ``source``: its source (``""`` for none); ``positions`` ``(M, d)``: its
    detections' positions; ``sensor``: where its sensor was (the detections'
    ``sensor_position``, or a static detector's ``position``), if given; ``reach``:
    the largest ``range`` of its detectors, if every one of them has one;
    ``fixed``: every detector of the scan is ``static`` (it sees the whole region, or
    ``reach`` around ``sensor``).
    """

    source: str
    positions: FloatArray
    sensor: FloatArray | None = None
    reach: float | None = None
    fixed: bool = False


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


@dataclass(frozen=True, slots=True)
class StreamCounts:
    """A stream's discounted counts: of the objects it detected in one scan of its
    detector that still existed at the next (``expected``), how many it detected again
    (``hits``); and the lineages it detected in its detector's last scan. An object
    counts from its second detection: one the stream only started may be a false
    alarm, and counting those as misses made a clutter-only class's stream learn a
    recall near 0 (:class:`FalseAlarms` counts them)."""

    hits: float = 0.0
    expected: float = 0.0
    detected: frozenset[int] = frozenset()

    def detection_probability(self, prior: float = 0.5) -> float:
        """Posterior mean per-scan detection probability, prior mean ``prior``."""
        return (self.hits + PRIOR_COUNTS * prior) / (self.expected + PRIOR_COUNTS)


@dataclass(frozen=True, slots=True)
class FalseAlarms:
    """A stream's false alarms as its data shows them: lineages it started that nothing
    has confirmed yet (``pending``), how many of those died unconfirmed
    (``count``), and when it was first heard of (``since``, s)."""

    since: float
    pending: frozenset[int] = frozenset()
    count: int = 0

    def after(
        self, started: Iterable[int], confirmed: Collection[int], alive: Collection[int]
    ) -> FalseAlarms:
        """After a scan: ``started`` lineages become pending, ``confirmed`` ones (a later
        detection took them) leave the pending set, and pending ones no longer
        ``alive`` count as false alarms."""
        still = self.pending - set(confirmed)
        dead = {lineage for lineage in still if lineage not in alive}
        return FalseAlarms(
            self.since, frozenset((still - dead) | set(started)), self.count + len(dead)
        )


RATE_WARNING_FACTOR = 3.0
"""The data's rate and the knowledge's differ by more than this: a warning."""

MIN_EVIDENCE_SECONDS = 10.0
"""A stream's clutter rate is judged after this long (s)."""

MIN_EVIDENCE_SCANS = 20.0
"""A stream's detection rate of a class is judged after this many expected detections."""


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
    false_alarms: Mapping[StreamKey, FalseAlarms] = field(default_factory=dict)

    def report(self, knowledge: Knowledge) -> list[StreamReport]:
        """Per stream, the clutter and detection rates its data shows beside the
        knowledge's, with a warning where they differ by more than
        :data:`RATE_WARNING_FACTOR` (a datasheet's numbers are often wrong)."""
        reports = []
        for (source, detector), alarms in sorted(self.false_alarms.items()):
            clock = self.sources.get(source)
            spec = knowledge.detectors.get(detector)
            if clock is None or spec is None:
                continue
            span = clock.last_time - alarms.since
            clutter = alarms.count / span if span > 0 else None
            warnings = []
            judged = clutter is not None and span >= MIN_EVIDENCE_SECONDS
            if judged and clutter is not None and _differs(clutter, spec.clutter_frequency):
                warnings.append(
                    f"clutter: {clutter:.3g} Hz in the data, {spec.clutter_frequency:g} Hz "
                    f"in the knowledge (detector {detector!r}'s clutter_frequency)"
                )
            detection: dict[str, float] = {}
            for (s, d, cls), counts in sorted(self.streams.items()):
                if s != source or d != detector or cls not in knowledge.classes:
                    continue
                known = knowledge.classes[cls].detection_frequency
                g = self.rate((s, d), cls, known)
                detection[cls] = g
                if counts.expected >= MIN_EVIDENCE_SCANS and _differs(g, known):
                    warnings.append(
                        f"detection of {cls}: {g:.3g} Hz in the data, {known:g} Hz in the "
                        "knowledge (its detection_frequency)"
                    )
            known_rates = {c: knowledge.classes[c].detection_frequency for c in detection}
            reports.append(
                StreamReport(
                    source,
                    detector,
                    span,
                    clutter,
                    spec.clutter_frequency,
                    detection,
                    known_rates,
                    tuple(warnings),
                )
            )
        return reports

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

    def miss_span(self, source: str, time: float) -> float:
        """s: how long before ``time`` a scan of ``source`` says it kept looking: the
        time since its previous scan, at most :data:`MAX_MISS_INTERVALS` of its mean
        interval (the whole time for its second scan, which sets that interval); 0 for
        its first."""
        clock = self.sources.get(source)
        if clock is None or time <= clock.last_time:
            return 0.0
        step = time - clock.last_time
        if clock.interval is None:
            return step
        return min(step, MAX_MISS_INTERVALS * clock.interval)

    @staticmethod
    def watched(
        scan: ScanCoverage,
        sources: Sequence[frozenset[str]],
        positions: FloatArray,
        margins: FloatArray,
        unconfirmed: Sequence[bool],
        spread: FloatArray | None = None,
        ranged: RangeCoverage | None = None,
        hull: HullDistance | None = None,
    ) -> FloatArray:
        r"""``(N,)``: the probability that the scan could have seen each object, so that
        not reporting it is evidence that it is gone (docs/knowledge.md, "What semwm
        concludes from not seeing something").

        * The scan gave its sensor's position and every detector of it has a
          ``range``: the probability that the object is within that range of the
          sensor (:func:`range_coverage`, with ``d`` its estimate's distance and ``s``
          its ``spread``, m), the range shortened by the object's widest ``margins``
          (its noise at the gate's quantile; zero for a class that moves): an object
          that stands within its noise of the range's edge may be just outside it,
          and is then never detected there, however often the sensor passes it by.
        * Every detector of the scan is declared ``static`` in the knowledge (fixed
          coverage): every object (the region's inside probability weighs it in
          :meth:`~semwm.mhf.filter.MultipleHypothesisFilter.miss_rates`).
        * Otherwise the source's coverage is learnt from what it reports: an object
          the source has itself detected (``sources``: each object version's
          :attr:`~semwm.mhf.state.Track.sources`), and either among what this scan
          reports (within the convex hull of its detections, widened by the
          object's ``margins``: a sensor's view is convex, so what lies between
          things it sees now is in its view too), or reported once and never
          confirmed (a lone false alarm is denied by the sensor that made it, while
          that sensor keeps scanning).

        An object another source found, or that this source found elsewhere than it
        now looks, is not watched: a scan from elsewhere is never a miss.

        ``ranged`` and ``hull``: the engine's :func:`range_coverage` and
        :func:`hull_distance` (:mod:`semwm.mhf.kernels`); these by default.
        """
        ranged = range_coverage if ranged is None else ranged
        hull = hull_distance if hull is None else hull
        count = len(sources)
        if count == 0:
            return np.zeros(0)
        radius = margins.max(axis=1) if margins.size else np.zeros(count)
        if scan.sensor is not None and scan.reach is not None:
            if not radius.any():
                return ranged(positions, scan.sensor, scan.reach, spread)
            covered = np.zeros(count)
            for edge in np.unique(radius).tolist():  # one call per class, in effect
                rows = np.flatnonzero(radius == edge)
                covered[rows] = ranged(
                    positions[rows],
                    scan.sensor,
                    max(scan.reach - edge, 0.0),
                    None if spread is None else spread[rows],
                )
            return covered
        if scan.fixed:
            return np.ones(count)
        source = scan.source
        by_source = np.fromiter((source in s for s in sources), dtype=bool, count=count)
        if not by_source.any():
            return np.zeros(count)
        near = np.zeros(count, dtype=bool)
        if scan.positions.shape[0]:
            rows = np.flatnonzero(by_source)
            d = min(positions.shape[1], scan.positions.shape[1])
            near[rows] = hull(positions[rows, :d], scan.positions[:, :d]) <= radius[rows]
        watched = by_source & (near | np.asarray(unconfirmed, dtype=bool))
        result: FloatArray = watched.astype(float)
        return result

    def source_rates(
        self,
        source: str,
        lineages: Sequence[int],
        class_rates: FloatArray,
        classes: Sequence[str],
    ) -> FloatArray:
        """``(N,)``: the rate (Hz) at which ``source`` reports each object while it sees
        it: the class's rate, raised to the observed rate of any of the source's
        detectors that has detected the object (:math:`f_{s,d}(o)`, the missed-detection
        rate of one source)."""
        result = np.array(class_rates, dtype=float, copy=True)
        if not self.seen:
            return result
        base = result.tolist()
        rates: dict[CountKey, float] = {}
        never: Mapping[StreamKey, float] = {}
        for i, lineage in enumerate(lineages):
            for stream in self.seen.get(lineage, never):
                if stream[0] != source:
                    continue
                key = (stream[0], stream[1], classes[i])
                g = rates.get(key)
                if g is None:
                    g = rates[key] = self.rate(stream, classes[i], base[i])
                if g > result[i]:
                    result[i] = g
        return result

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
        scanned: Collection[str] | None = None,
        out_of_view: Collection[int] = frozenset(),
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
        no stream and fade at the class's rate for seconds. ``scanned``: the detectors
        that made the scan (``None``: every detector of the source); only their
        streams count what they missed (a scan of the source's laser is no miss of
        its camera; an empty scan with a sensor view is a miss of everything its
        detector had detected). ``out_of_view``: lineages the scan's sensor view did
        not hold (an object the robot turned away from had no chance to be detected
        again: not a miss of its stream's recall).
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

        keys = {k for k in streams if k[0] == source and (scanned is None or k[1] in scanned)}
        for detector in set(detected) | set(born):
            for lineage in (*detected.get(detector, ()), *born.get(detector, ())):
                keys.add((source, detector, class_of(lineage)))
        for key in keys:
            detector, cls = key[1], key[2]
            old = streams.get(key, StreamCounts())
            # a hit is any detection of the object by the stream, whatever class it now has
            every = frozenset(detected.get(detector, ()))
            now = frozenset(lineage for lineage in every if class_of(lineage) == cls)
            expected = (old.detected & alive) - frozenset(out_of_view)
            kept = DISCOUNT ** len(expected)  # forget by evidence, not by time
            streams[key] = StreamCounts(
                kept * old.hits + len(expected & every),
                kept * old.expected + len(expected),
                now,  # a lineage counts once confirmed: a false alarm is not a miss
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
        alarms = dict(self.false_alarms)
        confirmed = {lineage for lineages in detected.values() for lineage in lineages}
        for detector in {*detected, *born, *(born_elsewhere or {})}:
            alarms.setdefault((source, detector), FalseAlarms(time))
        for stream_key, before in list(alarms.items()):
            if stream_key[0] != source:
                continue
            by = stream_key[1]
            new_lineages = (*born.get(by, ()), *(born_elsewhere or {}).get(by, ()))
            alarms[stream_key] = before.after(new_lineages, confirmed, alive)
        return ObservedRates(sources, streams, seen, alarms)


@dataclass(frozen=True)
class StreamReport:
    """One stream's rates: what its data shows (``clutter`` Hz over ``seconds``;
    ``detection`` Hz per class) beside the knowledge's, and the warnings."""

    source: str
    detector: str
    seconds: float
    clutter: float | None
    knowledge_clutter: float
    detection: Mapping[str, float]
    knowledge_detection: Mapping[str, float]
    warnings: tuple[str, ...]

    def to_dict(self) -> dict[str, object]:
        return {
            "detector": self.detector,
            "seconds": self.seconds,
            "clutter_hz": self.clutter,
            "knowledge_clutter_hz": self.knowledge_clutter,
            "detection_hz": dict(self.detection),
            "knowledge_detection_hz": dict(self.knowledge_detection),
            "warnings": list(self.warnings),
        }


def _differs(observed: float, known: float) -> bool:
    """More than :data:`RATE_WARNING_FACTOR` apart (either way; a zero against a
    positive rate differs)."""
    if known <= 0.0 or observed <= 0.0:
        return (known <= 0.0) != (observed <= 0.0)
    ratio = observed / known
    return ratio > RATE_WARNING_FACTOR or ratio < 1.0 / RATE_WARNING_FACTOR


WIDE_SPREAD = 0.25
"""A spread above this fraction of the reach makes :func:`range_coverage` integrate over
the sensor's disc (ball): there its edge is not straight at the estimate's scale."""

SERIES_CENTRE = 200.0
"""The largest ``(d / s)^2 / 2`` (the Poisson mixture's centre) for which
:func:`ball_probability` sums its series; beyond it the estimate lies more than 20
spreads from the sensor, the disc's edge is straight at its scale and the 1-D form
holds."""


def range_coverage(
    positions: FloatArray, sensor: FloatArray, reach: float, spread: FloatArray | None = None
) -> FloatArray:
    r"""``(N,)``: the probability that each object (estimate ``positions`` ``(N, d)``) is
    within ``reach`` (m) of the sensor at ``sensor`` (their first ``k = min(d, k)`` axes).

    With ``spread`` :math:`\sigma` ``(N,)`` (m) the object is taken as isotropic
    Gaussian around its estimate. Where the estimate is tight against the reach
    (:math:`\sigma \le` :data:`WIDE_SPREAD` :math:`r`) or far from the sensor, the
    disc's edge is straight at its scale:

    .. math:: \Phi\Big(\frac{r - \lVert x - s \rVert}{\max(\sigma, 10^{-9})}\Big)

    otherwise the probability of the disc (ball) itself, :func:`ball_probability`: an
    estimate spread far wider than the reach (a ball nobody has seen for a minute) is
    within it with probability about :math:`r^2 / 2\sigma^2`, not one half.
    ``None`` makes it a hard cut (:math:`\lVert x - s \rVert \le r`)."""
    k = min(positions.shape[1], sensor.shape[0])
    offset = positions[:, :k] - sensor[:k]
    distance = np.sqrt(np.einsum("nd,nd->n", offset, offset))
    if spread is None:
        hard: FloatArray = (distance <= reach).astype(float)
        return hard
    sd = np.maximum(spread, 1e-9)
    inside: FloatArray = ndtr((reach - distance) / sd)
    wide = (sd > WIDE_SPREAD * reach) & (0.5 * (distance / sd) ** 2 <= SERIES_CENTRE)
    for i in np.flatnonzero(wide).tolist():
        inside[i] = ball_probability(float(distance[i] / sd[i]), float(reach / sd[i]), k)
    return inside


def ball_probability(centre: float, radius: float, dim: int) -> float:
    r"""``P(|X| <= radius)`` for ``X ~ N(mu, I_dim)`` with ``|mu| = centre`` (the CDF of
    the noncentral chi distribution), for ``dim`` 1, 2 or 3.

    * 1: :math:`\Phi(b - a) - \Phi(-b - a)`;
    * 3: :math:`\Phi(b - a) - \Phi(-b - a) - (\varphi(b - a) - \varphi(b + a)) / a`
      (its limit :math:`2\Phi(b) - 1 - 2 b \varphi(b)` at :math:`a = 0`);
    * 2: the noncentral :math:`\chi^2_2` CDF at :math:`b^2` as its Poisson mixture of
      central ones, :math:`\sum_j \mathrm{Pois}(j; a^2/2)\, P(j + 1, b^2/2)`
      (:math:`P` the regularised lower incomplete gamma function,
      :math:`1 - e^{-y}\sum_{i \le j} y^i / i!`), summed until the Poisson weight
      left is below 1e-16.
    """
    a, b = centre, radius
    if dim == 1 or dim > 3:
        return float(ndtr(b - a) - ndtr(-b - a))
    if dim == 3:
        if a < 1e-8:
            return float(2.0 * ndtr(b) - 1.0 - 2.0 * b * _normal_pdf(b))
        return float(ndtr(b - a) - ndtr(-b - a) - (_normal_pdf(b - a) - _normal_pdf(b + a)) / a)
    m, y = 0.5 * a * a, 0.5 * b * b
    log_m = math.log(m) if m > 0.0 else -math.inf
    log_y = math.log(y) if y > 0.0 else -math.inf
    log_factorial = 0.0
    below = 0.0  # sum_{i <= j} e^-y y^i / i!
    total = 0.0
    j = 0
    while True:
        if j > 0:
            log_factorial += math.log(j)
        below += math.exp(-y + j * log_y - log_factorial) if y > 0.0 else float(j == 0)
        weight = math.exp(-m + j * log_m - log_factorial) if m > 0.0 else float(j == 0)
        total += weight * max(0.0, 1.0 - below)
        j += 1
        if m == 0.0 or (j > m and weight * j / (j - m) < 1e-17):
            break
    return min(max(total, 0.0), 1.0)


def _normal_pdf(x: float) -> float:
    return math.exp(-0.5 * x * x) / math.sqrt(2.0 * math.pi)


FLAT = 1e-6
"""Corners whose smallest singular value (centred) is at most this fraction of their
largest lie on one line (or plane) for :func:`hull_distance`: it measures to the segment
of their extremes. Stated here, not left to qhull's own tolerance, so that every engine
draws the line in the same place."""


def hull_distance(points: FloatArray, corners: FloatArray) -> FloatArray:
    """``(N,)`` (m): how far each point lies outside the convex hull of ``corners``
    ``(M, d)`` (0 inside): the distance to the point for one corner, to the segment of
    the extremes for fewer than ``d + 1`` corners or corners on one line or plane
    (:data:`FLAT`); otherwise the largest signed distance to the hull's facets (exact
    inside and along the faces, at most the true distance beyond a corner)."""
    if corners.shape[0] == 1:
        offset = points - corners[0]
        result: FloatArray = np.sqrt(np.einsum("nd,nd->n", offset, offset))
        return result
    centred = corners - corners.mean(axis=0)
    _, singular, axes = np.linalg.svd(centred, full_matrices=False)
    solid = corners.shape[0] >= points.shape[1] + 1 and singular[-1] > FLAT * singular[0]
    if solid:
        from scipy.spatial import ConvexHull, QhullError  # only scans of several need it

        try:
            equations = ConvexHull(corners).equations  # (F, d + 1): unit normal, offset
        except QhullError:  # qhull's tolerance is tighter than FLAT: not expected
            pass
        else:
            signed = points @ equations[:, :-1].T + equations[:, -1]
            outside: FloatArray = np.maximum(signed.max(axis=1), 0.0)
            return outside
    direction = axes[0]
    along = centred @ direction
    a = corners.mean(axis=0) + along.min() * direction
    b = corners.mean(axis=0) + along.max() * direction
    ab = b - a
    length = float(ab @ ab)
    t = np.clip((points - a) @ ab / length, 0.0, 1.0) if length > 0 else np.zeros(len(points))
    offset = points - (a + t[:, None] * ab)
    segment: FloatArray = np.sqrt(np.einsum("nd,nd->n", offset, offset))
    return segment
