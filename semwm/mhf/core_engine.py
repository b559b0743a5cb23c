"""The Rust engine's whole scan: the knowledge's tables handed to the core once, and the
filter's state kept in the core between scans (``core/src/mhf/filter.rs``).

:func:`tables` computes every number the core reads with the Python engine's own code
(the same :class:`~semwm.mhf.filter.MultipleHypothesisFilter`, its ``Associator`` and
``ClassModel``), so the two engines start from the same numbers. :class:`CoreEngine`
runs a scan in one call; the state it returns, :class:`CoreState`, stays in the core
and offers :class:`~semwm.mhf.state.MHFState`'s interface: its clusters and versions
become Python values only when read (for publishing, queries and tests), and those
already made for an earlier state are reused (a version and a cluster are immutable).
"""

from __future__ import annotations

import math
from collections.abc import Iterator, Mapping, Sequence
from typing import TYPE_CHECKING, Any, NamedTuple

import numpy as np

from semwm.confidence import BookView, ConfidenceBook, carried
from semwm.filters import rust
from semwm.mhf.measurement import Measurement, SensorView
from semwm.mhf.rates import FalseAlarms, ObservedRates, SourceClock, StreamCounts
from semwm.mhf.state import Cluster, Hypothesis, MHFState, StateView, Track

if TYPE_CHECKING:
    from semwm import _core
    from semwm.knowledge.model import ResolvedClass
    from semwm.mhf.filter import MultipleHypothesisFilter


def tables(mhf: MultipleHypothesisFilter) -> dict[str, Any]:
    """The knowledge's numeric tables as the core reads them
    (``core/src/mhf/tables.rs``), from ``mhf``'s own computations."""
    knowledge = mhf.knowledge
    associator = mhf.associator
    model = associator.class_model
    taxonomy = mhf.taxonomy
    names = model.names
    classes = []
    for name in names:
        spec = knowledge.classes[name]
        flt = mhf.factory.filter_for(name)
        margin, cap = mhf._class_region_terms(name)
        limits = mhf._limits[name]
        appearance = []
        for relation in spec.appearance:
            covered = taxonomy.covers(relation.target)
            log_frequency = math.log(relation.frequency) if relation.frequency > 0 else -math.inf
            appearance.append(
                {
                    "covered": [other in covered for other in names],
                    "frequency": float(relation.frequency),
                    "max_distance": float(relation.max_distance),
                    "log_num": log_frequency + associator._spread(relation.max_distance),
                    "known": [
                        [float(v) for v in known.position]
                        for known in knowledge.known_objects
                        if known.cls in covered
                    ],
                }
            )
        classes.append(
            {
                "name": name,
                "filter": rust.class_filter(flt),
                "initial_covariance": flt.initial_covariance.ravel().tolist(),
                "initial_mode_probabilities": flt.initial_mode_probabilities.tolist(),
                # what a query shows (WorldModel._world_object), not the filter's tables
                "mode_names": list(flt.mode_names) if flt.modes > 1 else None,
                "detection_frequency": float(spec.detection_frequency),
                "detection_probability": float(spec.detection_probability),
                "leave_frequency": float(spec.leave_frequency),
                "new_frequency": float(spec.new_frequency),
                "max_position_variance": float(limits[0]),
                "max_time_without_update": float(limits[1]),
                "region_margin": np.asarray(margin, dtype=float).tolist(),
                "region_cap": np.asarray(cap, dtype=float).tolist(),
                "leave_relations": [
                    {
                        "target": np.asarray(target, dtype=float).tolist(),
                        "max_distance": float(reach),
                        "frequency": float(rate),
                    }
                    for target, reach, rate in mhf._leave_relations[name]
                ],
                "appearance": appearance,
                "can_appear": bool(spec.new_frequency > 0.0 or spec.appearance),
                "kick_probability": float(spec.kick_probability),
                "confidence_decay": float(spec.confidence_decay),
                "looking_decay": float(spec.looking_decay),
                "confidence_decay_distance": float(spec.confidence_decay_distance),
            }
        )
    detectors = []
    for name, detector in knowledge.detectors.items():
        detectors.append(
            {
                "name": name,
                "clutter_log_density": float(associator.clutter_log_density[name]),
                # by report: a report's likelihoods over the true classes are one row
                "likelihood": model._likelihood[name].T.ravel().tolist(),
                "range": None if detector.range is None else float(detector.range),
                "fixed": bool(detector.static),
                "position": None
                if detector.position is None
                else [float(v) for v in detector.position],
                "confidence": float(detector.confidence),
            }
        )
    world = knowledge.world
    detector_names = list(knowledge.detectors)

    def specific(first: str, second: str) -> int | None:
        if not taxonomy.compatible(first, second):
            return None
        return model.index[taxonomy.most_specific(first, second)]

    return {
        "dim": world.dimension,
        "classes": classes,
        "detectors": detectors,
        "default_detector": detector_names.index(knowledge.default_detector),
        "mht": associator.model == "mht",
        "missed_detections": bool(mhf.missed_detections),
        "observed_rates": bool(mhf.observed_rates),
        "ratio": float(mhf.ratio),
        "max_hypotheses": int(mhf.max_hypotheses),
        "merge_distance": float(mhf.merge_distance),
        "removal_existence": float(mhf.removal_existence),
        "region": None if world.region is None else [(float(a), float(b)) for a, b in world.region],
        "gate": float(associator.gate),
        "gate_quantile": float(mhf._gate_quantile),
        "label_gate": float(associator.label_gate),
        "log_label_error": float(associator.log_label_error),
        "log_volume": float(associator.log_volume),
        "subtree": model.subtree.ravel().tolist(),
        "depth": [float(v) for v in model.depth.tolist()],
        "appear_mask": model.appear_mask.tolist(),
        "compatible": [taxonomy.compatible(a, b) for a in names for b in names],
        "class_likelihood": [taxonomy.class_likelihood(a, b) for a in names for b in names],
        "most_specific": [specific(a, b) for a in names for b in names],
        "min_existence": float(world.min_existence),
    }


