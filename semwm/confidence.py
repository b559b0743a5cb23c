"""Confidence of objects (paper 004 Section IV, Fig. 5): valid, suspicious, invalid.

Each object (lineage) carries a confidence ``c`` in [0, 1]:

* a detection associated with it (in the most probable hypothesis that holds it)
  sets ``c`` to its detector's ``confidence`` (1 for one's own camera, less for a
  teammate's relayed estimate);
* while it is not seen, ``c`` decays: ``c <- c exp(-lambda dt)`` with the class's
  ``confidence_decay`` (1/s), or its ``looking_decay`` over the interval since the
  same source's previous scan (at most :data:`MAX_LOOK`) when a scan's view held it
  (or flagged it ``looking_at``) and did not report it: negative information,
  paper 004's active feedback (each robot's looks count, whoever scans between);
  and by
  ``exp(-kappa moved)`` (``confidence_decay_distance``, 1/m) when a scan's sensor
  pose shows its observer moved (static landmarks, paper 004 IV-A-3);
* the class's ``suspicious_confidence`` and ``invalid_confidence`` turn it into a
  state.

Confidence is the paper's heuristic, not a probability: the existence probability
(:mod:`semwm.mhf.existence`) is the Bayesian answer to "does it exist", and the
two differ (docs/api.md, "Confidence and existence").
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Literal, Protocol

import numpy as np

from semwm.filters.factory import FilterFactory
from semwm.knowledge.model import Knowledge, ResolvedClass
from semwm.mhf.existence import in_view_probability
from semwm.mhf.measurement import Measurement, SensorView
from semwm.mhf.predict import predict_tracks
from semwm.mhf.state import StateView, Track

ConfidenceState = Literal["valid", "suspicious", "invalid"]
CONFIDENCE_STATES: tuple[ConfidenceState, ...] = ("valid", "suspicious", "invalid")


@dataclass(frozen=True)
class Confidence:
    """An object's confidence value and its state."""

    value: float
    state: ConfidenceState

    def to_dict(self) -> dict[str, object]:
        return {"value": self.value, "state": self.state}


def state_of(value: float, spec: ResolvedClass) -> ConfidenceState:
    """Paper 004 Fig. 5: thresholds l_suspicious and l_invalid of the class."""
    if value < spec.invalid_confidence:
        return "invalid"
    if value < spec.suspicious_confidence:
        return "suspicious"
    return "valid"


MAX_LOOK = 1.0
"""s: the longest interval one scan's look counts for (a source silent longer than
this did not keep looking)."""


class BookView(Protocol):
    """What reading confidences needs: :class:`ConfidenceBook`, or the Rust engine's
    book kept in the core (:class:`semwm.mhf.core_engine.CoreBook`)."""

    def at(self, lineage: int, time: float, spec: ResolvedClass) -> float: ...


@dataclass(frozen=True)
class ConfidenceBook:
    """Each lineage's confidence at a time, and each source's last sensor position and
    last scan time."""

    values: Mapping[int, tuple[float, float]] = field(default_factory=dict)
    poses: Mapping[str, tuple[float, float]] = field(default_factory=dict)
    scans: Mapping[str, float] = field(default_factory=dict)

    def at(self, lineage: int, time: float, spec: ResolvedClass) -> float:
        """The lineage's confidence carried to ``time`` with no scan in between."""
        return carried(self.values.get(lineage), time, spec)


def carried(entry: tuple[float, float] | None, time: float, spec: ResolvedClass) -> float:
    """A confidence ``(value, since)`` carried to ``time`` with no scan in between
    (``c exp(-lambda dt)``); 1 for a lineage the book does not hold."""
    if entry is None:
        return 1.0
    value, since = entry
    return value * math.exp(-spec.confidence_decay * max(0.0, time - since))


def representatives(state: StateView) -> dict[int, Track]:
    """Each lineage's version in the most probable hypothesis that holds it."""
    chosen: dict[int, Track] = {}
    tracks = state.tracks
    for cluster in state.clusters:
        if len(cluster.hypotheses) == 1:
            for key in cluster.hypotheses[0].tracks:
                track = tracks[key]
                chosen.setdefault(track.lineage, track)
            continue
        # every lineage of the cluster, to stop at the first hypotheses that hold them all
        pending = {tracks[key].lineage for key in cluster.keys}
        pending.difference_update(chosen)
        for h in cluster.hypotheses:
            for key in h.tracks:
                track = tracks[key]
                if track.lineage in pending:
                    chosen[track.lineage] = track
                    pending.discard(track.lineage)
            if not pending:
                break
    return chosen


def advance(
    book: ConfidenceBook,
    state: StateView,
    measurements: Sequence[Measurement],
    view: SensorView | None,
    knowledge: Knowledge,
    factory: FilterFactory,
) -> ConfidenceBook:
    """The book after one scan (``state`` is the filter after it)."""
    time = state.time
    if time is None:
        return book
    chosen = representatives(state)
    set_to = max((knowledge.detectors[m.detector].confidence for m in measurements), default=1.0)
    looked: set[int] = set()
    if view is not None:
        unseen = [t for t in chosen.values() if t.last_seen < time]
        if unseen:
            predicted = predict_tracks(unseen, time, factory)
            inside = in_view_probability(predicted.position, predicted.position_covariance, view)
            looked = {
                t.lineage
                for t, p in zip(unseen, inside, strict=True)
                if p >= 0.5 or t.lineage in view.looking_at
            }
    moved = 0.0
    poses = dict(book.poses)
    scans = dict(book.scans)
    source = view.source if view is not None else None
    looked_for: float | None = None  # how long this source's look lasted (s)
    if view is not None and source is not None:
        here = (float(view.position[0]), float(view.position[1]))
        before = poses.get(source)
        if before is not None:
            moved = math.dist(before, here)
        poses[source] = here
        if source in scans:
            looked_for = min(MAX_LOOK, max(0.0, time - scans[source]))
    if source is not None:
        scans[source] = time
    values: dict[int, tuple[float, float]] = {}
    for lineage, track in chosen.items():
        spec = knowledge.classes.get(track.cls)
        if spec is None:
            continue
        entry = book.values.get(lineage)
        if track.last_seen >= time or entry is None:
            values[lineage] = (set_to if track.last_seen >= time else 1.0, time)
            continue
        value, since = entry
        value *= math.exp(-spec.confidence_decay * max(0.0, time - since))
        if lineage in looked:  # the looking rate instead of the usual one, while it looked
            look = looked_for if looked_for is not None else max(0.0, time - since)
            extra = max(0.0, spec.looking_decay - spec.confidence_decay)
            value *= math.exp(-extra * min(look, MAX_LOOK))
        value *= math.exp(-spec.confidence_decay_distance * moved)
        values[lineage] = (value, time)
    return ConfidenceBook(values, poses, scans)


def view_of(
    pose: Sequence[float],
    time: float,
    source: str | None,
    detector: str,
    knowledge: Knowledge,
    looking_at: frozenset[int] = frozenset(),
) -> SensorView:
    """A sensor view from a pose ``[x, y, (z,) heading]`` and the detector's coverage."""
    spec = knowledge.detectors[detector]
    half = (
        math.radians(spec.field_of_view) / 2.0
        if spec.field_of_view is not None and spec.field_of_view < 360.0
        else None
    )
    return SensorView(
        time=time,
        source=source,
        position=np.asarray(pose[:2], dtype=float),
        heading=float(pose[-1]),
        range=spec.range,
        half_angle=half,
        looking_at=looking_at,
        detector=detector,
    )
