"""The knowledge-driven Multiple Hypothesis Filter (paper 002 Section III, paper 000 III).

One call processes one scan (detections with the same source and time):

1. every stored object version is predicted to the scan time (lazily: from its
   own last update, batched per class filter);
2. ``mht``: every version's existence is carried to the scan time and every
   hypothesis weighted by its objects' missed-detection likelihoods
   (:mod:`semwm.mhf.existence`);
3. objects that became too uncertain (P_max, paper 002 III-E), went unseen too
   long (paper 000 C3), left the region or whose existence fell below
   ``removal_existence`` are removed from every hypothesis;
4. the scan's options are computed once (:mod:`semwm.mhf.association`);
5. detection by detection, every hypothesis is expanded into its children (eq. 1
   in log space): ``paper``: clutter, a new object, each gated existing object;
   ``mht``: "new object or clutter" (one child: an object with existence
   ``lambda_b / (lambda_b + lambda_c)``) and each gated existing object. The
   labeling rules of paper 000 III-B are applied, identical hypotheses merged and
   the tree pruned (eq. 3 and n_hyp,max);
6. object versions no hypothesis refers to are dropped.

The filter is pure: it returns a new :class:`MHFState` and never changes one.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import replace

import numpy as np

from semwm.filters.engine import Engine
from semwm.filters.factory import FilterFactory
from semwm.filters.motion import FloatArray
from semwm.filters.small import largest_eigenvalue
from semwm.knowledge.model import Knowledge
from semwm.knowledge.taxonomy import Taxonomy
from semwm.mhf.association import Associator, DetectionOptions, SettledUpdate
from semwm.mhf.core_engine import CoreEngine, as_python
from semwm.mhf.existence import looked_at, near_rate, region_margins
from semwm.mhf.kernels import existence_kernels
from semwm.mhf.measurement import Measurement, SensorView
from semwm.mhf.predict import Predicted, predict_tracks
from semwm.mhf.prune import TIE, log_add, merge, prune
from semwm.mhf.rates import MIN_EVIDENCE_SCANS, ObservedRates, ScanCoverage
from semwm.mhf.similar import merge_similar
from semwm.mhf.state import Cluster, Hypothesis, MHFState, StateView, Track

_NO_LIMITS = (math.inf, math.inf)


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
        self.existence: dict[int, float] = dict(state.existence)
        self.births: dict[tuple[int, float], Track] = {}
        self.born: set[int] = set()  # detections (their new track's key) that started one
        self.origin: dict[int, int] = {}  # new version -> the pre-scan version it derives from
        self._first_new = state.next_key  # keys below it existed before the scan
        self.derived: dict[int, list[int]] = {}
        self.copies: dict[int, int] = {}  # pre-scan version -> its copy without label

    def new_key(self) -> int:
        key = self.next_key
        self.next_key += 1
        return key

    def add(
        self,
        track: Track,
        origin: int | None = None,
        fresh: bool = False,
        existence: float = 1.0,
    ) -> None:
        self.tracks[track.key] = track
        self.existence[track.key] = existence
        if track.label is not None:
            self.by_label.setdefault(track.label, set()).add(track.key)
        if fresh:
            self.fresh.add(track.key)
        if origin is not None:
            self.origin[track.key] = origin
            self.derived.setdefault(origin, []).append(track.key)

    def origin_of(self, key: int) -> int | None:
        """The pre-scan version ``key`` derives from (itself if it is one), else None."""
        return key if key < self._first_new else self.origin.get(key)

    def unlabeled(self, key: int) -> int:
        """The version of ``key`` that gave its label up (paper 000 III-B: the older of two
        objects with one label gets a new unique label; its id serves as that label)."""
        done = self._unlabeled.get(key)
        if done is None:
            done = self.copy_unlabeled(key, self.new_key())
        return done

    def copy_unlabeled(self, key: int, copy_key: int) -> int:
        """Makes version ``copy_key`` of ``key`` without its label (:meth:`unlabeled`)."""
        copy = self.tracks[key].relabeled(copy_key, None)
        origin = self.origin_of(key)
        self.add(copy, origin, key in self.fresh, self.existence[key])
        self._unlabeled[key] = copy_key
        if key not in self.fresh and origin == key:
            self.copies[key] = copy_key
        return copy_key

    def add_birth(self, new_track: Track, key: int, existence: float) -> None:
        """Adds version ``key`` of the new object ``new_track`` (itself for its first
        version) with ``existence`` (:meth:`MultipleHypothesisFilter._birth`)."""
        born = new_track if key == new_track.key else new_track.relabeled(key, new_track.label)
        self.add(born, fresh=True, existence=existence)


class MultipleHypothesisFilter:
    """The MHF for one knowledge base."""

    def __init__(self, knowledge: Knowledge, engine: Engine = "python") -> None:
        self.knowledge = knowledge
        self.taxonomy = Taxonomy({name: c.parents for name, c in knowledge.classes.items()})
        self.factory = FilterFactory(knowledge, engine)
        # survive, missed, the region and view probabilities, coverage: one engine's
        self.kernels = existence_kernels(engine)
        self.associator = Associator(knowledge, self.factory, self.taxonomy)
        self.ratio = knowledge.world.pruning_ratio
        self.log_ratio = math.log(self.ratio) if self.ratio > 0.0 else -math.inf
        self.max_hypotheses = knowledge.world.max_hypotheses
        world = knowledge.world
        self.mht = world.association_model == "mht"
        # whether hypotheses factorise over clusters: true for ``mht``; the ``paper``
        # model's normaliser F sums over every object, so it keeps one global cluster
        self.factorised = self.associator.model == "mht"
        self.missed_detections = self.mht and world.missed_detection_term
        self.observed_rates = self.mht and world.observed_detection_rates
        self.merge_distance = world.merge_distance if self.mht else 0.0
        self.region = world.region
        # sqrt(chi2_1 quantile of gate_probability): a margin in standard deviations
        self._gate_quantile = float(
            region_margins(np.ones((1, 1, 1)), knowledge.world.gate_probability)[0, 0]
        )
        self._terms: dict[str, tuple[FloatArray, FloatArray]] = {}
        self._last_terms: tuple[tuple[Track, ...], FloatArray, FloatArray] | None = None
        # per class: (P_max, longest time unseen), infinite when the class sets none
        self._limits = {
            name: (
                math.inf if spec.max_position_variance is None else spec.max_position_variance,
                math.inf if spec.max_time_without_update is None else spec.max_time_without_update,
            )
            for name, spec in knowledge.classes.items()
        }
        self.removal_existence = world.removal_existence if self.mht else 0.0
        self._leave_relations = {
            name: tuple(
                (np.asarray(known.position, dtype=float), relation.max_distance, relation.frequency)
                for relation in spec.disappearance
                for known in knowledge.known_objects
                if known.cls in self.taxonomy.covers(relation.target)
            )
            for name, spec in knowledge.classes.items()
        }
        # the Rust engine runs the whole scan in the core (made last: it reads the above)
        self._core = CoreEngine(self) if self.kernels.engine == "rust" else None

    def predict(self, state: StateView, keys: Sequence[int], time: float) -> Predicted:
        return predict_tracks([state.tracks[k] for k in keys], time, self.factory)

    def leave_rates(self, predicted: Predicted) -> FloatArray:
        """Leave rates mu (Hz) of predicted objects (``mht``): the class's
        ``leave_frequency``, or a disappearance relation's rate near its target."""
        classes = self.knowledge.classes
        mu = np.array([classes[t.cls].leave_frequency for t in predicted.tracks], dtype=float)
        for i, t in enumerate(predicted.tracks):
            relations = self._leave_relations[t.cls]
            if relations:  # near a target it leaves by (paper 002 eq. 4, mirrored)
                mu[i] = near_rate(predicted.position[i], float(mu[i]), relations)
        return mu

    def miss_rates(
        self, observed: ObservedRates, predicted: Predicted, scan: ScanCoverage
    ) -> FloatArray:
        """Detection rates f (Hz) with which the scan ``scan`` misses each predicted object
        (``mht``, :meth:`ObservedRates.watched`): the rate of the scan's source
        (:meth:`ObservedRates.source_rates`; the class's ``detection_frequency`` without
        observed rates) for the objects it could have seen, times the probability that
        the object is inside the region; 0 for every other object."""
        tracks = predicted.tracks
        watched = observed.watched(
            scan,
            [t.sources for t in tracks],
            predicted.position,
            self.region_margins(tracks),
            _unconfirmed(tracks),
            self._spread(predicted),
            self.kernels.range_coverage,
            self.kernels.hull_distance,
        )
        if not watched.any():
            return np.zeros(len(tracks))
        f = self.class_rates(tracks)
        if self.observed_rates:
            f = observed.source_rates(
                scan.source, [t.lineage for t in tracks], f, [t.cls for t in tracks]
            )
        result: FloatArray = f * watched * self.inside(predicted)
        return result

    @staticmethod
    def _spread(predicted: Predicted) -> FloatArray:
        """``(N,)`` (m): each object's position standard deviation (its estimate's
        largest variance): how far from its estimate it may be."""
        P = predicted.position_covariance
        largest = P.diagonal(axis1=1, axis2=2).max(axis=1) if P.shape[0] else np.zeros(0)
        result: FloatArray = np.sqrt(np.maximum(largest, 0.0))
        return result

    def inside(self, predicted: Predicted) -> FloatArray:
        """Each predicted object's probability of being inside the region, widened by its
        class's measurement noise (:func:`semwm.mhf.existence.inside_probability`).

        For a class without P_max (``max_position_variance``) the spread that counts is
        the estimate's, at most the class's measurement noise per axis: the knowledge
        keeps such objects however uncertain, and an estimate that grows while nobody
        sees the object (a ball out of view) says where it may be, not that it left; it
        leaves when its mean crosses the edge. A class with P_max counts its whole
        spread: P_max removes the estimates grown too uncertain."""
        margins, noise = self._region_terms(predicted.tracks)
        return predicted.inside_region(self.region, margins, self.kernels.inside_probability, noise)

    def region_margins(self, tracks: Sequence[Track]) -> FloatArray:
        """``(N, d)``: each object's region margin (:func:`region_margins`), from its
        class's measurement noise for the default detector; zero for a class whose
        filter has a velocity (it leaves by crossing the edge) and for a class since
        removed."""
        return self._region_terms(tracks)[0]

    def _region_terms(self, tracks: Sequence[Track]) -> tuple[FloatArray, FloatArray]:
        """Per object, from its class's measurement noise (the default detector's):
        ``(N, d)`` its region margins (:meth:`region_margins`) and ``(N, d)`` the caps of
        its position variances for the region (:meth:`inside`: the noise variances, or
        infinite, no cap, for a class with P_max or since removed)."""
        dim = self.factory.dim
        if not tracks:
            return np.zeros((0, dim)), np.zeros((0, dim))
        last = self._last_terms  # a scan asks for one prediction's terms up to 3 times
        if last is not None and last[0] is tracks:
            return last[1], last[2]
        terms = self._terms
        rows = []
        for t in tracks:
            known = terms.get(t.cls)
            if known is None:
                known = terms[t.cls] = self._class_region_terms(t.cls)
            rows.append(known)
        margins = np.array([r[0] for r in rows])
        caps = np.array([r[1] for r in rows])
        if isinstance(tracks, tuple):  # immutable: the same tuple has the same terms
            self._last_terms = (tracks, margins, caps)
        return margins, caps

    def _class_region_terms(self, cls: str) -> tuple[FloatArray, FloatArray]:
        dim = self.factory.dim
        if cls not in self.knowledge.classes:
            return np.zeros(dim), np.full(dim, np.inf)
        R = self.factory.measurement_noise(cls, self.knowledge.default_detector)[:dim, :dim]
        noise = np.diagonal(R).astype(float)
        if self.knowledge.classes[cls].max_position_variance is not None:
            noise = np.full(dim, np.inf)  # its P_max removes what grew too uncertain
        # a class that moves (its filter has a velocity) crosses the region's edge by
        # entering and leaving; a static one sits on it (a table top on the region's
        # floor, a shelf on its wall): only its edge is soft
        if self.factory.filter_for(cls).state_size > dim:
            return np.zeros(dim), noise
        p = self.knowledge.world.gate_probability
        return region_margins(R[None], p)[0], noise

    def class_rates(self, tracks: Sequence[Track]) -> np.ndarray:
        """Each object's class ``detection_frequency`` (Hz)."""
        classes = self.knowledge.classes
        return np.array([classes[t.cls].detection_frequency for t in tracks], dtype=float)

    def existence_at(
        self,
        state: StateView,
        predicted: Predicted,
        time: float,
        scan: ScanCoverage | None = None,
    ) -> tuple[dict[int, float], dict[int, float]]:
        """Existence of every predicted version at ``time`` (>= ``state.time``), and the
        log missed-detection likelihood of each (docs/knowledge.md, "What semwm
        concludes from not seeing something").

        Objects leave at their leave rate over the time since ``state.time``
        (:func:`survive` with no detection rate: no evidence, ``q = 1``). Absence is
        evidence only from a scan that could have seen the object: with ``scan`` (a
        scan without a sensor view, made at ``time``), the objects its source could
        have seen (:meth:`miss_rates`) are missed at its rate over the time since the
        source's previous scan (:meth:`ObservedRates.miss_span`). Without ``scan`` (a
        query, or a scan whose sensor view decides, :func:`looked_at`) nothing is
        missed: silence and time alone are never a miss.
        """
        tracks = predicted.tracks
        keys = [t.key for t in tracks]
        r = np.array([state.existence.get(k, 1.0) for k in keys])
        if not self.mht or state.time is None or not tracks:
            return dict(zip(keys, r.tolist(), strict=True)), {}
        if time > state.time:
            mu = self.leave_rates(predicted)
            if mu.any():
                r, _ = self.kernels.survive(r, mu, np.zeros(len(keys)), time - state.time)
        log_q: dict[int, float] = {}
        if scan is not None and self.missed_detections:
            span = state.observed.miss_span(scan.source, time)
            if span > 0.0:
                f = self.miss_rates(state.observed, predicted, scan)
                if f.any():
                    r, q = self.kernels.survive(r, np.zeros(len(keys)), f, span)
                    log_q = dict(zip(keys, q.tolist(), strict=True))
        return dict(zip(keys, r.tolist(), strict=True)), log_q

    def leaving(
        self, predicted: Predicted, time: float, existence: Mapping[int, float] | None = None
    ) -> set[int]:
        """Keys of objects to remove from every hypothesis at ``time``: position covariance
        above the class's P_max (paper 002 III-E), unseen longer than its maximum (C3),
        and (``mht``) existence inside the region below ``removal_existence``."""
        gone: set[int] = set()
        tracks = predicted.tracks
        if not tracks:
            return gone
        classes = self.knowledge.classes
        drop = np.array([t.cls not in classes for t in tracks])  # a class since removed
        if self.mht and existence is not None:
            r = np.array([existence.get(t.key, 1.0) for t in tracks])
            drop |= r * self.inside(predicted) < self.removal_existence
        finite = np.all(np.isfinite(predicted.position_covariance), axis=(1, 2))
        drop |= ~finite
        covariance = np.where(finite[:, None, None], predicted.position_covariance, 0.0)
        limits = [self._limits.get(t.cls, _NO_LIMITS) for t in tracks]
        max_variance = np.array([limit[0] for limit in limits])
        max_unseen = np.array([limit[1] for limit in limits])
        last_seen = np.array([t.last_seen for t in tracks])
        drop |= largest_eigenvalue(covariance) > max_variance  # P_max, paper 002 III-E
        drop |= time - last_seen > max_unseen  # paper 000 C3
        for row in np.flatnonzero(drop).tolist():
            gone.add(tracks[row].key)
        return gone

    def process_scan(
        self,
        state: StateView,
        measurements: Sequence[Measurement],
        view: SensorView | None = None,
    ) -> StateView:
        """Process one scan: detections sharing a source and a time. With ``view`` (where
        the sensor looked) the scan may be empty, and objects in view that it does not
        report lose existence (:func:`semwm.mhf.existence.looked_at`).

        With the Rust engine the whole scan runs in the core
        (:mod:`semwm.mhf.core_engine`, ``core/src/mhf/filter.rs``), whose state stays
        there; this method is its specification."""
        if not measurements and view is None:
            return state
        if self._core is not None:
            return self._core.process_scan(state, measurements, view)
        state = as_python(state)
        time = measurements[0].time if measurements else view.time  # type: ignore[union-attr]
        keys = list(state.tracks)
        predicted = self.predict(state, keys, time)
        scan = self._coverage(measurements) if view is None and measurements else None
        existence, log_q = self.existence_at(state, predicted, time, scan)
        clusters: Sequence[Cluster] = state.clusters
        if log_q:
            clusters = self.undetected(clusters, log_q, state.tracks)
        state = replace(state, clusters=tuple(clusters), existence=existence)
        table = _TrackTable(state)
        gone = self.leaving(predicted, time, existence)
        if gone:
            clusters = self.without(clusters, gone, table.tracks)
            alive = [i for i, k in enumerate(keys) if k not in gone]
            predicted = predicted.subset(alive)
        settle = self._settleable(clusters) if view is None else None
        out_of_view: frozenset[int] = frozenset()  # lineages a view did not hold
        options = self.associator.options(
            predicted,
            measurements,
            table.new_key,
            [existence[t.key] for t in predicted.tracks],
            self._stream_rates(state.observed, predicted, measurements, time),
            settle,
            self.log_ratio,
        )
        if view is not None and self.mht:
            seen = {  # no SettledUpdate with a view (settle is None)
                k
                for option in options
                if isinstance(option, DetectionOptions)
                for k in option.existing
            }
            # an object the view's source has never reported, standing on the view's
            # edge, may be just outside it: the view eroded by its margin for it
            never = np.array([(view.source or "") not in t.sources for t in predicted.tracks])
            edges = never * np.minimum(
                self.region_margins(predicted.tracks).max(axis=1, initial=0.0),
                self._gate_quantile * self._spread(predicted),
            )
            r_view, log_q_view = looked_at(
                view,
                predicted,
                seen,
                table.existence,
                self.knowledge,
                self.kernels,
                self._view_detection(state.observed, view) if self.observed_rates else None,
                edges if edges.any() else None,  # things that stand still: the eroded view
            )
            table.existence.update(r_view)
            clusters = self.undetected(clusters, log_q_view, table.tracks)
            # an object the view did not hold had no chance to be detected again
            held = self.kernels.in_view_probability(
                predicted.position, predicted.position_covariance, view, None
            )
            out_of_view = frozenset(
                t.lineage for t, c in zip(predicted.tracks, held.tolist(), strict=True) if c < 0.5
            )
        final = self._expand_scan(clusters, options, table)
        if self.merge_distance > 0.0:
            untouched = {id(c) for c in clusters}
            final = self._merge_similar(final, table, untouched)
        # in key order: the order of the next scan's predicted rows, which orders the
        # keys its updates get (a set's order is CPython's hashing, no specification)
        referenced = sorted(set().union(*(c.keys for c in final)))
        tracks = {k: table.tracks[k] for k in referenced}
        kept = {k: table.existence.get(k, 1.0) for k in referenced}
        observed = state.observed
        if (self.observed_rates or self.missed_detections) and (measurements or view):
            observed = self._observe(
                observed,
                out_of_view,
                state.tracks,
                options,
                final,
                table,
                time,
                *self._scanner(measurements, view),
            )
        return MHFState(final, tracks, time, table.next_key, kept, observed)

    def _expand_scan(
        self,
        clusters: Sequence[Cluster],
        options: Sequence[DetectionOptions | SettledUpdate],
        table: _TrackTable,
    ) -> tuple[Cluster, ...]:
        """Step 5: the scan's clusters, detection by detection: the clusters a detection
        touches joined (:func:`_product`), expanded (:meth:`_expand`) and split
        (:meth:`_split`); settled and certain updates are bookkeeping (no hypothesis is
        built)."""
        book = _ClusterBook(clusters)
        for option in options:
            if isinstance(option, SettledUpdate):  # what _certain_update would give
                table.add(option.updated, origin=option.old_key, fresh=True)
                book.take(book.owners({option.old_key}))
                book.put((_certain(option.updated),))
                continue
            if not self.mht:
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
            certain = self._certain_update(book, touched, option, table)
            if certain is not None:
                book.take(touched)
                book.put((certain,))
                continue
            merged = _product(book.take(touched), self.ratio, self.max_hypotheses)
            expanded = self._expand(merged, option, table)
            book.put(self._split(expanded, table.tracks))
        return book.clusters()

    def _view_detection(self, observed: ObservedRates, view: SensorView) -> dict[str, float]:
        """Per class, the per-scan detection probability the view's stream is observed to
        have (prior: the class's ``detection_probability``), once it has expected
        :data:`~semwm.mhf.rates.MIN_EVIDENCE_SCANS` detections."""
        source = view.source or ""
        result = {}
        for (s, d, cls), counts in observed.streams.items():
            enough = counts.expected >= MIN_EVIDENCE_SCANS
            if s == source and d == view.detector and cls in self.knowledge.classes and enough:
                prior = self.knowledge.classes[cls].detection_probability
                result[cls] = counts.detection_probability(prior)
        return result

    def _coverage(self, measurements: Sequence[Measurement]) -> ScanCoverage:
        """What the scan (no sensor view) tells about where its source looked."""
        first = measurements[0]
        detectors = self.knowledge.detectors
        used = [detectors[d] for d in {m.detector for m in measurements}]
        ranges = [d.range for d in used]
        reach = (
            max(r for r in ranges if r is not None) if all(r is not None for r in ranges) else None
        )
        fixed = all(d.static for d in used)
        sensor = first.sensor
        if fixed and sensor is None and len(used) == 1 and used[0].position is not None:
            sensor = np.asarray(used[0].position, dtype=float)
        return ScanCoverage(
            first.source or "",
            np.array([m.z for m in measurements], dtype=float),
            sensor,
            reach,
            fixed,
        )

    def _settleable(self, clusters: Sequence[Cluster]) -> dict[int, float] | None:
        """Object key -> log weight of its cluster's only hypothesis, for the objects alone
        and certain in their cluster: the ones a detection can update for certain
        (:class:`SettledUpdate`). ``None`` where :meth:`_certain_update` never applies."""
        if not (self.mht and self.factorised and self.ratio > 0.0):
            return None
        return {
            next(iter(c.keys)): c.hypotheses[0].log_weight
            for c in clusters
            if len(c.hypotheses) == 1 and len(c.keys) == 1
        }

    def _merge_similar(
        self, clusters: Sequence[Cluster], table: _TrackTable, untouched: set[int]
    ) -> tuple[Cluster, ...]:
        """Clusters with hypotheses that differ only in near-identical versions of their
        objects merged (:mod:`semwm.mhf.similar`); clusters no detection of the scan
        touched (``id`` in ``untouched``) were merged when they last changed."""
        result = []
        for cluster in clusters:
            if len(cluster.hypotheses) > 1 and id(cluster) not in untouched:
                merged = merge_similar(
                    cluster.hypotheses, table.tracks, table.existence, self.merge_distance
                )
                if len(merged) < len(cluster.hypotheses):
                    cluster = Cluster.of(merged)
            result.append(cluster)
        return tuple(result)

    def _stream_rates(
        self,
        observed: ObservedRates,
        predicted: Predicted,
        measurements: Sequence[Measurement],
        time: float,
    ) -> dict[str, np.ndarray] | None:
        """Per detector of the scan, each predicted object's rate in the association
        weight of its detections (:meth:`ObservedRates.from_stream`)."""
        if not self.observed_rates or not measurements or not predicted.tracks:
            return None
        source = measurements[0].source or ""
        lineages = [t.lineage for t in predicted.tracks]
        base = self.class_rates(predicted.tracks)
        classes = [t.cls for t in predicted.tracks]
        unconfirmed = _unconfirmed(predicted.tracks)
        return {
            detector: observed.from_stream(
                (source, detector), lineages, base, time, classes, unconfirmed
            )
            for detector in {m.detector for m in measurements}
        }

    @staticmethod
    def _observe(
        observed: ObservedRates,
        out_of_view: frozenset[int],
        before: Mapping[int, Track],
        options: Sequence[DetectionOptions | SettledUpdate],
        final: Sequence[Cluster],
        table: _TrackTable,
        time: float,
        source: str,
        scanned: frozenset[str],
    ) -> ObservedRates:
        """The observed rates after the scan of ``source`` by the detectors ``scanned``:
        per detector, which objects its detections updated or started in the most
        probable hypothesis (:mod:`semwm.mhf.rates`), and which it started in the others
        (they see those too, but do not count them)."""
        detector_of: dict[int, str] = {}
        for option in options:
            detector = option.measurement.detector
            if isinstance(option, SettledUpdate):  # it started no object
                detector_of.setdefault(before[option.old_key].lineage, detector)
                continue
            detector_of.setdefault(option.new_track.lineage, detector)
            for old_key in option.existing:
                detector_of.setdefault(before[old_key].lineage, detector)
        existed = {t.lineage for t in before.values()}
        detected: dict[str, list[int]] = {}
        born: dict[str, list[int]] = {}
        born_elsewhere: dict[str, list[int]] = {}
        alive: set[int] = set()
        classes: dict[int, str] = {}
        for cluster in final:
            for key in cluster.keys:
                alive.add(table.tracks[key].lineage)
            best = cluster.hypotheses[0].tracks
            for key in best & table.fresh:
                lineage = table.tracks[key].lineage
                by = detector_of.get(lineage)
                if by is not None:
                    target = detected if lineage in existed else born
                    target.setdefault(by, []).append(lineage)
                    classes[lineage] = table.tracks[key].cls
            for key in (cluster.keys - best) & table.fresh:
                lineage = table.tracks[key].lineage
                by = detector_of.get(lineage)
                if by is not None and lineage not in existed:
                    born_elsewhere.setdefault(by, []).append(lineage)
        first = options[0].measurement if options else None
        sensor = None if first is None or first.sensor is None else tuple(first.sensor.tolist())
        return observed.after_scan(
            source,
            time,
            detected,
            born,
            alive,
            sensor,
            classes,
            born_elsewhere,
            scanned,
            out_of_view,
        )

    def _scanner(
        self, measurements: Sequence[Measurement], view: SensorView | None
    ) -> tuple[str, frozenset[str]]:
        """The scan's source and the detectors that made it; an empty scan with a view
        looked with the view's detector (the default one if it names none) and saw
        nothing: its misses count too."""
        if measurements:
            return measurements[0].source or "", frozenset(m.detector for m in measurements)
        assert view is not None
        return view.source or "", frozenset({view.detector or self.knowledge.default_detector})

    def undetected(
        self,
        clusters: Sequence[Cluster],
        log_q: Mapping[int, float],
        tracks: Mapping[int, Track],
    ) -> tuple[Cluster, ...]:
        r"""Weight every hypothesis by the missed-detection likelihoods of its objects.

        .. math:: p(h \mid \text{no detection}) \propto p(h) \prod_{o \in h} q_o

        with :math:`q_o` from :func:`semwm.mhf.existence.survive`. A cluster with one
        hypothesis is unchanged (normalised on its own).
        """
        result = []
        for cluster in clusters:
            if len(cluster.hypotheses) == 1:
                result.append(cluster)
                continue
            hypotheses = prune(
                merge(
                    (h.tracks, h.log_weight + math.fsum(log_q[k] for k in h.tracks), h.rate)
                    for h in cluster.hypotheses
                ),
                self.ratio,
                self.max_hypotheses,
            )
            if len(hypotheses) == len(cluster.hypotheses) and not _common(hypotheses):
                result.append(Cluster(hypotheses, cluster.keys))  # the same objects
            else:
                result.extend(self._split(hypotheses, tracks))
        return tuple(result)

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
        certain and become clusters of their own (in key order); a cluster whose only
        hypothesis is empty carries nothing and is dropped."""
        if not self.factorised:
            if len(hypotheses) == 1 and not hypotheses[0].tracks:
                return []
            return [Cluster.of(tuple(hypotheses))]
        common = frozenset.intersection(*(h.tracks for h in hypotheses))
        result = [
            Cluster((Hypothesis(0.0, frozenset({k}), tracks[k].rate),), frozenset({k}))
            for k in sorted(common)
        ]
        if len(hypotheses) > 1 and not common:  # nothing to split off
            result.append(Cluster.of(tuple(hypotheses)))
        elif len(hypotheses) > 1:
            common_rate = sum(tracks[k].rate for k in sorted(common))
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
        pruned. A hypothesis's objects are visited in key order, so that the children's
        order (which orders hypotheses of equal weight) and the keys of label copies do
        not depend on how Python hashes a set."""
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
        holders = table.by_label.setdefault(label, set()) if label is not None else set()
        log_clutter = option.log_clutter
        log_or_clutter = log_add(log_clutter, option.new_log)  # the usual "new or clutter"
        floor = self._update_floor(hypotheses, option, bool(copies))
        born_at: dict[float, int] = {}  # birth weight -> the version born (mht)
        for h in hypotheses:
            tracks = h.tracks
            birth_rate, birth_log = option.new_rate, option.new_log
            if presence:
                for k in sorted(presence_keys & tracks):
                    rate, log_num = presence[k]
                    if log_num > birth_log:
                        birth_rate, birth_log = rate, log_num
            log_norm = h.log_weight
            if per_parent:
                # paper 002 eqs. (5)-(7): F sums the frequencies open to this detection;
                # objects that took a detection of this scan cannot take another
                taken = tracks & fresh
                open_rate = (
                    h.rate - sum(table.tracks[k].rate for k in sorted(taken)) if taken else h.rate
                )
                log_norm -= math.log(option.clutter_rate + birth_rate + open_rate)
            labelled = label is not None and not holders.isdisjoint(tracks)
            if self.mht:
                # one child "new object or clutter": an object with existence
                # lambda_b / (lambda_b + lambda_c), weight lambda_b + lambda_c
                log_unassigned = (
                    log_or_clutter
                    if birth_log == option.new_log
                    else log_add(log_clutter, birth_log)
                )
                if labelled:
                    log_unassigned += self.associator.log_label_error
                if birth_log > -math.inf:
                    born = born_at.get(birth_log)
                    if born is None:
                        born = born_at[birth_log] = self._birth(option, birth_log, table)
                    child = tracks | {born}
                    if labelled:
                        child = _give_label(child, born, holders, table)
                    children.append((child, log_norm + log_unassigned, h.rate + new_rate))
                elif log_unassigned > -math.inf:
                    children.append((tracks, log_norm + log_unassigned, h.rate))
            else:
                if log_clutter > -math.inf:
                    children.append((tracks, log_norm + log_clutter, h.rate))
                if birth_log > -math.inf:
                    child = tracks | {new_key}
                    if labelled:
                        child = _give_label(child, new_key, holders, table)
                    children.append((child, log_norm + birth_log, h.rate + new_rate))
            for k in sorted(existing_keys & tracks):
                updated, log_num, rate_change = existing[k]
                if self.mht and labelled and k not in holders and table.tracks[k].label is None:
                    # an unlabelled object takes the label from its holder: another
                    # explanation than the holder, it pays the label error too (the
                    # associator charges objects holding a different label)
                    log_num += self.associator.log_label_error
                if log_norm + log_num < floor:
                    continue  # pruned by eq. (3) whatever else is built: no set made
                child = (tracks - {k}) | {updated.key}
                if labelled:
                    child = _give_label(child, updated.key, holders, table)
                children.append((child, log_norm + log_num, h.rate + rate_change))
            if copies:
                for k in sorted(copy_keys & tracks):
                    updated, log_num, rate_change = existing[copies[k]]
                    holder = updated.key if label is not None else table.unlabeled(updated.key)
                    child = (tracks - {k}) | {holder}
                    if label is not None:
                        child = _give_label(child, holder, holders, table)
                    children.append((child, log_norm + log_num, h.rate + rate_change))
        if not children:  # nothing can explain it: a knowledge base with no clutter or births
            return tuple(hypotheses)
        return prune(merge(children), self.ratio, self.max_hypotheses)

    def _update_floor(
        self, hypotheses: Sequence[Hypothesis], option: DetectionOptions, copies: bool
    ) -> float:
        """A log weight under which an update child of :meth:`_expand` is pruned by eq.
        (3) whatever else is built, known before any child is: alpha times a lower bound
        of the best child's weight (any parent's best update, or the clutter part of its
        "new object or clutter" child). ``-inf`` where skipping could change a result:
        only ``mht`` children with no label and no label copies are each a set of objects
        no other child holds, so a child under the floor has nothing to merge with."""
        if (
            not self.mht
            or self.ratio <= 0.0
            or copies
            or option.measurement.label is not None
            or not hypotheses
        ):
            return -math.inf
        parent = hypotheses[0]
        best = option.log_clutter
        existing = option.existing
        for k in existing.keys() & parent.tracks:
            best = max(best, existing[k][1])
        return parent.log_weight + best + self.log_ratio - TIE

    def _certain_update(
        self, book: _ClusterBook, touched: set[int], option: DetectionOptions, table: _TrackTable
    ) -> Cluster | None:
        """The cluster :meth:`_expand` and :meth:`_split` would give, computed directly in
        the most common case (``mht``): the detection gates exactly one object, which is
        alone and certain in its cluster, and "new object or clutter" falls below eq.
        (3)'s floor against the update. Then the only child is the updated object, with
        probability 1. ``None`` in every other case (the general path decides)."""
        if not self.mht or self.ratio <= 0.0 or len(touched) != 1 or len(option.existing) != 1:
            return None
        if option.presence or option.measurement.label is not None:
            return None
        cluster = book.get(next(iter(touched)))
        if len(cluster.hypotheses) != 1 or len(cluster.keys) != 1:
            return None
        ((old_key, (updated, log_num, _)),) = option.existing.items()
        if old_key not in cluster.keys or old_key in table.copies:
            return None
        log_norm = cluster.hypotheses[0].log_weight
        log_update = log_norm + log_num
        if log_update == -math.inf:
            return None
        log_unassigned = log_norm + log_add(option.log_clutter, option.new_log)
        if log_unassigned >= log_update + math.log(self.ratio) - TIE:
            return None  # both children are kept: the general path
        return _certain(updated)

    def _birth(self, option: DetectionOptions, birth_log: float, table: _TrackTable) -> int:
        """The version a detection starts with birth weight ``birth_log`` (``mht``): its
        existence is ``lambda_b / (lambda_b + lambda_c)``. Hypotheses whose objects make
        a birth likelier (eq. 4) start a version of their own."""
        born = table.births.get((option.new_track.key, birth_log))
        if born is None:
            log_total = log_add(option.log_clutter, birth_log)
            first = option.new_track.key not in table.born
            born = (
                option.new_track
                if first
                else option.new_track.relabeled(table.new_key(), option.new_track.label)
            )
            table.add(born, fresh=True, existence=math.exp(birth_log - log_total))
            table.births[(option.new_track.key, birth_log)] = born
            table.born.add(option.new_track.key)
        return born.key