def observed_from_core(rates: _core.ObservedRates) -> ObservedRates:
    """The specification's :class:`ObservedRates` of the core's."""
    sources, streams, seen, alarms = rates.state()
    return ObservedRates(
        {
            name: SourceClock(last, interval, None if at is None else tuple(at), speed)
            for name, last, interval, at, speed in sources
        },
        {
            (s, d, c): StreamCounts(hits, expected, frozenset(detected))
            for s, d, c, hits, expected, detected in streams
        },
        {lineage: {(s, d): at for s, d, at in rows} for lineage, rows in seen},
        {
            (s, d): FalseAlarms(since, frozenset(pending), count)
            for s, d, since, pending, count in alarms
        },
    )


def observed_to_core(rates: ObservedRates) -> _core.ObservedRates:
    """The core's observed rates of the specification's."""
    from semwm import _core

    return _core.ObservedRates.of(
        [
            (name, c.last_time, c.interval, _listed(c.position), c.speed)
            for name, c in rates.sources.items()
        ],
        [
            (s, d, c, counts.hits, counts.expected, sorted(counts.detected))
            for (s, d, c), counts in rates.streams.items()
        ],
        [
            (lineage, [(s, d, at) for (s, d), at in streams.items()])
            for lineage, streams in rates.seen.items()
        ],
        [
            (s, d, alarms.since, sorted(alarms.pending), alarms.count)
            for (s, d), alarms in rates.false_alarms.items()
        ],
    )


def _listed(position: tuple[float, ...] | None) -> list[float] | None:
    return None if position is None else list(position)


class _VersionRefSpec(NamedTuple):
    """A version of a core state, named without making its Python value (the published
    world of every scan names every object shown; their values are made only where
    needed: :func:`track_of`). The core makes them (``semwm._core.VersionRef``, these
    fields); this one stands in where the core is not built, and then none is made."""

    lineage: int
    cls: str
    key: int
    serial: int
    state: CoreState


if TYPE_CHECKING:
    from semwm._core import VersionRef
else:
    try:
        from semwm._core import VersionRef
    except ImportError:  # no core, no core states: no VersionRef is ever made
        VersionRef = _VersionRefSpec


