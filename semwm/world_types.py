"""Values the world model answers with: objects of the world and hypothesis summaries."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, TypeVar

from semwm.confidence import Confidence

TENTATIVE_IDS = 1_000_000_000
"""Ids of tentative objects (below the publishing threshold) start above this: one
plus the number of the detection that started the object, added to it."""

_Value = TypeVar("_Value")


def made_without_init(cls: type[_Value], fields: dict[str, Any]) -> _Value:
    """A value of the frozen dataclass ``cls`` with ``fields`` (every field, by name),
    made without its ``__init__``, which sets each field through a guarded
    ``object.__setattr__`` (a :class:`WorldObject`: 1.2 µs; this: 0.4 µs). For the
    values made per object of a query or per scan; equal to, and as frozen as, the
    constructor's (tests hold each use to the constructor)."""
    value = _new_object(cls)
    value.__dict__.update(fields)
    return value


_new_object = object.__new__


@dataclass(frozen=True)
class WorldObject:
    """An object of the maximum a posteriori hypothesis, predicted to the query time.

    ``covariance`` is the position covariance (m^2); ``velocity`` is ``None`` for
    classes whose filter has no velocity; ``existence`` is the probability that the
    object exists (over every hypothesis: ``sum_h p(h) r_h(o)``); ``mode_probabilities``
    maps each motion model of an IMM to its probability; ``class_probabilities`` the
    probability of each class being its true class (``mht`` model; classes below
    0.001 left out), ``cls`` being the most specific class holding half of it. ``id``
    is stable while the object lives. ``tentative``: the object is below the
    publishing threshold (the knowledge's ``min_existence``) and a query asked for it
    (a lower ``min_existence``); its id is then :data:`TENTATIVE_IDS` plus one plus the
    number of the detection that started it (positive and stable; it answers
    :meth:`semwm.WorldModel.object` until the object is published, and then leads to
    the object under its published id). ``confidence``: paper 004's confidence value
    and state (``mht``; :mod:`semwm.confidence`).
    """

    id: int
    cls: str
    label: str | None
    position: tuple[float, ...]
    velocity: tuple[float, ...] | None
    covariance: tuple[tuple[float, ...], ...]
    existence: float
    last_seen: float
    created: float
    mode_probabilities: dict[str, float] | None
    class_probabilities: dict[str, float] | None = None
    confidence: Confidence | None = None
    tentative: bool = False

    def to_dict(self) -> dict[str, object]:
        """The fields as plain values (``cls`` as ``class``, last), what
        ``dataclasses.asdict`` gives, written out: ``asdict`` deep-copies every value and
        cost 21 µs per object, more than the query that made it."""
        modes, probabilities = self.mode_probabilities, self.class_probabilities
        return {
            "id": self.id,
            "label": self.label,
            "position": self.position,
            "velocity": self.velocity,
            "covariance": self.covariance,
            "existence": self.existence,
            "last_seen": self.last_seen,
            "created": self.created,
            "mode_probabilities": None if modes is None else dict(modes),
            "class_probabilities": None if probabilities is None else dict(probabilities),
            "confidence": None if self.confidence is None else self.confidence.to_dict(),
            "tentative": self.tentative,
            "class": self.cls,
        }


@dataclass(frozen=True)
class WorldState:
    """The world at ``time``: the MAP hypothesis's objects."""

    time: float | None
    objects: tuple[WorldObject, ...]

    def to_dict(self) -> dict[str, object]:
        return {"time": self.time, "objects": [o.to_dict() for o in self.objects]}


@dataclass(frozen=True)
class HypothesisObject:
    """An object of a hypothesis: its public id if it was ever published, its track, and
    its existence probability in this hypothesis (``mht``; 1 under ``paper``)."""

    id: int | None
    track: int
    cls: str
    label: str | None
    position: tuple[float, ...]
    existence: float = 1.0

    def to_dict(self) -> dict[str, object]:
        """The fields as plain values (``cls`` as ``class``, last), as
        :meth:`WorldObject.to_dict`."""
        return {
            "id": self.id,
            "track": self.track,
            "label": self.label,
            "position": self.position,
            "existence": self.existence,
            "class": self.cls,
        }


@dataclass(frozen=True)
class HypothesisSummary:
    """One hypothesis: its probability (and its log10, which does not round to 0) and its
    objects."""

    probability: float
    log10_probability: float
    objects: tuple[HypothesisObject, ...]

    def to_dict(self) -> dict[str, object]:
        return {
            "probability": self.probability,
            "log10_probability": self.log10_probability,
            "objects": [o.to_dict() for o in self.objects],
        }
