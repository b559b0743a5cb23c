"""The knowledge-driven Multiple Hypothesis Filter (paper 002 Section III, paper 000 III).

One call processes one scan (detections with the same source and time):

1. every stored object version is predicted to the scan time (lazily: from its
   own last update, batched per class filter);
2. objects that became too uncertain (P_max, paper 002 III-E) or went unseen too
   long (paper 000 C3) are removed from every hypothesis;
3. the scan's options are computed once (:mod:`semwm.mhf.association`);
4. detection by detection, every hypothesis is expanded into clutter, a new
   object, and each gated existing object it holds (eq. 1 in log space), the
   labeling rules of paper 000 III-B are applied, identical hypotheses merged and
   the tree pruned (eq. 3 and n_hyp,max);
5. object versions no hypothesis refers to are dropped.

The filter is pure: it returns a new :class:`MHFState` and never changes one.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

import numpy as np

from semwm.filters.factory import FilterFactory
from semwm.knowledge.model import Knowledge
from semwm.knowledge.taxonomy import Taxonomy
from semwm.mhf.association import Associator, DetectionOptions
from semwm.mhf.measurement import Measurement
from semwm.mhf.predict import Predicted, predict_tracks
from semwm.mhf.prune import merge, prune
from semwm.mhf.state import Cluster, Hypothesis, MHFState, Track


class _TrackTable:
    """The scan's working track table: new versions get keys here.

    It also remembers, for the scan, which versions *took* a detection of it
    (``fresh``: new objects and updated versions; they cannot take another one) and
    which versions *derive* from a version that existed before the scan (updates,
    and copies that gave a label up), so that eq. (4) and later detections of the
    scan see an object under whichever version a hypothesis holds.
    """

    def __init__(self, state: MHFState) -> None:
        self.tracks: dict[int, Track] = dict(state.tracks)
        self.next_key = state.next_key
        self.by_label: dict[str, set[int]] = {}
        for track in self.tracks.values():
            if track.label is not None:
                self.by_label.setdefault(track.label, set()).add(track.key)
        self._unlabeled: dict[int, int] = {}
        self.fresh: set[int] = set()
        self.origin: dict[int, int] = {key: key for key in self.tracks}
        self.derived: dict[int, list[int]] = {}
        self.copies: dict[int, int] = {}  # pre-scan version -> its copy without label

    def new_key(self) -> int:
        key = self.next_key
        self.next_key += 1
        return key

    def add(self, track: Track, origin: int | None = None, fresh: bool = False) -> None:
        self.tracks[track.key] = track
        if track.label is not None:
            self.by_label.setdefault(track.label, set()).add(track.key)
        if fresh:
            self.fresh.add(track.key)
        if origin is not None:
            self.origin[track.key] = origin
            self.derived.setdefault(origin, []).append(track.key)

    def unlabeled(self, key: int) -> int:
        """The version of ``key`` that gave its label up (paper 000 III-B: the older of two
        objects with one label gets a new unique label; its id serves as that label)."""
        done = self._unlabeled.get(key)
        if done is None:
            copy = self.tracks[key].relabeled(self.new_key(), None)
            self.add(copy, self.origin.get(key), fresh=key in self.fresh)
            done = self._unlabeled[key] = copy.key
            if key not in self.fresh and self.origin.get(key) == key:
                self.copies[key] = copy.key
        return done


class MultipleHypothesisFilter:
    """The MHF for one knowledge base."""

    def __init__(self, knowledge: Knowledge) -> None:
        self.knowledge = knowledge
        self.taxonomy = Taxonomy({name: c.parents for name, c in knowledge.classes.items()})
        self.factory = FilterFactory(knowledge)
        self.associator = Associator(knowledge, self.factory, self.taxonomy)
        self.ratio = knowledge.world.pruning_ratio
        self.max_hypotheses = knowledge.world.max_hypotheses
        world = knowledge.world
        self.missed_detections = world.association_model == "mht" and world.missed_detection_term

    def predict(self, state: MHFState, keys: Sequence[int], time: float) -> Predicted:
        return predict_tracks([state.tracks[k] for k in keys], time, self.factory)

    def leaving(self, predicted: Predicted, time: float) -> set[int]:
        """Keys of objects to remove from every hypothesis at ``time``: position covariance
        above the class's P_max (paper 002 III-E) or unseen longer than its maximum (C3)."""
        gone: set[int] = set()
        if not predicted.tracks:
            return gone
        largest = np.linalg.eigvalsh(predicted.position_covariance)[:, -1]
        classes = self.knowledge.classes
        for i, track in enumerate(predicted.tracks):
            spec = classes.get(track.cls)
            if spec is None:
                gone.add(track.key)
                continue
            if (
                spec.max_position_variance is not None and largest[i] > spec.max_position_variance
            ) or (
                spec.max_time_without_update is not None
                and time - track.last_seen > spec.max_time_without_update
            ):
                gone.add(track.key)
        return gone

    def process_scan(self, state: MHFState, measurements: Sequence[Measurement]) -> MHFState:
        """Process one scan: detections sharing a source and a time."""
        if not measurements:
            return state
        time = measurements[0].time
        table = _TrackTable(state)
        keys = list(state.tracks)
        predicted = self.predict(state, keys, time)
        gone = self.leaving(predicted, time)
        clusters: Sequence[Cluster] = state.clusters
        if gone:
            clusters = self.without(clusters, gone, table.tracks)
            alive = [i for i, k in enumerate(keys) if k not in gone]
            predicted = _subset(predicted, alive)
        if self.missed_detections and state.time is not None and time > state.time:
            clusters = self._undetected(clusters, time - state.time, table.tracks)
        options = self.associator.options(predicted, measurements, table.new_key)
        book = _ClusterBook(clusters)
        for option in options:
            table.add(option.new_track, fresh=True)
            for old_key, (updated, _, _) in option.existing.items():
                table.add(updated, origin=old_key, fresh=True)
            if self.factorised:
                involved = set(option.existing) | set(option.presence)
                if option.measurement.label is not None:
                    involved |= table.by_label.get(option.measurement.label, set())
                touched = book.owners(involved)
            else:
                touched = book.ids()
            merged = _product(book.take(touched), self.ratio, self.max_hypotheses)
            expanded = self._expand(merged, option, table)
            book.put(self._split(expanded, table.tracks))
        final = book.clusters()
        referenced: set[int] = set().union(*(c.keys for c in final))
        tracks = {k: table.tracks[k] for k in referenced}
        return MHFState(final, tracks, time, table.next_key)

    def _undetected(
        self, clusters: Sequence[Cluster], elapsed: float, tracks: Mapping[int, Track]
    ) -> tuple[Cluster, ...]:
        r"""The ``mht`` model's missed-detection term: objects detected at rates f_e (Hz) that
        produced no detection for ``elapsed`` seconds.

        .. math:: p(\text{no detection in } \Delta t \mid h) = \exp(-\Delta t \sum_{o \in h} f_e(o))

        Clutter and birth rates are the same in every hypothesis and cancel; this term
        is what makes a hypothesis with a duplicate or an unconfirmed object less
        probable while it is not seen. It factorises over clusters.
        """
        result = []
        for cluster in clusters:
            if len(cluster.hypotheses) == 1:
                result.append(cluster)
                continue
            hypotheses = prune(
                merge(
                    (h.tracks, h.log_weight - elapsed * h.rate, h.rate) for h in cluster.hypotheses
                ),
                self.ratio,
                self.max_hypotheses,
            )
            result.extend(self._split(hypotheses, tracks))
        return tuple(result)

    @property
    def factorised(self) -> bool:
        """Whether hypotheses factorise over clusters: true for ``mht``; the ``paper``
        model's normaliser F sums over every object, so it keeps one global cluster."""
        return self.associator.model == "mht"

    def without(
        self, clusters: Sequence[Cluster], gone: set[int], tracks: Mapping[int, Track]
    ) -> tuple[Cluster, ...]:
        """Remove objects from every hypothesis; hypotheses that become identical merge."""
        result: list[Cluster] = []
        for cluster in clusters:
            if cluster.keys & gone:
                result.extend(self._split(_without(cluster.hypotheses, gone, tracks), tracks))
            else:
                result.append(cluster)
        return tuple(result)

    def _split(
        self, hypotheses: Sequence[Hypothesis], tracks: Mapping[int, Track]
    ) -> list[Cluster]:
        """Split a cluster: objects held (in the same version) by every hypothesis are
        certain and become clusters of their own; a cluster whose only hypothesis is
        empty carries nothing and is dropped."""
        if not self.factorised:
            if len(hypotheses) == 1 and not hypotheses[0].tracks:
                return []
            return [Cluster.of(tuple(hypotheses))]
        common = frozenset.intersection(*(h.tracks for h in hypotheses))
        result = [
            Cluster((Hypothesis(0.0, frozenset({k}), tracks[k].rate),), frozenset({k}))
            for k in common
        ]
        if len(hypotheses) > 1:
            common_rate = sum(tracks[k].rate for k in common)
            rest = prune(
                merge((h.tracks - common, h.log_weight, h.rate - common_rate) for h in hypotheses),
                0.0,
                len(hypotheses),
            )
            if len(rest) > 1 or rest[0].tracks:
                result.append(Cluster.of(rest))
        return result

    def _expand(
        self, hypotheses: Sequence[Hypothesis], option: DetectionOptions, table: _TrackTable
    ) -> tuple[Hypothesis, ...]:
        """Children of every hypothesis for one detection (eq. 1 with eqs. 4-8), merged and
        pruned."""
        children: list[tuple[frozenset[int], float, float]] = []
        new_key = option.new_track.key
        new_rate = option.new_track.rate
        label = option.measurement.label
        per_parent = self.associator.model == "paper"
        # eq. (4): an object counts under any version a hypothesis holds of it
        presence = dict(option.presence)
        for key, value in option.presence.items():
            for version in table.derived.get(key, ()):
                presence[version] = value
        presence_keys = presence.keys()
        existing = option.existing
        existing_keys = existing.keys()
        # objects that gave their label up earlier in the scan may still take this one
        copies = {table.copies[k]: k for k in existing if k in table.copies}
        copy_keys = copies.keys()
        fresh = table.fresh
        for h in hypotheses:
            tracks = h.tracks
            birth_rate, birth_log = option.new_rate, option.new_log
            for k in presence_keys & tracks:
                rate, log_num = presence[k]
                if log_num > birth_log:
                    birth_rate, birth_log = rate, log_num
            log_norm = h.log_weight
            if per_parent:
                # paper 002 eqs. (5)-(7): F sums the frequencies open to this detection;
                # objects that took a detection of this scan cannot take another
                taken = tracks & fresh
                open_rate = h.rate - sum(table.tracks[k].rate for k in taken) if taken else h.rate
                log_norm -= math.log(option.clutter_rate + birth_rate + open_rate)
            if option.log_clutter > -math.inf:
                children.append((tracks, log_norm + option.log_clutter, h.rate))
            if birth_log > -math.inf:
                child = tracks | {new_key}
                if label is not None:
                    child = _give_label(child, new_key, label, table)
                children.append((child, log_norm + birth_log, h.rate + new_rate))
            for k in existing_keys & tracks:
                updated, log_num, rate_change = existing[k]
                child = (tracks - {k}) | {updated.key}
                if label is not None:
                    child = _give_label(child, updated.key, label, table)
                children.append((child, log_norm + log_num, h.rate + rate_change))
            for k in copy_keys & tracks:
                updated, log_num, rate_change = existing[copies[k]]
                holder = updated.key if label is not None else table.unlabeled(updated.key)
                child = (tracks - {k}) | {holder}
                if label is not None:
                    child = _give_label(child, holder, label, table)
                children.append((child, log_norm + log_num, h.rate + rate_change))
        if not children:  # nothing can explain it: a knowledge base with no clutter or births
            return tuple(hypotheses)
        return prune(merge(children), self.ratio, self.max_hypotheses)