def _certain(track: Track) -> Cluster:
    """A cluster holding ``track`` for certain: one hypothesis, probability 1."""
    key = track.key
    return Cluster((Hypothesis(0.0, frozenset({key}), track.rate),), frozenset({key}))


class _ClusterBook:
    """The scan's working set of clusters and which cluster holds each object version."""

    def __init__(self, clusters: Sequence[Cluster]) -> None:
        self._clusters: dict[int, Cluster] = dict(enumerate(clusters))
        self._owner = {k: i for i, c in self._clusters.items() for k in c.keys}
        self._next = len(self._clusters)

    def ids(self) -> set[int]:
        return set(self._clusters)

    @property
    def next_id(self) -> int:
        """The id the next cluster put gets (every id so far is below it)."""
        return self._next

    def get(self, cluster_id: int) -> Cluster:
        return self._clusters[cluster_id]

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
        # combinations below eq. (3)'s floor are pruned: skip them before building their
        # sets (the clusters hold disjoint objects, so no two combinations merge)
        best = max(a.log_weight for a in result) + max(b.log_weight for b in hypotheses)
        floor = best + math.log(ratio) - TIE if ratio > 0.0 else -math.inf
        result = prune(
            merge(
                (a.tracks | b.tracks, a.log_weight + b.log_weight, a.rate + b.rate)
                for a in result
                for b in hypotheses
                if a.log_weight + b.log_weight >= floor
            ),
            ratio,
            max_hypotheses,
        )
    return result


