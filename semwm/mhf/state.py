"""The MHF's values: object versions (tracks), hypotheses and the filter state.

Performance principle (DESIGN.md): an object version is stored once, in the
state's track table, and every hypothesis that holds it refers to it by key.
All three types are immutable: a step of the filter returns a new state, so a
rejected batch leaves the previous state untouched and old states serve as
snapshots for the reorder window.
"""

from __future__ import annotations

import heapq
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import NamedTuple, Protocol

from semwm.filters.motion import FloatArray
from semwm.mhf.rates import ObservedRates


@dataclass(eq=False, slots=True)
class Track:
    """One version of one object: its filter state after a given association history.

    Never changed once made (a step of the filter makes new versions). It is not a
    frozen dataclass only for speed: a frozen dataclass's ``__init__`` sets each of
    its 12 fields through ``object.__setattr__`` (2.2 µs against 0.4 µs), and the
    filter makes tens of versions per detection.

    Attributes
    ----------
    key
        Unique key of this version in the track table.
    lineage
        Identity of the object across versions: the sequence number of the
        detection that created it. Public ids are given to lineages.
    cls
        The published class: the most specific class the associated detections
        support (``mht``: the most specific class holding half of ``class_probs``);
        the class whose filter tracks it.
    x, P, mu
        Filter state at ``time``: ``(M, n)``, ``(M, n, n)``, ``(M,)``.
    last_seen
        Time of the last detection associated with it (s).
    rate
        f_existing of its class (Hz), paper 002 eq. (6).
    class_probs
        ``(K,)`` probability of each class of the knowledge (sorted by name) being
        its true class (:mod:`semwm.mhf.classes`).
    sources
        The sources whose detections this version took (its history's; ``""`` for
        detections that name none): only their scans can miss it where no sensor view
        says more (:meth:`semwm.mhf.rates.ObservedRates.watched`).
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
    class_probs: FloatArray
    sources: frozenset[str] = frozenset()

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
            self.class_probs,
            self.sources,
        )


class Hypothesis(NamedTuple):
    """A set of objects with a log probability (a named tuple: cheap to make, compared
    and hashed by value).

    ``rate`` is the sum of f_existing over its objects, kept so that the
    normaliser F of paper 002 eqs. (5)-(7) costs O(1) per hypothesis.
    """

    log_weight: float
    tracks: frozenset[int]
    rate: float


class Cluster(NamedTuple):
    """Hypotheses over a group of objects that no detection has yet tied to others.

    Under the ``mht`` association model hypothesis weights factorise over such
    groups, so the global hypotheses are the products of one hypothesis per
    cluster, and their probabilities the products of the clusters' (each cluster
    is normalised on its own). ``keys`` is every object version its hypotheses hold.
    """

    hypotheses: tuple[Hypothesis, ...]
    keys: frozenset[int]

    @staticmethod
    def of(hypotheses: tuple[Hypothesis, ...]) -> Cluster:
        return Cluster(hypotheses, frozenset().union(*(h.tracks for h in hypotheses)))


class StateView(Protocol):
    """What reading a filter state needs: :class:`MHFState` (the Python engine's), or
    the Rust engine's state kept in the core
    (:class:`semwm.mhf.core_engine.CoreState`). Read-only: a step of the filter
    returns a new state."""

    @property
    def clusters(self) -> tuple[Cluster, ...]: ...

    @property
    def tracks(self) -> Mapping[int, Track]: ...

    @property
    def time(self) -> float | None: ...

    @property
    def next_key(self) -> int: ...

    @property
    def existence(self) -> Mapping[int, float]: ...

    @property
    def observed(self) -> ObservedRates: ...

    @property
    def best(self) -> Hypothesis: ...

    @property
    def hypothesis_count(self) -> int: ...

    @property
    def log10_joint_count(self) -> float: ...

    @property
    def cluster_count(self) -> int: ...

    @property
    def track_count(self) -> int: ...

    def top(self, k: int) -> list[Hypothesis]: ...


@dataclass(frozen=True)
class MHFState:
    """The whole filter: independent clusters of hypotheses (each most probable first,
    normalised), the track table, each version's existence probability at
    ``time`` (:mod:`semwm.mhf.existence`; 1 for every version under ``paper``), and
    the detection rates observed on the sources' streams (:mod:`semwm.mhf.rates`)."""

    clusters: tuple[Cluster, ...]
    tracks: Mapping[int, Track]
    time: float | None
    next_key: int
    existence: Mapping[int, float]
    observed: ObservedRates = field(default_factory=ObservedRates)

    @staticmethod
    def empty() -> MHFState:
        return MHFState((), {}, None, 0, {})

    @property
    def best(self) -> Hypothesis:
        """The maximum a posteriori hypothesis: the best of every cluster."""
        log_weight = 0.0
        tracks: set[int] = set()
        rate = 0.0
        for cluster in self.clusters:
            h = cluster.hypotheses[0]
            log_weight += h.log_weight
            tracks |= h.tracks
            rate += h.rate
        return Hypothesis(log_weight, frozenset(tracks), rate)

    @property
    def hypothesis_count(self) -> int:
        """Number of hypotheses stored: the sum of the clusters' counts (the global
        hypotheses are their combinations; see :attr:`log10_joint_count`)."""
        return sum(len(c.hypotheses) for c in self.clusters)

    @property
    def log10_joint_count(self) -> float:
        """log10 of the number of global hypotheses (the product of the clusters'
        counts, which can have thousands of digits)."""
        return math.fsum(math.log10(len(c.hypotheses)) for c in self.clusters)

    @property
    def cluster_count(self) -> int:
        """Number of clusters."""
        return len(self.clusters)

    @property
    def track_count(self) -> int:
        """Number of stored object versions."""
        return len(self.tracks)

    def top(self, k: int) -> list[Hypothesis]:
        """The ``k`` most probable global hypotheses, best first.

        k-best of a product of sorted lists: a combination is the best hypothesis
        with some clusters moved to a lower-ranked hypothesis, written as its changes
        ``((cluster, rank), ...)`` in increasing cluster order. Each combination is
        reached by exactly one path (raise the last change's rank, or add a change at
        a later cluster), and children are never more probable than their parent,
        so a best-first search pops them in order. Memory is O(k x clusters).
        """
        multi = [c.hypotheses for c in self.clusters if len(c.hypotheses) > 1]
        best = self.best
        result: list[Hypothesis] = []
        counter = 0
        heap: list[tuple[float, int, tuple[tuple[int, int], ...]]] = [(-best.log_weight, 0, ())]
        while heap and len(result) < k:
            negative, _, changes = heapq.heappop(heap)
            tracks = set(best.tracks)
            rate = best.rate
            for position, rank in changes:
                chosen, first = multi[position][rank], multi[position][0]
                tracks -= first.tracks
                tracks |= chosen.tracks
                rate += chosen.rate - first.rate
            result.append(Hypothesis(-negative, frozenset(tracks), rate))
            children = []
            if changes:
                position, rank = changes[-1]
                if rank + 1 < len(multi[position]):
                    step = multi[position][rank].log_weight - multi[position][rank + 1].log_weight
                    children.append((negative + step, (*changes[:-1], (position, rank + 1))))
            for position in range(changes[-1][0] + 1 if changes else 0, len(multi)):
                step = multi[position][0].log_weight - multi[position][1].log_weight
                children.append((negative + step, (*changes, (position, 1))))
            for weight, child in children:
                counter += 1
                heapq.heappush(heap, (weight, counter, child))
        return result

    @property
    def hypotheses(self) -> tuple[Hypothesis, ...]:
        """The global hypotheses (at most 10 000), best first. For inspection and tests;
        :meth:`top` is the way to ask for a few."""
        return tuple(self.top(10_000))