class _ClusterBook:
    """The scan's working set of clusters and which cluster holds each object version."""

    def __init__(self, clusters: Sequence[Cluster]) -> None:
        self._clusters: dict[int, Cluster] = dict(enumerate(clusters))
        self._owner = {k: i for i, c in self._clusters.items() for k in c.keys}
        self._next = len(self._clusters)

    def ids(self) -> set[int]:
        return set(self._clusters)

    def owners(self, keys: set[int]) -> set[int]:
        owner = self._owner
        return {owner[k] for k in keys if k in owner}

    def take(self, ids: set[int]) -> list[tuple[Hypothesis, ...]]:
        taken = []
        for i in sorted(ids):
            cluster = self._clusters.pop(i)
            for k in cluster.keys:
                del self._owner[k]
            taken.append(cluster.hypotheses)
        return taken

    def put(self, clusters: Sequence[Cluster]) -> None:
        for cluster in clusters:
            self._clusters[self._next] = cluster
            for k in cluster.keys:
                self._owner[k] = self._next
            self._next += 1

    def clusters(self) -> tuple[Cluster, ...]:
        return tuple(self._clusters.values())


def _product(
    groups: Sequence[tuple[Hypothesis, ...]], ratio: float, max_hypotheses: int
) -> tuple[Hypothesis, ...]:
    """Join clusters: every combination of one hypothesis from each, weights multiplied,
    pruned as the tree is (eq. 3, n_hyp,max)."""
    if not groups:
        return (Hypothesis(0.0, frozenset(), 0.0),)
    result = groups[0]
    for hypotheses in groups[1:]:
        result = prune(
            merge(
                (a.tracks | b.tracks, a.log_weight + b.log_weight, a.rate + b.rate)
                for a in result
                for b in hypotheses
            ),
            ratio,
            max_hypotheses,
        )
    return result