def track_of(version: Track | VersionRef) -> Track:
    """The version's Python value."""
    if isinstance(version, VersionRef):
        state: CoreState = version.state
        return state.engine.resolve(version)
    return version


def unpickled_track(track: Track) -> Track:
    """What a pickled ``VersionRef`` becomes: its version's Python value (the core
    state it names lives in this process only; ``semwm._core.VersionRef.__reduce__``)."""
    return track


class _Made:
    """Python values made from core states, reused for later ones. A cluster is named by
    its address, valid while a state holding it lives (``cluster_state`` keeps the last
    one read alive); a version by its serial number, unique for the whole run."""

    def __init__(self) -> None:
        self.cluster_state: _core.State | None = None
        self.clusters: dict[int, Cluster] = {}
        self.tracks: dict[int, Track] = {}


class CoreState:
    """A filter state kept in the core, with :class:`MHFState`'s interface (read-only)."""

    __slots__ = ("_clusters", "_existence", "_observed", "_python", "_tracks", "core", "engine")

    def __init__(self, core: _core.State, engine: CoreEngine) -> None:
        self.core = core
        self.engine = engine
        self._tracks: dict[int, Track] | None = None
        self._clusters: tuple[Cluster, ...] | None = None
        self._existence: dict[int, float] | None = None
        self._observed: ObservedRates | None = None
        self._python: MHFState | None = None

    @property
    def time(self) -> float | None:
        return self.core.time

    @property
    def next_key(self) -> int:
        return self.core.next_key

    @property
    def hypothesis_count(self) -> int:
        return self.core.hypothesis_count

    @property
    def clusters(self) -> tuple[Cluster, ...]:
        if self._clusters is None:
            self._clusters = self.engine._clusters_of(self.core)
        return self._clusters

    @property
    def tracks(self) -> Mapping[int, Track]:
        if self._tracks is None:
            self._tracks, self._existence = self.engine._tracks_of(self.core)
        return self._tracks

    @property
    def existence(self) -> Mapping[int, float]:
        if self._existence is None:
            self._tracks, self._existence = self.engine._tracks_of(self.core)
        return self._existence

    @property
    def observed(self) -> ObservedRates:
        if self._observed is None:
            self._observed = observed_from_core(self.core.observed())
        return self._observed

    def __reduce__(self) -> tuple[Any, tuple[Any, ...]]:
        """Pickled as the specification's :class:`MHFState` (snapshots): the core state
        lives in this process only; the Rust engine takes it back on its next scan."""
        python = self.python()
        return (
            MHFState,
            (
                python.clusters, python.tracks, python.time, python.next_key,
                python.existence, python.observed,
            ),
        )  # fmt: skip

    def python(self) -> MHFState:
        """The same state as the specification's values."""
        if self._python is None:
            self._python = MHFState(
                self.clusters, dict(self.tracks), self.time, self.next_key,
                dict(self.existence), self.observed,
            )  # fmt: skip
        return self._python

    @property
    def best(self) -> Hypothesis:
        return self.python().best

    @property
    def log10_joint_count(self) -> float:
        """:attr:`MHFState.log10_joint_count`, from the core's cluster sizes."""
        return math.fsum(math.log10(size) for size in self.core.cluster_sizes())

    @property
    def cluster_count(self) -> int:
        return self.core.cluster_count

    @property
    def track_count(self) -> int:
        return self.core.track_count

    def top(self, k: int) -> list[Hypothesis]:
        return self.python().top(k)

    @property
    def hypotheses(self) -> tuple[Hypothesis, ...]:
        return self.python().hypotheses


class CoreBook:
    """The confidence book (:class:`~semwm.confidence.ConfidenceBook`) kept in the core
    (``core/src/confidence.rs``)."""

    __slots__ = ("core",)

    def __init__(self, core: _core.Book) -> None:
        self.core = core

    def at(self, lineage: int, time: float, spec: ResolvedClass) -> float:
        """:meth:`ConfidenceBook.at`."""
        return carried(self.core.entry(lineage), time, spec)

    def python(self) -> ConfidenceBook:
        values, poses, scans = self.core.state()
        return ConfidenceBook(
            {lineage: (value, since) for lineage, value, since in values},
            {source: (x, y) for source, x, y in poses},
            dict(scans),
        )

    def __reduce__(self) -> tuple[Any, tuple[Any, ...]]:
        """Pickled as the specification's :class:`ConfidenceBook` (snapshots)."""
        book = self.python()
        return (ConfidenceBook, (book.values, book.poses, book.scans))