def _common(hypotheses: Sequence[Hypothesis]) -> bool:
    """Whether some object is held by every hypothesis (the cluster splits)."""
    first, *others = hypotheses
    common = set(first.tracks)
    for h in others:
        common &= h.tracks
        if not common:
            return False
    return bool(common)


def _give_label(
    child: frozenset[int], holder: int, holders: set[int], table: _TrackTable
) -> frozenset[int]:
    """Paper 000 III-B: the object that took the labeled detection holds the label; any
    other object of the hypothesis with that label (``holders``: every version holding
    it) gives it up (in key order: the order their copies get keys)."""
    others = (holders & child) - {holder}
    if not others:
        return child
    return (child - others) | {table.unlabeled(k) for k in sorted(others)}


def _without(
    hypotheses: Sequence[Hypothesis], gone: set[int], tracks: Mapping[int, Track]
) -> tuple[Hypothesis, ...]:
    """Remove objects from every hypothesis; hypotheses that become identical merge."""
    children = []
    for h in hypotheses:
        removed = h.tracks & gone
        if removed:
            rate = h.rate - sum(tracks[k].rate for k in sorted(removed))
            children.append((h.tracks - removed, h.log_weight, rate))
        else:
            children.append((h.tracks, h.log_weight, h.rate))
    return prune(merge(children), 0.0, len(children))


def _unconfirmed(tracks: Sequence[Track]) -> list[bool]:
    """Per version: no detection since the one that started it."""
    return [t.last_seen <= t.created for t in tracks]