def _give_label(
    child: frozenset[int], holder: int, label: str, table: _TrackTable
) -> frozenset[int]:
    """Paper 000 III-B: the object that took the labeled detection holds the label; any
    other object of the hypothesis with that label gives it up."""
    others = (table.by_label.get(label, set()) & child) - {holder}
    if not others:
        return child
    return (child - others) | {table.unlabeled(k) for k in others}


def _without(
    hypotheses: Sequence[Hypothesis], gone: set[int], tracks: Mapping[int, Track]
) -> tuple[Hypothesis, ...]:
    """Remove objects from every hypothesis; hypotheses that become identical merge."""
    children = []
    for h in hypotheses:
        removed = h.tracks & gone
        if removed:
            rate = h.rate - sum(tracks[k].rate for k in removed)
            children.append((h.tracks - removed, h.log_weight, rate))
        else:
            children.append((h.tracks, h.log_weight, h.rate))
    return prune(merge(children), 0.0, len(children))


def _subset(predicted: Predicted, rows: list[int]) -> Predicted:
    return Predicted(
        tuple(predicted.tracks[i] for i in rows),
        [predicted.x[i] for i in rows],
        [predicted.P[i] for i in rows],
        [predicted.mu[i] for i in rows],
        [predicted.state_mean[i] for i in rows],
        predicted.position[rows],
        predicted.position_covariance[rows],
    )