def as_python_book(book: BookView) -> ConfidenceBook:
    """``book`` as the specification's :class:`ConfidenceBook`."""
    if isinstance(book, ConfidenceBook):
        return book
    if isinstance(book, CoreBook):
        return book.python()
    raise TypeError(f"not a confidence book: {type(book).__name__}")


def as_python(state: StateView) -> MHFState:
    """``state`` as the specification's :class:`MHFState`."""
    if isinstance(state, MHFState):
        return state
    if isinstance(state, CoreState):
        return state.python()
    raise TypeError(f"not a filter state: {type(state).__name__}")


class CoreEngine:
    """The whole scan in the core for one :class:`MultipleHypothesisFilter`."""

    def __init__(self, mhf: MultipleHypothesisFilter) -> None:
        from semwm import _core

        self._core = _core
        self.engine = _core.Engine(tables(mhf))
        self.names: tuple[str, ...] = tuple(self.engine.class_names())
        self.index = {name: i for i, name in enumerate(self.names)}
        self.detectors = {name: i for i, name in enumerate(mhf.knowledge.detectors)}
        self.dim = mhf.knowledge.world.dimension
        self._made = _Made()

    # ------------------------------------------------------------------ scans
    def process_scan(
        self, state: StateView, measurements: Sequence[Measurement], view: SensorView | None
    ) -> CoreState:
        core = self.to_core(state)
        view_row = None if view is None else self._view(view)
        after = self.engine.process_measurements(core, self.scan_rows(measurements), view_row)
        return CoreState(after, self)

    def scan_rows(self, measurements: Sequence[Measurement]) -> Sequence[Measurement]:
        """The rows a scan hands the core: its measurements as they are, a list, or the
        reader's ``Scan`` whose rows the core takes without its values (one place, so
        that a test can alter what the core sees)."""
        return (
            measurements if isinstance(measurements, list | self._core.Scan) else list(measurements)
        )

    def process_and_advance(
        self,
        state: StateView,
        book: BookView,
        measurements: Sequence[Measurement],
        view: SensorView | None,
    ) -> tuple[CoreState, CoreBook]:
        """:meth:`process_scan`, then :meth:`advance` over the state after it, in one
        call to the core (``WorldModel._step`` with the ``mht`` model)."""
        after, after_book = self.engine.process_and_advance(
            self.to_core(state),
            self.core_book(book),
            self.scan_rows(measurements),
            None if view is None else self._view(view),
            None if view is None else view.source,
        )
        return CoreState(after, self), CoreBook(after_book)

    def state_of(self, core: _core.State) -> CoreState:
        """The :class:`CoreState` of a state this engine's core made."""
        return CoreState(core, self)

    def _view(self, view: SensorView) -> tuple[Any, ...]:
        return (
            float(view.time),
            view.source or "",
            (float(view.position[0]), float(view.position[1])),
            float(view.heading),
            None if view.range is None else float(view.range),
            None if view.half_angle is None else float(view.half_angle),
            sorted(view.looking_at),
            None if view.detector is None else self.detectors[view.detector],
        )

    def to_core(self, state: StateView) -> _core.State:
        """The core's state of ``state`` (made from the specification's values unless it
        is this engine's)."""
        if isinstance(state, CoreState) and state.engine is self:
            return state.core
        python = as_python(state)
        existence = python.existence
        versions = [
            (
                (t.key, t.lineage, self.index[t.cls], t.label),
                (*t.x.shape, t.x.ravel().tolist(), t.P.ravel().tolist(), t.mu.tolist()),
                (float(t.time), float(t.last_seen), float(t.created), float(t.rate)),
                (t.class_probs.tolist(), sorted(t.sources), float(existence.get(t.key, 1.0))),
            )
            for t in python.tracks.values()
        ]
        clusters = [
            [(h.log_weight, sorted(h.tracks), h.rate) for h in c.hypotheses]
            for c in python.clusters
        ]
        return self._core.State.of(
            clusters, versions, python.time, python.next_key, observed_to_core(python.observed)
        )

    # ------------------------------------------------------------------ reading a state
    def _clusters_of(self, core: _core.State) -> tuple[Cluster, ...]:
        made = self._made
        ids = core.cluster_ids()
        missing = [i for i, cid in enumerate(ids) if cid not in made.clusters]
        rows = iter(core.clusters(missing)) if missing else iter(())
        clusters: dict[int, Cluster] = {}
        result = []
        for cid in ids:
            cluster = made.clusters.get(cid)
            if cluster is None:
                hypotheses = tuple(
                    Hypothesis(lw, frozenset(keys), rate) for lw, keys, rate in next(rows)
                )
                cluster = Cluster.of(hypotheses)
            clusters[cid] = cluster
            result.append(cluster)
        made.clusters = clusters
        made.cluster_state = core
        return tuple(result)

    def _tracks_of(self, core: _core.State) -> tuple[dict[int, Track], dict[int, float]]:
        keys, serials, existence = core.entries()
        tracks = dict(zip(keys, self._made_tracks(core, keys, serials), strict=True))
        return tracks, dict(zip(keys, existence, strict=True))

    def tracks_of(self, state: CoreState, keys: list[int]) -> list[Track]:
        """The versions of ``keys`` in ``state`` as Python values."""
        return self._made_tracks(state.core, keys, state.core.serials(keys))

    def _made_tracks(self, core: _core.State, keys: list[int], serials: list[int]) -> list[Track]:
        made = self._made.tracks
        missing = [k for k, serial in zip(keys, serials, strict=True) if serial not in made]
        made_now = iter(self._versions(core, missing)) if missing else iter(())
        result = []
        for serial in serials:
            track = made.get(serial)
            if track is None:
                track = made[serial] = next(made_now)
            result.append(track)
        if len(made) > 2 * max(1024, core.track_count):  # forget versions long gone
            _, alive, _ = core.entries()
            self._made.tracks = {serial: made[serial] for serial in alive if serial in made}
        return result

    def advance(
        self,
        book: BookView,
        state: CoreState,
        measurements: Sequence[Measurement],
        view: SensorView | None,
    ) -> CoreBook:
        """:func:`semwm.confidence.advance` in the core."""
        core_book = self.core_book(book)
        detectors = [self.detectors[m.detector] for m in measurements]
        return CoreBook(
            self.engine.advance(
                core_book,
                state.core,
                detectors,
                None if view is None else self._view(view),
                None if view is None else view.source,
            )
        )

    def core_book(self, book: BookView) -> _core.Book:
        """The core's confidence book of ``book``."""
        if isinstance(book, CoreBook):
            return book.core
        if isinstance(book, ConfidenceBook):
            return self._core.Book.of(
                [(lineage, value, since) for lineage, (value, since) in book.values.items()],
                [(source, x, y) for source, (x, y) in book.poses.items()],
                list(book.scans.items()),
            )
        raise TypeError(f"not a confidence book: {type(book).__name__}")

    def current(
        self, state: CoreState, published: Mapping[int, Any], ids: Mapping[int, int]
    ) -> dict[int, VersionRef]:
        """``WorldModel._current`` of ``state``: lineage -> the version shown
        (``core/src/world.rs``); ``published`` the objects shown now by id, ``ids``
        theirs (lineage -> id)."""
        return self.engine.current(state, published, ids)

    def resolve(self, ref: VersionRef) -> Track:
        """The version ``ref`` names as a Python value."""
        return self._made_tracks(ref.state.core, [ref.key], [ref.serial])[0]

    def _versions(self, core: _core.State, keys: list[int]) -> Iterator[Track]:
        names = self.names
        for head, (x, P, mu), times, (probs, sources, _) in core.versions(keys):
            key, lineage, cls, label = head
            time, last_seen, created, rate = times
            yield Track(
                key, lineage, names[cls], label, x, P, mu, time, last_seen, created, rate,
                probs, frozenset(sources),
            )  # fmt: skip
