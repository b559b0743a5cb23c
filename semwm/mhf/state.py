"""The MHF's values: object versions (tracks), hypotheses and the filter state.

Performance principle (DESIGN.md): an object version is stored once, in the
state's track table, and every hypothesis that holds it refers to it by key.
All three types are immutable: a step of the filter returns a new state, so a
rejected batch leaves the previous state untouched and old states serve as
snapshots for the reorder window.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

from semwm.filters.motion import FloatArray


@dataclass(frozen=True, eq=False, slots=True)
class Track:
    """One version of one object: its filter state after a given association history.

    Attributes
    ----------
    key
        Unique key of this version in the track table.
    lineage
        Identity of the object across versions: the sequence number of the
        detection that created it. Public ids are given to lineages.
    cls
        The most specific class the associated detections support.
    x, P, mu
        Filter state at ``time``: ``(M, n)``, ``(M, n, n)``, ``(M,)``.
    last_seen
        Time of the last detection associated with it (s).
    rate
        f_existing of its class (Hz), paper 002 eq. (6).
    """

    key: int
    lineage: int
    cls: str
    label: str | None
    x: FloatArray
    P: FloatArray
    mu: FloatArray
    time: float
    last_seen: float
    created: float
    rate: float

    def relabeled(self, key: int, label: str | None) -> Track:
        return Track(
            key,
            self.lineage,
            self.cls,
            label,
            self.x,
            self.P,
            self.mu,
            self.time,
            self.last_seen,
            self.created,
            self.rate,
        )


@dataclass(frozen=True, slots=True)
class Hypothesis:
    """A set of objects with a log probability.

    ``rate`` is the sum of f_existing over its objects, kept so that the
    normaliser F of paper 002 eqs. (5)-(7) costs O(1) per hypothesis.
    """

    log_weight: float
    tracks: frozenset[int]
    rate: float


@dataclass(frozen=True)
class MHFState:
    """The whole filter: hypotheses (most probable first, normalised) and the track table."""

    hypotheses: tuple[Hypothesis, ...]
    tracks: Mapping[int, Track]
    time: float | None
    next_key: int

    @staticmethod
    def empty() -> MHFState:
        return MHFState((Hypothesis(0.0, frozenset(), 0.0),), {}, None, 0)

    @property
    def best(self) -> Hypothesis:
        return self.hypotheses[0]
