"""Confidence of objects (paper 004 Section IV, Fig. 5): valid, suspicious, invalid.

Each object (lineage) carries a confidence ``c`` in [0, 1]:

* a detection associated with it (in the most probable hypothesis that holds it)
  sets ``c`` to its detector's ``confidence`` (1 for one's own camera, less for a
  teammate's relayed estimate);
* while it is not seen, ``c`` decays: ``c <- c exp(-lambda dt)`` with the class's
  ``confidence_decay`` (1/s), or its ``looking_decay`` over the interval ending in a
  scan whose view held it (or that flagged it ``looking_at``) and that did not
  report it: negative information, paper 004's active feedback; and by
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
from typing import Literal

import numpy as np

from semwm.filters.factory import FilterFactory
from semwm.knowledge.model import Knowledge, ResolvedClass
from semwm.mhf.existence import in_view_probability
from semwm.mhf.measurement import Measurement, SensorView
from semwm.mhf.predict import predict_tracks
from semwm.mhf.state import MHFState, Track

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


@dataclass(frozen=True)
class ConfidenceBook:
    """Each lineage's confidence at a time, and each source's last sensor position."""

    values: Mapping[int, tuple[float, float]] = field(default_factory=dict)
    poses: Mapping[str, tuple[float, float]] = field(default_factory=dict)

    def at(self, lineage: int, time: float, spec: ResolvedClass) -> float:
        """The lineage's confidence carried to ``time`` with no scan in between."""
        entry = self.values.get(lineage)
        if entry is None:
            return 1.0
        value, since = entry
        return value * math.exp(-spec.confidence_decay * max(0.0, time - since))


def representatives(state: MHFState) -> dict[int, Track]:
    """Each lineage's version in the most probable hypothesis that holds it."""
    chosen: dict[int, Track] = {}
    for cluster in state.clusters:
        for h in cluster.hypotheses:
            for key in h.tracks:
                track = state.tracks[key]
                chosen.setdefault(track.lineage, track)
    return chosen


def advance(
    book: ConfidenceBook,
    state: MHFState,
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
    if view is not None and view.source is not None:
        here = (float(view.position[0]), float(view.position[1]))
        before = poses.get(view.source)
        if before is not None:
            moved = math.dist(before, here)
        poses[view.source] = here
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
        rate = spec.looking_decay if lineage in looked else spec.confidence_decay
        value *= math.exp(-rate * max(0.0, time - since))
        value *= math.exp(-spec.confidence_decay_distance * moved)
        values[lineage] = (value, time)
    return ConfidenceBook(values, poses)


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
    )
