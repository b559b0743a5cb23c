"""The facade users call: ingest detections, query the world.

>>> from semwm import WorldModel, load_knowledge
>>> wm = WorldModel(load_knowledge("knowledge/sim1.yaml"))      # doctest: +SKIP
>>> wm.ingest({"time": 0.0, "class": "Cup", "position": [1.0, 2.0]})  # doctest: +SKIP
>>> wm.world().objects                                             # doctest: +SKIP

The world model owns the only mutable state: the current :class:`MHFState`, the
scans kept for the reorder window, and the map from object lineages to public
ids. A batch is validated whole before anything changes; a rejected batch
changes nothing.
"""

from __future__ import annotations

import heapq
import math
from bisect import bisect_left, bisect_right
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, replace
from operator import attrgetter
from typing import TYPE_CHECKING, Any, Literal, NamedTuple, cast

import numpy as np
import numpy.typing as npt
from pydantic import ValidationError
from scipy.optimize import linear_sum_assignment

from semwm.collector import collector_paused
from semwm.confidence import (
    CONFIDENCE_STATES,
    BookView,
    Confidence,
    ConfidenceBook,
    advance,
    state_of,
    view_of,
)
from semwm.detection import (
    ActionReport,
    BeforeHistoryError,
    Detection,
    DetectionError,
    DetectionProblem,
    OutOfOrderError,
    SensorReport,
)
from semwm.filters.engine import Engine, resolve_engine
from semwm.filters.motion import FloatArray
from semwm.filters.small import mahalanobis_squared
from semwm.knowledge.model import Knowledge
from semwm.knowledge.taxonomy import Taxonomy
from semwm.mhf import nearby
from semwm.mhf.actions import Kick, apply_kick
from semwm.mhf.classes import SHOWN_FLOOR
from semwm.mhf.core_engine import CoreBook, CoreState, as_python, as_python_book, track_of
from semwm.mhf.filter import MultipleHypothesisFilter
from semwm.mhf.measurement import Measurement, SensorView
from semwm.mhf.predict import Predicted
from semwm.mhf.prune import TIE
from semwm.mhf.rates import StreamReport
from semwm.mhf.state import Cluster, MHFState, StateView, Track
from semwm.validation import (
    ClassesHeld,
    DetectionInput,
    as_batch,
    check,
    core_reader,
    out_of_range,
    outside_region,
    parse,
    region_bounds,
)
from semwm.world_types import (
    TENTATIVE_IDS,
    HypothesisObject,
    HypothesisSummary,
    WorldObject,
    WorldState,
    made_without_init,
)

if TYPE_CHECKING:
    from semwm._core import Published, VersionRef
    from semwm.mhf.core_engine import CoreEngine

ScanKey = tuple[float, str]
_HANDOVER_GATE = 13.8  # chi-square 99.9 % for 2 degrees of freedom; ids move only this close
_SAME_OBJECT_GATE = 1.0  # 4 x Bhattacharyya distance: two lineages' estimates coincide
_GROUPING_FLOOR = 1e-3  # lineages less likely than this are not grouped
_TENTATIVE_FLOOR = 1e-12  # a tentative object by id: whatever its existence
# a batch of at most this many detections the Rust engine takes in one call makes so few
# Python objects that pausing the collector (semwm.collector) costs more than it saves
_UNPAUSED_BATCH = 64
# a query's answer of more objects than this is made with the collector paused: each
# object is several Python objects, none in a cycle (semwm.collector)
_UNPAUSED_QUERY = 64


IgnoreReason = Literal["out_of_range", "outside_region"]


@dataclass(frozen=True)
class IgnoredDetection:
    """A detection accepted but not used, and why: ``out_of_range`` (beyond its
    detector's ``range`` from its sensor, paper 000 C2) or ``outside_region`` (clearly
    outside the knowledge's region: :func:`semwm.validation.outside_region`).
    ``index``: its place in the batch."""

    index: int
    reason: IgnoreReason
    message: str
    source: str | None = None

    def to_dict(self) -> dict[str, object]:
        return {"index": self.index, "reason": self.reason, "message": self.message}


@dataclass(frozen=True)
class IngestResult:
    """How many detections were applied, how many ignored (and which, why), and the
    world time after them."""

    applied: int
    time: float | None
    ignored: int = 0
    ignored_detections: tuple[IgnoredDetection, ...] = ()


_new_object = object.__new__
"""How :func:`~semwm.world_types.made_without_init` makes a value; the one-scan path
(:meth:`WorldModel._ingest_scan`) makes its ``IngestResult`` so, inlined."""

_new_tuple = tuple.__new__
"""How a named tuple's class makes one without its ``__new__`` (a Python function):
the one-scan path makes its :class:`_LoggedScan` so, in half the time."""


class _Asked(NamedTuple):
    """What a query (:meth:`WorldModel.world`) asks of its objects beyond its time,
    checked: at least ``floor`` likely to exist, of class ``cls`` or below, within
    ``near``'s radius, carrying ``label``, in one of the confidence ``states``."""

    floor: float
    cls: str | None
    near: Sequence[float] | None
    label: str | None
    states: set[str] | None


class _Marginal(NamedTuple):
    """What the whole hypothesis set says of one object (lineage) at a time: its
    existence probability (the sum over hypotheses of p(h) times the existence of
    the version h holds, inside the region) and its version in the most probable
    hypothesis that holds it, with that version's row in the prediction. A named
    tuple: one is made per object per scan."""

    existence: float
    track: Track
    row: int


class _LoggedScan(NamedTuple):
    """A processed scan in the reorder log, with the state and confidences before it (a
    named tuple: one is made per scan)."""

    key: ScanKey
    measurements: Sequence[Measurement]  # never changed (a tuple, or the reader's Scan)
    before: StateView
    view: SensorView | None
    book: BookView


_log_key = attrgetter("key")
_id_of = attrgetter("id")


@dataclass(frozen=True)
class _Held:
    """A scan the hold keeps pending: its detections (numbered when accepted) and its
    sensor view, in the order its batches came."""

    key: ScanKey
    measurements: tuple[Measurement, ...]
    view: SensorView | None = None


_Published = Mapping[int, "Track | VersionRef"]
"""The published world: id -> version (a dict, or the Rust engine's ``Published``
table, whose values are made when read)."""
_Tables = tuple[dict[int, int], int, _Published, dict[int, "_Lost"]]
"""The id tables: lineage -> id, the next id, the published and the lost objects."""
_Link = tuple[_Held, StateView, BookView, _Tables]


@dataclass(frozen=True)
class _Tentative:
    """The held scans processed on a copy, for queries: from the committed ``base``,
    ``base_book`` and ``base_tables``, each held scan (in time order) with the state,
    confidences and id tables after it. When a held scan is released, its link is
    committed as it is (no second run)."""

    base: StateView
    base_book: BookView
    base_tables: _Tables
    chain: tuple[_Link, ...]


class _Lost(NamedTuple):
    """A published object that left the published world, its id waiting for it: its
    version as last published (positions are computed only if its id has to be handed
    over) and when it left."""

    track: Track | VersionRef  # the Rust engine's: made into a Track only where needed
    lost_at: float

    @property
    def lineage(self) -> int:
        return self.track.lineage


_Floor = tuple[ScanKey, str]
"""No scan at or before this key may be processed any more, and why."""

_Read = tuple[int, dict[ScanKey, Sequence[Measurement]], list["IgnoredDetection"]]
"""The Rust engine's reading of a plain batch (:meth:`WorldModel._read_plain`): how many
detections are used, their scans, and why each other one is not."""


def _same_tables(a: _Tables, b: _Tables) -> bool:
    """The same id tables (the same dicts, not equal ones)."""
    return a[0] is b[0] and a[1] == b[1] and a[2] is b[2] and a[3] is b[3]


def _shown_lineages(published: _Published) -> set[int]:
    """The lineages of the published world (the Rust engine's table gives them without
    making its values)."""
    lineages = getattr(published, "lineages", None)
    if lineages is not None:
        return set(lineages())
    return {track.lineage for track in published.values()}


def _frozen(scan: Sequence[Measurement]) -> Sequence[Measurement]:
    """A scan's measurements as a sequence nobody changes: a list copied into a tuple;
    a tuple, or the reader's ``Scan``, as it is."""
    return tuple(scan) if isinstance(scan, list) else scan


def _same(a: Sequence[Measurement], b: Sequence[Measurement]) -> bool:
    """The same detection objects in the same order."""
    return len(a) == len(b) and all(x is y for x, y in zip(a, b, strict=True))


def _checked_hold(hold: float) -> float:
    if hold < 0 or not math.isfinite(hold):
        raise ValueError(f"hold must be a finite number >= 0 (s); got {hold}")
    return float(hold)


def _within(value: float, low: float, high: float) -> bool:
    return low <= value <= high


def _within_reach(position: Sequence[float], sensor: Sequence[float], reach: float | None) -> bool:
    """Whether a detection lies within its detector's ``reach`` of its sensor: then
    :func:`semwm.validation.out_of_range` keeps it whatever the margin (the same
    distance, summed in the same order)."""
    if reach is None:
        return True
    squared = 0.0
    for a, b in zip(position, sensor, strict=True):
        value = float(a) - float(b)
        squared += value * value
    return math.sqrt(squared) <= reach


def _view_key(view: SensorView) -> ScanKey:
    return (view.time, view.source or "")


def _grouped(
    measurements: Sequence[Measurement], view: SensorView | None
) -> tuple[dict[ScanKey, list[Measurement]], dict[ScanKey, SensorView]]:
    """A batch's detections by scan (time, source), and its sensor view by scan."""
    scans: dict[ScanKey, list[Measurement]] = {}
    views: dict[ScanKey, SensorView] = {}
    for m in measurements:  # the key (time, source or ""), inline: once per detection
        key = (m.time, m.source or "")
        group = scans.get(key)
        if group is None:
            scans[key] = [m]
        else:
            group.append(m)
    if view is not None:
        key = _view_key(view)
        scans.setdefault(key, [])
        views[key] = view
    return scans, views


def _stored_positions(tracks: Sequence[Track], dim: int) -> tuple[FloatArray, FloatArray]:
    """Combined positions ``(N, d)`` and covariances ``(N, d, d)`` of stored versions."""
    position = np.zeros((len(tracks), dim))
    covariance = np.zeros((len(tracks), dim, dim))
    groups: dict[tuple[int, ...], list[int]] = {}
    for i, track in enumerate(tracks):
        groups.setdefault(track.x.shape, []).append(i)
    for rows in groups.values():  # one batched call per filter shape
        x = np.array([tracks[i].x for i in rows])[:, :, :dim]  # (N, M, d)
        P = np.array([tracks[i].P for i in rows])[:, :, :dim, :dim]
        if x.shape[1] == 1:  # one mode: nothing to combine
            position[rows] = x[:, 0]
            covariance[rows] = P[:, 0]
            continue
        mu = np.array([tracks[i].mu for i in rows])  # (N, M)
        position[rows] = np.einsum("nm,nmd->nd", mu, x)
        covariance[rows] = np.einsum("nm,nmij->nij", mu, P)
    return position, covariance


def _summary_position(track: Track, dim: int) -> tuple[FloatArray, FloatArray]:
    """Combined position and covariance of a stored version (no prediction)."""
    x = track.mu @ track.x[:, :dim]
    P = np.einsum("m,mij->ij", track.mu, track.P[:, :dim, :dim])
    return x, P


class WorldModel:
    """A semantic world model: a knowledge-driven MHF with a query interface.

    Parameters
    ----------
    knowledge
        Resolved knowledge (:func:`semwm.load_knowledge`).
    reorder_window
        Detections may arrive up to this many seconds (s) late and are still
        processed in time order (the scans after them are replayed); older ones
        raise :class:`~semwm.detection.OutOfOrderError`.
    hold
        Scans newer than the newest accepted time minus ``hold`` (s) are kept pending
        and processed in time order once they are older than that, so sources whose
        detections arrive up to ``hold`` s out of order cost no replay; only what
        arrives later than the hold is replayed (within ``reorder_window``, counted
        from the latest processed scan). Queries answer with the pending scans
        included: they are processed on a copy that is not committed. ``0``
        (default): every scan is processed at once. Choose about the sources'
        arrival jitter (docs/operations.md).
    engine
        ``"python"`` or ``"rust"``: who runs the numeric kernels (docs/engines.md);
        ``None`` (default): ``$SEMWM_ENGINE``, else ``"rust"`` where the extension is
        built (:func:`~semwm.filters.engine.resolve_engine`). ``"rust"`` without
        the built extension raises :class:`~semwm.filters.engine.EngineUnavailable`.

    The reorder history is also bounded in count (:attr:`max_reorder_scans`): past
    it the oldest scans are forgotten, and a detection that would have to be
    replayed before the newest forgotten scan is refused as out of order, so memory
    stays bounded however fast scans arrive.
    """

    max_reorder_scans = 1000
    """Most scans kept for replay; each holds a reference to the state before it."""

    def __init__(
        self,
        knowledge: Knowledge,
        *,
        reorder_window: float = 0.0,
        hold: float = 0.0,
        engine: str | None = None,
    ) -> None:
        self.engine: Engine = resolve_engine(engine)
        self._summaries: dict[int, tuple[Track, FloatArray, FloatArray, float]] = {}
        if reorder_window < 0 or not math.isfinite(reorder_window):
            raise ValueError(f"reorder_window must be a finite number >= 0; got {reorder_window}")
        self.reorder_window = reorder_window
        self._hold = _checked_hold(hold)
        self._set_knowledge(knowledge)
        self.reset()

    # ------------------------------------------------------------------ state
    def _set_knowledge(self, knowledge: Knowledge) -> None:
        # the region's bounds per (class, detector), for the batches' region check
        self._region_bounds: dict[tuple[str, str], tuple[list[float], list[float]] | None] = {}
        self._knowledge = knowledge
        self._mhf = MultipleHypothesisFilter(knowledge, self.engine)
        # the Rust engine reads plain batches in one pass, as the three below decide
        core = self._mhf._core
        self._reader = None if core is None else core_reader(knowledge, self._mhf.factory, core)
        self._summaries = {}  # the region may have changed
        # lost ids found able to return (_may_return) under this knowledge, by id()
        self._returning: dict[int, _Lost] = {}

    def reset(self) -> None:
        """Forget every detection and object."""
        self._state: StateView = MHFState.empty()
        self._book: BookView = ConfidenceBook()
        core = self._mhf._core
        if core is not None:  # the core's own empty state: the first scan is one call too
            self._state = core.state_of(core.to_core(self._state))
            self._book = CoreBook(core.core_book(self._book))
        self._summaries = {}
        self._log: list[_LoggedScan] = []
        self._replay_floor: _Floor | None = None  # no replay at or before this scan
        self._seq = 0
        self._ids: dict[int, int] = {}
        self._next_id = 1
        # id -> the version published (the Rust engine's: a VersionRef, made into a
        # Track only where needed)
        self._published: _Published = {}
        self._lost: dict[int, _Lost] = {}
        self._pending: dict[ScanKey, _Held] = {}  # held scans (values immutable)
        self._newest: float | None = None  # newest accepted time, pending included
        self._earliest: float | None = None  # earliest accepted time: nothing before it
        self._tentative: _Tentative | None = None  # cache for queries
        self.replayed_scans = 0  # logged scans processed again: an older one came after

    @property
    def hold(self) -> float:
        """Seconds scans are kept pending (see the class); :meth:`set_hold` changes it."""
        return self._hold

    def set_hold(self, hold: float) -> None:
        """Use another hold from now on; scans it no longer holds are processed now."""
        self._hold = _checked_hold(hold)
        if self._pending:
            self._release()

    @property
    def pending_scans(self) -> int:
        """Scans accepted and held, not yet processed (:attr:`hold`)."""
        return len(self._pending)

    @property
    def processed_time(self) -> float | None:
        """Time of the latest processed scan (s); behind :attr:`latest_time` by at most
        :attr:`hold` while scans are pending."""
        return self._state.time

    @property
    def processed_source(self) -> str | None:
        """Source (``""`` for none) of the latest processed scan, while the reorder log
        holds it (``reorder_window`` > 0); scans are processed in (time, source) order."""
        if not self._log or self._log[-1].key[0] != self._state.time:
            return None
        return self._log[-1].key[1]

    @property
    def knowledge(self) -> Knowledge:
        return self._knowledge

    @property
    def taxonomy(self) -> Taxonomy:
        return self._mhf.taxonomy

    @property
    def latest_time(self) -> float | None:
        """Time of the latest accepted detection (s), pending ones (:attr:`hold`)
        included: the time queries answer at by default."""
        return self._newest if self._pending else self._state.time

    @property
    def hypothesis_count(self) -> int:
        """Hypotheses stored (the sum over clusters; see :attr:`log10_joint_hypotheses`).
        This and the other counts are of the processed state (pending scans excluded:
        they are cheap, read after every change)."""
        return self._state.hypothesis_count

    @property
    def log10_joint_hypotheses(self) -> float:
        """log10 of the number of global hypotheses (combinations of the clusters')."""
        return self._state.log10_joint_count

    @property
    def cluster_count(self) -> int:
        """Independent groups of hypotheses (clusters)."""
        return self._state.cluster_count

    @property
    def object_count(self) -> int:
        """Objects of the published world."""
        return len(self._published)

    @property
    def track_count(self) -> int:
        """Distinct object versions stored, shared by all hypotheses."""
        return self._state.track_count

    def replace_knowledge(self, knowledge: Knowledge, *, refuse_held: bool = False) -> None:
        """Use new knowledge from the next detection on. Objects of classes it no longer
        has are removed; the reorder window restarts (no replay across the change).

        ``refuse_held``: raise :class:`~semwm.validation.ClassesHeld` instead, naming
        the classes and objects, when tracked objects (in any stored hypothesis) hold a
        class the knowledge lacks. The work is per cluster and per stored object
        version, never per global hypothesis (issue 30: a class edit that enumerated
        them took 272 s). Held scans are released first; a caller that must change
        nothing on a refusal restores the model (the service does).
        """
        if knowledge.world.dimension != self._knowledge.world.dimension:
            raise ValueError(
                f"the new knowledge has dimension {knowledge.world.dimension}; the world has "
                f"{self._knowledge.world.dimension}: reset first"
            )
        MultipleHypothesisFilter(knowledge)  # fail here, before anything changes
        self._release(everything=True)  # held scans were accepted under the old knowledge
        if refuse_held:
            held: dict[str, set[int | None]] = {}
            tracks = self._state.tracks
            for cluster in self._state.clusters:
                for key in cluster.keys:
                    track = tracks[key]
                    if track.cls not in knowledge.classes:
                        held.setdefault(track.cls, set()).add(self._ids.get(track.lineage))
            if held:
                raise ClassesHeld(held)
        gone = {k for k, t in self._state.tracks.items() if t.cls not in knowledge.classes}
        old_names = self._mhf.associator.class_model.names
        self._set_knowledge(knowledge)
        self._state = _remap_classes(self._state, old_names, self._mhf.associator.class_model.names)
        if gone:
            state = self._state
            clusters = self._mhf.without(state.clusters, gone, state.tracks)
            referenced = sorted(set().union(*(c.keys for c in clusters)))
            tracks = {k: state.tracks[k] for k in referenced}
            existence = {k: state.existence.get(k, 1.0) for k in referenced}
            self._state = replace(state, clusters=clusters, tracks=tracks, existence=existence)
        self._published = {i: p for i, p in self._published.items() if p.cls in knowledge.classes}
        self._lost = {i: p for i, p in self._lost.items() if p.track.cls in knowledge.classes}
        if gone:
            self._publish()
        self._restart_reorder("a knowledge change")

    def _restart_reorder(self, at: str) -> None:
        """Forget the reorder history: no replay across ``at``, so a scan older than
        the world's time is refused from now on (it cannot be put before the change)."""
        self._log = []
        time = self._state.time
        floor = None if time is None else ((time, ""), f"the reorder window restarts at {at}")
        self._replay_floor = floor

    # ------------------------------------------------------------------ input
    def validate(self, detections: DetectionInput | Iterable[DetectionInput]) -> list[Measurement]:
        """Check detections without applying them; raises ``DetectionError``."""
        parsed = parse(as_batch(detections))
        return check(parsed, self._knowledge, self._mhf.factory, self._seq)

    def ingest(
        self,
        detections: DetectionInput | Iterable[DetectionInput],
        sensor: SensorReport | Mapping[str, Any] | None = None,
    ) -> IngestResult:
        """Apply detections (values or plain dicts), whole or not at all.

        ``sensor`` (:class:`~semwm.detection.SensorReport`) says where the scan's sensor
        looked: objects predicted in its view that the scan does not report lose
        existence and confidence (paper 004's negative information). With it the
        batch may be empty: "I looked and saw nothing".

        Raises
        ------
        DetectionError
            A detection is malformed or does not fit the knowledge; nothing applied.
        OutOfOrderError
            A detection is older than the reorder window allows; nothing applied.

        Python's cyclic garbage collector is paused meanwhile (:mod:`semwm.collector`),
        except for a small batch the Rust engine takes in one call, which makes too few
        Python objects for the pause to pay.
        """
        # as_batch and _read_plain, inlined for the common small list
        batch = list(detections) if type(detections) is list else as_batch(detections)
        if len(batch) <= _UNPAUSED_BATCH:
            reader = self._reader
            answer = None if reader is None else reader.read(batch, self._seq)
            read: _Read | None
            if answer is None or not answer[2]:
                # none unplaced: its empty list is the list of what is ignored too
                read = answer  # type: ignore[assignment]
            else:
                read = self._read_unplaced(batch, sensor, answer)
            done = None if sensor is not None else self._ingest_scan(read, len(batch))
            if done is not None:
                return done
            with collector_paused():
                return self._ingest(batch, sensor, read)
        with collector_paused():
            read = self._read_plain(batch, sensor)
            done = None if sensor is not None else self._ingest_scan(read, len(batch))
            return done if done is not None else self._ingest(batch, sensor, read)

    def _ingest(
        self,
        batch: list[DetectionInput],
        sensor: SensorReport | Mapping[str, Any] | None,
        read: _Read | None,
    ) -> IngestResult:
        if read is not None and sensor is None:  # the common batch: its scans as read
            applied, skipped = read[0], read[2]
            grouped: tuple[dict[ScanKey, Sequence[Measurement]], dict[ScanKey, SensorView]]
            grouped = (read[1], {})
            view = None
        else:
            measurements, used, skipped = self._read(batch, read)
            view = self._view(sensor, measurements) if sensor is not None else None
            grouped = cast(
                "tuple[dict[ScanKey, Sequence[Measurement]], dict[ScanKey, SensorView]]",
                _grouped(used, view),
            )
            applied = len(used)
        ignored = len(skipped)
        latest = self._state.time
        # the batch's scans (its used detections' and its view's): their times are the
        # batch's times, found once per scan rather than per detection
        keys = grouped[0]
        times = [key[0] for key in keys]
        if times and latest is not None:
            earliest = min(times)
            if earliest < latest - self.reorder_window - 1e-12:
                raise OutOfOrderError(earliest, latest, self.reorder_window)
            floor = self._replay_floor
            if floor is not None and min(keys) <= floor[0]:
                raise OutOfOrderError(earliest, latest, latest - floor[0][0], why=floor[1])
        if times:
            newest, earliest = max(times), min(times)
            self._newest = newest if self._newest is None else max(self._newest, newest)
            self._earliest = earliest if self._earliest is None else min(self._earliest, earliest)
        if self._hold > 0 and (applied or view is not None):
            self._hold_scans(*grouped)
        elif applied or view is not None:
            self._commit(*self._process_scans(*grouped))
            self._publish()
        self._seq += len(batch)
        return IngestResult(
            applied=applied,
            time=self.latest_time,
            ignored=ignored,
            ignored_detections=tuple(skipped),
        )

    def _ingest_scan(self, read: _Read | None, size: int) -> IngestResult | None:
        """:meth:`_ingest` of a batch of ``size`` detections the Rust engine's reader
        read whole into one scan (``read``), without a sensor report or a hold, after
        every logged scan: what the general path does (its checks,
        :meth:`_process_scans`, :meth:`_publish`), with no call that case does not need.
        ``None`` (nothing done) when the batch is not that case, or the state not the
        core's: the general path takes it.

        The scan of one detection takes a few µs in the core, so this path is written
        for the interpreter: no call, table or value it does not need (the model's
        ``_commit`` and the result's making are inlined)."""
        if read is None or len(read[1]) != 1:
            return None
        core = self._mhf._core
        state, book = self._state, self._book
        if (
            core is None
            or self._hold != 0
            or type(state) is not CoreState
            or state.engine is not core
            or type(book) is not CoreBook
            or self._tentative is not None
            or self._pending
        ):
            return None
        applied, scans, skipped = read
        ((key, scan),) = scans.items()
        log = self._log
        if log and not log[-1].key < key:
            return None  # a replay: the general path
        time, latest = key[0], state.core.time  # the core's, not the property's frame
        if latest is not None:
            if time < latest - self.reorder_window - 1e-12:
                raise OutOfOrderError(time, latest, self.reorder_window)
            floor = self._replay_floor
            if floor is not None and key <= floor[0]:
                raise OutOfOrderError(time, latest, latest - floor[0][0], why=floor[1])
        newest, earliest = self._newest, self._earliest
        if newest is None or time > newest:
            self._newest = time
        if earliest is None or time < earliest:
            self._earliest = time
        # the scan, its confidences and its publishing (_publish_core) in one core call;
        # the state after it is at the scan's time
        waiting = self._still_waiting(time) if self._lost else ()
        after_state, after_book, shown, unchanged = core.engine.process_and_publish(
            state.core,
            book.core,
            scan,
            self._published,
            self._ids,
            waiting is None,
            self._next_id,
            () if waiting is None else waiting,
            core.state_of,
        )
        # _commit, inlined; the log trimmed (_trimmed) only when it holds a scan older
        # than the window or more scans than it may
        after_time = after_state.core.time
        window = self.reorder_window
        if window > 0:
            kept = [*log, _new_tuple(_LoggedScan, (key, scan, state, None, book))]
            if kept[0].key[0] < after_time - window or len(kept) > self.max_reorder_scans:
                self._log, self._replay_floor = self._trimmed(kept, after_state)
            else:
                self._log = kept
        elif log:
            self._log = []
        # paper: no confidences (_step), the book the same
        self._state, self._book = after_state, CoreBook(after_book) if self._mhf.mht else book
        self._published_core(shown, unchanged)
        self._seq += size
        result: IngestResult = _new_object(IngestResult)  # made_without_init
        result.__dict__.update(
            {
                "applied": applied,
                "time": after_time,
                "ignored": len(skipped),
                "ignored_detections": tuple(skipped) if skipped else (),
            }
        )
        return result

    def _read_plain(self, batch: list[DetectionInput], sensor: object) -> _Read | None:
        """The Rust engine's reading of a plain batch (``semwm._core.DetectionReader``):
        how many detections are used, their scans, and why each other one is not
        (:meth:`_ignored_apart`); ``None`` when the batch takes the specification's path
        (:meth:`_read`): no reader, a detection that is not plain, or one the reader left
        out with a sensor report (whose view reads every detection)."""
        if self._reader is None:
            return None
        read = self._reader.read(batch, self._seq)
        if read is None:
            return None
        if not read[2]:
            # its list of the unplaced is empty, so a list of what is ignored too
            return read  # type: ignore[return-value]
        return self._read_unplaced(batch, sensor, read)

    def _read_unplaced(
        self,
        batch: list[DetectionInput],
        sensor: object,
        read: tuple[int, dict[ScanKey, Sequence[Measurement]], list[int]],
    ) -> _Read | None:
        """:meth:`_read_plain` of a batch the reader read (``read``) but for the
        detections it left unplaced (their indices, ``read[2]``, not empty)."""
        count, scans, unplaced = read
        skipped = None if sensor is not None else self._ignored_apart(batch, unplaced)
        return None if skipped is None else (count, scans, skipped)

    def _ignored_apart(
        self, batch: list[DetectionInput], indices: list[int]
    ) -> list[IgnoredDetection] | None:
        """Why each detection ``indices`` of a batch the reader read otherwise is not used
        (:meth:`_ignored`, each parsed and checked alone, numbered as in its batch); ``None``
        when one is used after all (within the margin :meth:`_ignored` allows beyond the
        reader's bounds) or does not check: the batch then takes the specification's path."""
        skipped = []
        for index in indices:
            try:
                parsed = parse([batch[index]])
                m = check(parsed, self._knowledge, self._mhf.factory, self._seq + index)[0]
            except DetectionError:
                return None
            why = self._ignored(parsed[0], m, index, self._region_bounds)
            if why is None:
                return None
            skipped.append(why)
        return skipped

    def _read(
        self,
        batch: list[DetectionInput],
        read: tuple[int, Mapping[ScanKey, Sequence[Measurement]], list[IgnoredDetection]]
        | None = None,
    ) -> tuple[list[Measurement], list[Measurement], list[IgnoredDetection]]:
        """A batch's measurements, those used, and why each other detection is not.

        The specification: :func:`~semwm.validation.parse`, then
        :func:`~semwm.validation.check` against the knowledge (raises
        ``DetectionError``), then :meth:`_placed`. The Rust engine's reader gives the
        same for a batch of plain detections in one pass (``read``: its answer, the
        batch's scans; docs/engines.md, "The boundary"); all of them are used."""
        if read is not None:  # every detection plain, numbered in the batch's order
            assert not read[2], "the reader left detections to place: the specification's"
            measurements = sorted(
                (m for scan in read[1].values() for m in scan), key=attrgetter("seq")
            )
            return measurements, measurements, []
        parsed = parse(batch)
        measurements = check(parsed, self._knowledge, self._mhf.factory, self._seq)
        used, skipped = self._placed(parsed, measurements)
        return measurements, used, skipped

    def _placed(
        self, parsed: list[Detection], measurements: list[Measurement]
    ) -> tuple[list[Measurement], list[IgnoredDetection]]:
        """The batch's measurements used, and why each other detection is not
        (:meth:`_ignored`). A detection with the class's noise, within its detector's
        range of its sensor position (if it gives one) and inside the region's bounds for
        its (class, detector) is used without a call to :meth:`_ignored`: the common
        case, decided as :meth:`_ignored` decides it."""
        used: list[Measurement] = []
        skipped: list[IgnoredDetection] = []
        bounds = self._region_bounds
        plain = self._knowledge.world.region is None
        detectors = self._knowledge.detectors
        for index, (m, d) in enumerate(zip(measurements, parsed, strict=True)):
            sensor = d.sensor_position
            if d.covariance is None and (
                sensor is None or _within_reach(d.position, sensor, detectors[m.detector].range)
            ):
                if plain:
                    used.append(m)
                    continue
                limits = bounds.get((m.cls, m.detector))
                if limits is not None:
                    low, high = limits
                    if all(map(_within, d.position, low, high)):
                        used.append(m)
                        continue
            why = self._ignored(d, m, index, bounds)
            if why is None:
                used.append(m)
            else:
                skipped.append(why)
        return used, skipped

    def _ignored(
        self,
        det: Detection,
        m: Measurement,
        index: int,
        bounds: dict[tuple[str, str], tuple[list[float], list[float]] | None],
    ) -> IgnoredDetection | None:
        """Why detection ``index`` of a batch is not used, or ``None`` when it is.
        ``bounds``: the region's bounds per (class, detector) for detections with the
        class's noise (:func:`semwm.validation.region_bounds`), made once per knowledge."""
        if det.sensor_position is not None and out_of_range(det, self._knowledge, m.R):
            detector = det.detector or self._knowledge.default_detector
            reach = self._knowledge.detectors[detector].range
            return IgnoredDetection(
                index,
                "out_of_range",
                f"beyond detector {detector!r}'s range of {reach:g} m from its sensor_position "
                "(check units and frame)",
                m.source,
            )
        if self._knowledge.world.region is None:
            return None
        if det.covariance is None:  # the class's noise: the bounds once per batch
            key = (m.cls, m.detector)
            if key not in bounds:
                bounds[key] = region_bounds(self._knowledge, m.R)
            limits = bounds[key]
            assert limits is not None
            low, high = limits
            outside = False
            for v, a, b in zip(det.position, low, high, strict=False):
                if v < a or v > b:
                    outside = True
                    break
        else:
            outside = outside_region(det, self._knowledge, m.R)
        if outside:
            region = ", ".join(f"[{a:g}, {b:g}]" for a, b in self._knowledge.world.region)
            return IgnoredDetection(
                index,
                "outside_region",
                f"position {list(det.position)} is outside the knowledge's region {region} "
                "by more than its noise (check units and frame)",
                m.source,
            )
        return None

    def _commit(
        self, state: StateView, log: list[_LoggedScan], book: BookView, floor: _Floor | None
    ) -> None:
        self._state, self._log, self._book, self._replay_floor = state, log, book, floor

    def _hold_scans(
        self, scans: dict[ScanKey, Sequence[Measurement]], views: dict[ScanKey, SensorView]
    ) -> None:
        """Scans before the latest processed one are processed now (replayed); the others
        join the pending ones, and those the hold no longer keeps are processed."""
        time = self._state.time
        last = self._log[-1].key if self._log else None
        late = [
            k
            for k in scans
            if time is not None and (k[0] < time or (last is not None and k <= last))
        ]
        if late:
            self._commit(
                *self._process_scans(
                    {k: scans[k] for k in late}, {k: views[k] for k in late if k in views}
                )
            )
            self._publish()
        for key, measurements in scans.items():
            if key in late:
                continue
            held = self._pending.get(key)
            view = views.get(key)
            if held is not None:  # another batch of a held scan: its view replaces the held one
                measurements = [*held.measurements, *measurements]
                view = view if view is not None else held.view
            self._pending[key] = _Held(key, tuple(measurements), view)
        self._release()

    def _release(self, everything: bool = False) -> None:
        """Process, one at a time in time order, the held scans older than the newest
        accepted time minus :attr:`hold` (``everything``: all), publishing after each as
        if each had come alone."""
        assert self._newest is not None or not self._pending
        boundary = math.inf if everything else (self._newest or 0.0) - self._hold + 1e-9
        for key in sorted(self._pending):
            if key[0] > boundary:
                break
            held = self._pending.pop(key)
            views = {key: held.view} if held.view is not None else {}
            cache = self._tentative
            cached = (
                self._fits(cache)
                and cache is not None
                and bool(cache.chain)
                and cache.chain[0][0] is held
            )
            self._commit(*self._process_scans({key: list(held.measurements)}, views))
            if cached and self._tentative is not None and self._tentative.base is self._state:
                # the ids a query gave after this scan: what _publish gives here
                ids, next_id, published, lost = self._tentative.base_tables
                self._ids, self._next_id = dict(ids), next_id
                self._published, self._lost = published, dict(lost)
                self._tentative = replace(self._tentative, base_tables=self._tables())
            else:
                self._publish()

    def act(self, action: ActionReport | Mapping[str, Any]) -> list[int]:
        """Apply an action (paper 004 IV-B; :mod:`semwm.mhf.actions`): a kick splits every
        hypothesis holding the object into kicked and not kicked. Returns the ids of the
        objects it may have moved.

        The reorder window restarts at the action (no replay across it: a detection
        older than the action then gives :class:`~semwm.detection.OutOfOrderError`).

        Raises
        ------
        DetectionError
            The action is malformed or names no passive object with velocity.
        OutOfOrderError
            It is older than the latest processed detection.
        """
        try:
            report = action if isinstance(action, ActionReport) else ActionReport(**action)
        except ValidationError as error:
            raise DetectionError(
                [DetectionProblem(path=tuple(e["loc"]), message=e["msg"]) for e in error.errors()]
            ) from None
        dim = self._knowledge.world.dimension
        problems: list[DetectionProblem] = []

        def problem(name: str, message: str) -> None:
            problems.append(DetectionProblem(path=(name,), message=message))

        if len(report.direction) != dim or not any(report.direction):
            problem("direction", f"direction must be {dim} numbers, not all 0")
        if (report.object is None) == (report.near is None):
            problem("object", "name the object ('object': id) or a position ('near': [x, y])")
        if report.near is not None and len(report.near) != dim:
            problem("near", f"near must have {dim} coordinates")
        if problems:
            raise DetectionError(problems)
        latest = self.latest_time  # held scans are processed before the action
        if latest is not None and report.time < latest - 1e-12:
            raise OutOfOrderError(report.time, latest, 0.0)
        with self._including_pending():
            lineages, moved = self._kicked(report, problems, problem)
        self._release(everything=True)
        direction = np.asarray(report.direction, dtype=float)
        kick = Kick(report.time, lineages, direction / np.linalg.norm(direction), report.speed)
        self._state = apply_kick(self._mhf, self._state, kick)
        self._restart_reorder("an action")
        self._publish()
        return moved

    def _kicked(
        self,
        report: ActionReport,
        problems: list[DetectionProblem],
        problem: Callable[[str, str], None],
    ) -> tuple[set[int], list[int]]:
        """The lineages and ids of the objects ``report`` kicks (raises ``DetectionError``)."""
        world = self.world(report.time, min_existence=1e-6)
        if report.object is not None:
            chosen = [o for o in world.objects if o.id == report.object]
            where = "object"
            if not chosen:
                problem(where, f"no object with id {report.object} in the world")
        else:
            assert report.near is not None
            near = np.asarray(report.near)
            candidates = [
                (float(np.linalg.norm(np.asarray(o.position) - near)), o)
                for o in world.objects
                if self._knowledge.classes[o.cls].category == "passive"
            ]
            close = [c for c in candidates if c[0] <= report.radius]
            chosen = [min(close, key=lambda c: c[0])[1]] if close else []
            where = "near"
            if not chosen:
                problem(where, f"no passive object within {report.radius:g} m of {report.near}")
        for obj in chosen:
            spec = self._knowledge.classes[obj.cls]
            if spec.category != "passive" or obj.velocity is None:
                problem(where, f"object {obj.id} ({obj.cls}) is not a passive object with velocity")
        if problems:
            raise DetectionError(problems)
        by_id = {object_id: lineage for lineage, object_id in self._ids.items()}
        return {by_id.get(o.id, -1 - o.id) for o in chosen}, [o.id for o in chosen]

    def _view(
        self, sensor: SensorReport | Mapping[str, Any], measurements: Sequence[Measurement]
    ) -> SensorView:
        """The scan's sensor view, checked against the knowledge and the batch."""
        try:
            report = sensor if isinstance(sensor, SensorReport) else SensorReport(**sensor)
        except ValidationError as error:
            raise DetectionError(
                [
                    DetectionProblem(path=("sensor", *e["loc"]), message=e["msg"])
                    for e in error.errors()
                ]
            ) from None
        problems: list[DetectionProblem] = []

        def problem(field: str, message: str) -> None:
            problems.append(DetectionProblem(path=("sensor", field), message=message))

        dim = self._knowledge.world.dimension
        if len(report.pose) != dim + 1:
            problem("pose", f"pose must be {dim} coordinates and a heading (rad)")
        times = {m.time for m in measurements}
        sources = {m.source for m in measurements}
        if report.time is None and len(times) != 1:
            problem("time", "an empty scan, or one of several times, needs the sensor's time")
        elif report.time is not None and times - {report.time}:
            problem("time", "the sensor's time differs from its detections' time")
        source = report.source if report.source is not None else next(iter(sources), None)
        if len(sources) > 1 or (sources and source not in sources):
            problem("source", "a sensor view belongs to one scan: detections of its source")
        detector = report.detector or next(
            (m.detector for m in measurements), self._knowledge.default_detector
        )
        if detector not in self._knowledge.detectors:
            problem("detector", f"unknown detector {detector!r}")
        by_id = {object_id: lineage for lineage, object_id in self._ids.items()}
        if self._pending and any(i not in by_id for i in report.looking_at):
            with self._including_pending():  # ids queries showed, held scans included
                by_id = {object_id: lineage for lineage, object_id in self._ids.items()}
        unknown = [i for i in report.looking_at if i not in by_id]
        if unknown:
            problem("looking_at", f"no object with id {unknown[0]} in the world")
        if problems:
            raise DetectionError(problems)
        time = report.time if report.time is not None else next(iter(times))
        return view_of(
            report.pose,
            time,
            source,
            detector,
            self._knowledge,
            frozenset(by_id[i] for i in report.looking_at),
        )

    def _process_scans(
        self, scans: dict[ScanKey, Sequence[Measurement]], views: dict[ScanKey, SensorView]
    ) -> tuple[StateView, list[_LoggedScan], BookView, _Floor | None]:
        """Process new scans, grouped by key (:func:`_grouped`; ``scans`` not empty and
        changed here), in time order, replaying logged scans they precede.

        Returns the new state, reorder log and confidences, and the log's replay floor
        (raised past the newest scan dropped to keep it within :attr:`max_reorder_scans`)."""
        first = min(scans)
        # the first logged scan at or after ``first`` (the log is in key order; a new
        # scan usually comes after all of it)
        history = self._log
        if not history or history[-1].key < first:
            start = len(history)
        else:
            start = bisect_left(history, first, key=_log_key)
        self.replayed_scans += len(self._log) - start
        if start < len(self._log):
            state, book = self._log[start].before, self._log[start].book
        else:
            state, book = self._state, self._book
        for logged in self._log[start:]:
            scans[logged.key] = [*logged.measurements, *scans.get(logged.key, [])]
            if logged.view is not None and logged.key not in views:
                views[logged.key] = logged.view
        log = self._log[:start]
        keep = self.reorder_window > 0  # else nothing is kept for a replay
        for key in sorted(scans):
            before, before_book = state, book
            scan_view = views.get(key)
            state, book = self._step(state, book, scans[key], scan_view)
            if keep:
                log.append(_LoggedScan(key, _frozen(scans[key]), before, scan_view, before_book))
        log, floor = self._trimmed(log if keep else [], state)
        return state, log, book, floor

    def _trimmed(
        self, log: list[_LoggedScan], state: StateView
    ) -> tuple[list[_LoggedScan], _Floor | None]:
        """The reorder log after a scan brought the state to ``state``: without the
        scans older than the reorder window, and at most :attr:`max_reorder_scans` long;
        with the replay floor, raised past the newest scan dropped to keep it so."""
        assert state.time is not None
        horizon = state.time - self.reorder_window
        cut = 0  # the log is in key (time) order: drop its head
        while cut < len(log) and log[cut].key[0] < horizon:
            cut += 1
        log = log[cut:] if cut else log
        floor = self._replay_floor
        if len(log) > self.max_reorder_scans:
            dropped = len(log) - self.max_reorder_scans
            floor = (
                log[dropped - 1].key,
                f"the reorder history holds at most {self.max_reorder_scans} scans",
            )
            log = log[dropped:]
        return log, floor

    # ------------------------------------------------------------------ held scans
    @contextmanager
    def _including_pending(self) -> Iterator[None]:
        """Within: the model as if each held scan had been ingested now, in time order
        (state, confidences and ids), with none held; after: exactly as before.

        This is how queries include every accepted detection without committing the
        held scans (committing early would make a later scan within the hold a
        replay, and what is accepted would depend on when someone asked). It costs
        one :meth:`MultipleHypothesisFilter.process_scan` and one :meth:`_publish` per
        held scan not yet in the cache (:meth:`_tentative_chain`); a released scan the
        cache holds is committed from it, so a scan is processed once either way.
        """
        if not self._pending:
            yield
            return
        saved = (
            self._state, self._book, self._pending, self._ids, self._next_id,
            self._published, self._lost, self._summaries,
        )  # fmt: skip
        try:
            _, self._state, self._book, tables = self._tentative_chain()[-1]
            self._pending = {}
            self._ids, self._next_id, self._published, self._lost = tables
            yield
        finally:
            (
                self._state, self._book, self._pending, self._ids, self._next_id,
                self._published, self._lost, self._summaries,
            ) = saved  # fmt: skip

    def _tables(self) -> _Tables:
        return self._ids, self._next_id, self._published, self._lost

    def _fits(self, cache: _Tentative | None) -> bool:
        """Whether ``cache`` starts from the committed state, confidences and ids."""
        return (
            cache is not None
            and cache.base is self._state
            and cache.base_book is self._book
            and _same_tables(cache.base_tables, self._tables())
        )

    def _tentative_chain(self) -> tuple[_Link, ...]:
        """Each held scan (time order) with the state, confidences and id tables after
        it, from the committed ones; not committed (the model's attributes are changed
        and must be restored: :meth:`_including_pending`). Cached: the cached scans that
        are still the first held ones are not run again."""
        held = [self._pending[k] for k in sorted(self._pending)]
        cache = self._tentative
        chain: list[_Link] = []
        if self._fits(cache):
            assert cache is not None
            for link, scan in zip(cache.chain, held, strict=False):
                if link[0] is not scan:
                    break
                chain.append(link)
        base = self._state, self._book, self._tables()
        state, book, tables = chain[-1][1:] if chain else base
        for scan in held[len(chain) :]:
            state, book = self._step(state, book, list(scan.measurements), scan.view)
            ids, next_id, published, lost = tables  # tables in a link are never changed
            self._state, self._ids, self._next_id = state, dict(ids), next_id
            self._published, self._lost = published, dict(lost)
            self._publish()
            tables = self._tables()
            chain.append((scan, state, book, tables))
        self._tentative = _Tentative(base[0], base[1], base[2], tuple(chain))
        return tuple(chain)

    def _step(
        self,
        state: StateView,
        book: BookView,
        measurements: Sequence[Measurement],
        view: SensorView | None,
    ) -> tuple[StateView, BookView]:
        """One scan processed: the MHF (paper 002) and the confidences (paper 004). The
        first scan of the query cache, from the same state, is taken from it: the same
        values, computed once."""
        cache = self._tentative
        if cache is not None and cache.chain and cache.base is state and cache.base_book is book:
            held, after, after_book, tables = cache.chain[0]
            if held.view is view and _same(held.measurements, measurements):
                self._tentative = _Tentative(after, after_book, tables, cache.chain[1:])
                return after, after_book
        core = self._mhf._core
        if core is not None and self._mhf.mht and (measurements or view is not None):
            return core.process_and_advance(state, book, measurements, view)  # one call
        state = self._mhf.process_scan(state, measurements, view)
        if self._mhf.mht:
            if core is not None and isinstance(state, CoreState) and state.engine is core:
                book = core.advance(book, state, measurements, view)
            else:
                book = advance(
                    as_python_book(book), state, measurements, view, self._knowledge,
                    self._mhf.factory,
                )  # fmt: skip
        return state, book

    # ------------------------------------------------------------------ ids
    def _publish(self) -> None:
        """Give public ids to the objects of the published world (:meth:`_current`).

        An object keeps its id as long as its lineage lives. A lineage new to the MAP
        takes over the id of a published object that left the MAP (the MAP switched to
        a hypothesis that explains the same object by another history) when they are
        close (Mahalanobis) and of compatible classes; otherwise it gets the next id.
        Ids are given only to published objects, so discarded branches burn none.
        """
        core = self._mhf._core
        state = self._state
        if core is not None and isinstance(state, CoreState) and state.engine is core:
            self._publish_core(core, state)
            return
        current = self._current()
        if (
            not self._lost
            and self._ids.keys() <= current.keys()
            and all(track.lineage in current for track in self._published.values())
        ):
            self._publish_unchanged(current)
        else:
            self._publish_changed(current)

    def _publish_core(self, core: CoreEngine, state: CoreState) -> None:
        """:meth:`_publish` of a state of the Rust engine's core (``core``): the core gives
        the common cases itself (``Engine.publish``, core/src/python/engine.rs)."""
        waiting = self._still_waiting(state.time)
        shown, unchanged = core.engine.publish(
            state,
            self._published,
            self._ids,
            waiting is None,
            self._next_id,
            waiting if waiting is not None else [],
        )
        self._published_core(shown, unchanged)

    def _published_core(
        self,
        shown: Mapping[int, VersionRef] | None,
        unchanged: tuple[dict[int, int], Published, int] | None,
    ) -> None:
        """The tables after the core's publishing (``Engine.publish``): ``unchanged``
        when it gave them, else ``shown``, the published world, for
        :meth:`_publish_changed`."""
        if unchanged is None:
            assert shown is not None
            self._publish_changed(shown)
        else:  # the published table's values are made if someone reads them
            self._ids, self._published, self._next_id = unchanged

    def _still_waiting(self, now: float | None) -> list[tuple[int, int]] | None:
        """The ids waiting for their objects (``(id, lineage)``) when each will still
        wait at ``now`` unless its object is shown again or an object new to the
        published world may take it (what the core's publishing checks): ``mht``, each
        already found able to return (:meth:`_returnable`), none waiting longer than
        ``id_memory``. ``None`` when :meth:`_publish_changed` must see them."""
        lost = self._lost
        if not lost:
            return []
        if not self._mhf.mht or now is None:
            return None
        memory = self._knowledge.world.id_memory
        returning = self._returning
        waiting = []
        for object_id, pub in lost.items():
            if now - pub.lost_at > memory or returning.get(id(pub)) is not pub:
                return None
            waiting.append((object_id, pub.lineage))
        return waiting

    def _publish_changed(self, current: Mapping[int, Track | VersionRef]) -> None:
        """:meth:`_publish` in general: ``current`` the published world now."""
        # new tables, changed below: the ones given out (a query's cached tables, the
        # held scans' chain) must not change under their holders
        self._ids, self._lost = dict(self._ids), dict(self._lost)
        state = self._state
        dim = self._knowledge.world.dimension
        alive = self._lineages(state)
        now = state.time if state.time is not None else 0.0
        memory = self._knowledge.world.id_memory
        for object_id, track in list(self._published.items()):
            if track.lineage not in current:
                self._lost[object_id] = _Lost(track, now)
        if self._mhf.mht:  # ids wait id_memory seconds for their object to come back
            self._lost = {
                i: p
                for i, p in self._lost.items()
                if now - p.lost_at <= memory and self._returnable(p)
            }
            returning = self._returning
            self._returning = {id(p): p for p in self._lost.values() if returning.get(id(p)) is p}
        else:  # paper: an id waits while its lineage lives (the MAP may switch back)
            self._lost = {
                i: p
                for i, p in self._lost.items()
                if p.lineage in alive and self._ids.get(p.lineage) == i
            }
        for lineage in current:
            held = self._ids.get(lineage)
            if held is not None:
                self._lost.pop(held, None)
        # a lineage shown again after a replay brought it back takes its own lost id
        # back; one shown under another id is not lost under the old one
        for object_id, pub in list(self._lost.items()):
            if pub.lineage in current:
                del self._lost[object_id]
                self._ids.setdefault(pub.lineage, object_id)
        fresh = [t for lineage, t in current.items() if lineage not in self._ids]
        if fresh and self._lost:
            self._hand_over(fresh, dim)
        for track in fresh:
            if track.lineage not in self._ids:
                self._ids[track.lineage] = self._next_id
                self._next_id += 1
        self._ids = {lineage: i for lineage, i in self._ids.items() if lineage in alive}
        self._published = {self._ids[lineage]: track for lineage, track in current.items()}

    def _publish_unchanged(self, current: Mapping[int, Track | VersionRef]) -> None:
        """:meth:`_publish` when no published object left and no id waits for its object
        (the common scan): what it gives then, without reading every lineage the state
        holds. Every lineage with an id is shown (so alive), and new ones take the next
        ids in the published world's order (no lost id to hand over)."""
        ids = self._ids
        fresh = [lineage for lineage in current if lineage not in ids]
        if fresh:
            ids = dict(ids)  # a new table: one a query cached must not change
            for lineage in fresh:
                ids[lineage] = self._next_id
                self._next_id += 1
            self._ids = ids
        self._published = {ids[lineage]: track for lineage, track in current.items()}

    def _returnable(self, pub: _Lost) -> bool:
        """:meth:`_may_return`, remembered for each lost id while the knowledge stays (it
        depends on nothing else): a lost id is tested once, not at every scan it
        waits."""
        if self._returning.get(id(pub)) is pub:
            return True
        if not self._may_return(pub):
            return False
        self._returning[id(pub)] = pub
        return True

    def _may_return(self, pub: _Lost) -> bool:
        """Whether a lost object may come back under its id (``mht``): not when it was
        lost out of the region or next to a target it leaves by (a disappearance
        relation: it left, and someone coming in there is someone else). The Rust
        engine's versions are tested in the core (``Engine.may_return``, the same rule:
        ``crate::world::may_return``)."""
        spec = self._knowledge.classes.get(pub.track.cls)
        if spec is None:
            return False
        core, version = self._mhf._core, pub.track
        if core is not None and not isinstance(version, Track):  # a version in the core
            return core.engine.may_return(version.state.core, version.key, version.cls)
        track = track_of(version)
        x, P = _summary_position(track, self._knowledge.world.dimension)
        region = self._knowledge.world.region
        margin = self._mhf.region_margins([track])
        if self._mhf.kernels.inside_probability(x[None], P[None], region, margin)[0] < 0.5:
            return False
        for relation in spec.disappearance:
            covered = self.taxonomy.covers(relation.target)
            for known in self._knowledge.known_objects:
                near = float(np.linalg.norm(x - np.asarray(known.position)))
                if known.cls in covered and near <= relation.max_distance:
                    return False
        return True

    def _hand_over(self, fresh_versions: list[Track | VersionRef], dim: int) -> None:
        """Lost ids go to fresh objects within the hand-over gate of the lost objects'
        predictions to now (lowest total Mahalanobis distance, Hungarian)."""
        fresh = [track_of(version) for version in fresh_versions]
        lost = list(self._lost.items())
        now = self._state.time if self._state.time is not None else 0.0
        predicted = self._mhf.predict(
            MHFState((), {i: track_of(pub.track) for i, (_, pub) in enumerate(lost)}, None, 0, {}),
            list(range(len(lost))),
            now,
        )
        cost = np.full((len(fresh), len(lost)), 1e9)
        for a, track in enumerate(fresh):
            x, P = _summary_position(track, dim)
            for b, (_, pub) in enumerate(lost):
                if not self.taxonomy.compatible(track.cls, pub.track.cls):
                    continue
                x_lost, P_lost = predicted.position[b], predicted.position_covariance[b]
                if not np.all(np.isfinite(P_lost)):
                    continue
                delta = x - x_lost
                d2 = float(delta @ np.linalg.solve(P + P_lost, delta))
                if d2 <= _HANDOVER_GATE:
                    cost[a, b] = d2
        rows, cols = linear_sum_assignment(cost)
        for a, b in zip(rows, cols, strict=True):
            if cost[a, b] < 1e9:
                object_id, pub = lost[b]
                if self._ids.get(pub.lineage) == object_id:  # not if it is shown anew
                    del self._ids[pub.lineage]
                self._ids[fresh[a].lineage] = object_id
                del self._lost[object_id]

    # ------------------------------------------------------------------ queries
    def _lineages(self, state: StateView) -> set[int]:
        """Every lineage ``state`` holds."""
        if isinstance(state, CoreState):
            return set(state.core.lineages())
        return {t.lineage for t in state.tracks.values()}

    def _current(self) -> Mapping[int, Track | VersionRef]:
        """The published world at the latest time: lineage -> version. ``mht``: objects
        whose existence is at least ``min_existence``; ``paper``: the MAP hypothesis.
        The Rust engine computes it in the core (``core/src/world.rs``)."""
        state = self._state
        core = self._mhf._core
        if core is not None and isinstance(state, CoreState) and state.engine is core:
            return core.current(state, self._published, self._ids)
        if not self._mhf.mht:
            tracks = state.tracks
            return {tracks[k].lineage: tracks[k] for k in sorted(state.best.tracks)}
        if state.time is None:
            return {}
        # existence at the latest time (the scan updated it); inside the region judged
        # from each version as stored (a version not updated by the scan is not
        # predicted: this decides ids only; queries predict)
        stored = self._stored_summaries(state.tracks)
        totals: dict[int, float] = {}
        chosen: dict[int, Track] = {}
        present_in: set[int] = set()
        floor = self._knowledge.world.min_existence
        existence = state.existence
        for cluster in state.clusters:
            # each version's probability mass: the sum over the hypotheses holding it
            mass: dict[int, float] = {}
            for h in cluster.hypotheses:  # most probable first
                p = math.exp(h.log_weight)
                for key in sorted(h.tracks):  # key order: it orders the ids given
                    mass[key] = mass.get(key, 0.0) + p
            for key, p in mass.items():  # in order of first appearance
                track = state.tracks[key]
                present = existence.get(key, 1.0) * stored[key][3]
                totals[track.lineage] = totals.get(track.lineage, 0.0) + p * present
                if present >= floor and track.lineage not in present_in:
                    present_in.add(track.lineage)  # see _marginals: not a stale version
                    chosen[track.lineage] = track
                chosen.setdefault(track.lineage, track)
        lineages = list(totals)
        dim = self._knowledge.world.dimension
        position = np.array([stored[chosen[lineage].key][1] for lineage in lineages]).reshape(
            -1, dim
        )
        covariance = np.array([stored[chosen[lineage].key][2] for lineage in lineages]).reshape(
            -1, dim, dim
        )
        merged = self._same_objects(
            {
                lineage: _Marginal(totals[lineage], chosen[lineage], row)
                for row, lineage in enumerate(lineages)
            },
            position,
            covariance,
        )
        return {lineage: m.track for lineage, m in merged.items() if m.existence >= floor}

    def _stored_summaries(
        self, tracks: Mapping[int, Track]
    ) -> dict[int, tuple[Track, FloatArray, FloatArray, float]]:
        """Key -> (version, combined position, its covariance, probability of being inside
        the region) of every stored version. Versions are immutable, so each is computed
        once, for the versions new since the last call (batched), and kept while stored."""
        previous = self._summaries
        current: dict[int, tuple[Track, FloatArray, FloatArray, float]] = {}
        new: list[Track] = []
        for key, track in tracks.items():
            known = previous.get(key)
            if known is not None and known[0] is track:
                current[key] = known
            else:
                new.append(track)
        if new:
            dim = self._knowledge.world.dimension
            position, covariance = _stored_positions(new, dim)
            inside = self._mhf.kernels.inside_probability(
                position, covariance, self._knowledge.world.region, self._mhf.region_margins(new)
            )
            for track, x, P, p in zip(
                new, list(position), list(covariance), inside.tolist(), strict=True
            ):
                current[track.key] = (track, x, P, p)
        self._summaries = current
        return current

    def _same_objects(
        self,
        marginals: dict[int, _Marginal],
        position: FloatArray,
        covariance: FloatArray,
    ) -> dict[int, _Marginal]:
        """One entry per physical object: lineages that are the same object in different
        hypotheses (their estimates nearly coincide, their classes are compatible, and
        the most probable hypothesis does not hold both as shown) are one object, whose
        existence is the sum of theirs (at most 1), shown as the lineage published now
        (stable ids), else the most likely one.

        Hypotheses that agree an object exists but not on which detection started it
        hold it under different lineages; without this, a 50/50 disagreement about
        identity would read as two objects of existence 0.5 each. Two lineages count as
        two objects only when each is shown in its version of the most probable
        hypothesis: one shown in another hypothesis's version (its own in the best one
        is leaving) may be the very object the best one calls by the other lineage
        (people who swapped lineages when they passed close by).
        """
        candidates = [lineage for lineage, m in marginals.items() if m.existence >= _GROUPING_FLOOR]
        if len(candidates) < 2:
            return marginals
        best_keys = self._state.best.tracks
        together = {lineage for lineage in candidates if marginals[lineage].track.key in best_keys}
        if len(together) == len(candidates):
            return marginals  # the most probable hypothesis holds each as shown: all distinct
        parent = {lineage: lineage for lineage in candidates}

        def root(lineage: int) -> int:
            while parent[lineage] != lineage:
                parent[lineage] = parent[parent[lineage]]
                lineage = parent[lineage]
            return lineage

        rows = np.array([marginals[lineage].row for lineage in candidates])
        x, P = position[rows], covariance[rows]
        # cheap bound first (d^2 <= gate * lambda_max(S) <= gate * trace(S)), then the
        # Mahalanobis distance of the pairs that pass it only
        spread = np.trace(P, axis1=1, axis2=2)
        if len(candidates) ** 2 > nearby.DENSE_PAIRS and nearby.usable(x, spread):
            # a k-d tree: the pairs the dense test below finds, in its order. A pair
            # within the bound is within sqrt(2 gate s) of the one with more spread s.
            aa, bb = nearby.close_pairs(x, np.sqrt(2.0 * _SAME_OBJECT_GATE * spread))
            pair_delta = x[aa] - x[bb]
            near = (pair_delta * pair_delta).sum(-1) <= _SAME_OBJECT_GATE * (
                spread[aa] + spread[bb]
            )
            aa, bb, pair_delta = aa[near], bb[near], pair_delta[near]
        else:
            delta = x[:, None, :] - x[None, :, :]
            near = (delta * delta).sum(-1) <= _SAME_OBJECT_GATE * (
                spread[:, None] + spread[None, :]
            )
            aa, bb = np.nonzero(near)
            upper = aa < bb  # each pair once
            aa, bb = aa[upper], bb[upper]
            pair_delta = delta[aa, bb]
        if aa.size == 0:
            return marginals  # no two estimates near each other: each is one object
        close = _coinciding(pair_delta, P[aa], P[bb])
        if not close.any():
            return marginals
        for a, b in zip(aa[close].tolist(), bb[close].tolist(), strict=True):
            first, second = candidates[int(a)], candidates[int(b)]
            if first in together and second in together:
                continue  # the most probable hypothesis holds both: two objects
            if not self.taxonomy.compatible(
                marginals[first].track.cls, marginals[second].track.cls
            ):
                continue
            parent[root(first)] = root(second)
        groups: dict[int, list[int]] = {}
        for lineage in candidates:
            groups.setdefault(root(lineage), []).append(lineage)
        result = dict(marginals)
        for members in groups.values():
            if len(members) == 1:
                continue
            # shown as a member that already has an id (stable ids), one shown in its
            # version of the most probable hypothesis first (not one that is there only
            # by another hypothesis's account), else the likeliest (existences within
            # TIE of the largest are a tie: the oldest lineage, not rounding, decides)
            shown = _shown_lineages(self._published)
            with_id = [m for m in members if m in shown]
            if with_id:
                best = min(with_id, key=lambda m: (m not in together, self._ids.get(m, 0)))
            else:
                top = max(marginals[m].existence for m in members)
                best = min(m for m in members if marginals[m].existence >= top - TIE)
            total = min(1.0, math.fsum(marginals[m].existence for m in members))
            for member in members:
                del result[member]
            result[best] = marginals[best]._replace(existence=total)
        return result

    def _as_of(self, at: float) -> tuple[StateView, BookView]:
        """The state and confidences as they were at ``at`` (s): the current ones from the
        newest scan on; before it, the ones after the last scan at or before ``at``, from
        the reorder history. Raises :class:`BeforeHistoryError` when the history does not
        reach back that far."""
        state = self._state
        if state.time is None or at >= state.time - 1e-9:
            return state, self._book
        if self._earliest is not None and at < self._earliest:  # before anything was seen
            return MHFState.empty(), ConfidenceBook()
        log = self._log
        later = bisect_right(log, at, key=lambda scan: scan.key[0])  # first scan after at
        if later == len(log):  # no scan logged after ``at``: the log is empty
            raise BeforeHistoryError(at, None, state.time)
        before = log[later].before
        if later == 0 and before.time is not None and before.time > at:
            raise BeforeHistoryError(at, before.time, state.time)
        return before, log[later].book

    def _marginals(
        self, at: float, state: StateView | None = None
    ) -> tuple[dict[int, _Marginal], Predicted]:
        """Every object's marginal existence at ``at`` and its most probable version, in
        ``state`` (default: the current one)."""
        state = self._state if state is None else state
        keys = list(state.tracks)
        predicted = self._mhf.predict(state, keys, at)
        if self._mhf.mht:
            future = at if state.time is not None and at > state.time else state.time or at
            # past the last scan no scan has missed anything: objects only leave at
            # their leave rates (no missed-detection term, no weight changes)
            existence, _ = self._mhf.existence_at(state, predicted, future)
            clusters: tuple[Cluster, ...] = state.clusters
            # Python floats: the sums below stay floats (numpy scalars are slower, and
            # made the published existence an np.float64 when it was below 1)
            inside = self._mhf.inside(predicted).tolist()
        else:
            existence = dict.fromkeys(keys, 1.0)
            clusters = state.clusters
            inside = [1.0] * len(keys)
        row = {k: i for i, k in enumerate(keys)}
        floor = self._knowledge.world.min_existence
        gone = self._mhf.leaving(predicted, at, existence if self._mhf.mht else None)
        result: dict[int, _Marginal] = {}
        for cluster in clusters:
            totals: dict[int, float] = {}
            chosen: dict[int, Track] = {}
            present_in: set[int] = set()
            for h in cluster.hypotheses:  # most probable first
                p = math.exp(h.log_weight)
                for key in h.tracks:
                    if key in gone:
                        continue
                    track = state.tracks[key]
                    lineage = track.lineage
                    present = existence[key] * inside[row[key]]
                    totals[lineage] = totals.get(lineage, 0.0) + p * present
                    # shown in the most probable hypothesis's version in which it is
                    # present (existence in the region >= min_existence), not in a
                    # stale version that left the region long ago
                    if present >= floor and lineage not in present_in:
                        present_in.add(lineage)
                        chosen[lineage] = track
                    chosen.setdefault(lineage, track)
            for lineage, total in totals.items():
                if lineage not in result or result[lineage].existence < total:
                    track = chosen[lineage]
                    result[lineage] = _Marginal(min(1.0, total), track, row[track.key])
        return result, predicted

    def world(
        self,
        time: float | None = None,
        cls: str | None = None,
        near: Sequence[float] | None = None,
        label: str | None = None,
        min_existence: float | None = None,
        confidence: str | Iterable[str] | None = None,
    ) -> WorldState:
        """The objects of the world, predicted to ``time`` (s).

        ``mht``: every object whose existence probability (over the whole hypothesis
        set, :class:`_Marginal`) is at least ``min_existence`` (default: the
        knowledge's ``world.min_existence``), in the version of the most probable
        hypothesis that holds it: a near tie between hypotheses does not make an
        object flicker. ``paper``: the maximum a posteriori hypothesis's objects.
        Objects created after ``time`` are not listed.

        Parameters
        ----------
        cls
            Only objects of this class or its subclasses (``Can`` covers ``CokeCan``).
        near
            ``(x, y, r)`` or ``(x, y, z, r)``: only objects within ``r`` metres.
        label
            Only objects carrying this label.
        min_existence
            Only objects at least this likely to exist (``0 < min_existence <= 1``).
        confidence
            Only objects in this confidence state (``valid``, ``suspicious``,
            ``invalid``) or these states (paper 004 Fig. 5; ``mht`` only).
        """
        if self._pending:  # every accepted detection included, nothing committed
            with self._including_pending():
                return self.world(time, cls, near, label, min_existence, confidence)
        dim = self._knowledge.world.dimension
        if cls is not None and cls not in self._knowledge.classes:
            known = ", ".join(sorted(self._knowledge.classes))
            raise ValueError(f"unknown class {cls!r}; known classes: {known}")
        if near is not None and len(near) != dim + 1:
            raise ValueError(f"near needs {dim} coordinates and a radius; got {len(near)} values")
        if min_existence is not None and not 0.0 < min_existence <= 1.0:
            raise ValueError(f"min_existence must be in (0, 1]; got {min_existence}")
        floor = min_existence if min_existence is not None else self._knowledge.world.min_existence
        wanted = {confidence} if isinstance(confidence, str) else confidence
        states = set(wanted) if wanted is not None else None
        if states is not None and not states <= set(CONFIDENCE_STATES):
            bad = sorted(states - set(CONFIDENCE_STATES))
            raise ValueError(
                f"unknown confidence state {bad[0]!r}; known: {', '.join(CONFIDENCE_STATES)}"
            )
        at = time if time is not None else self._state.time
        if at is None or not math.isfinite(at):
            return WorldState(time=at, objects=())
        state, book = self._as_of(at)
        if state.time is None:  # before the first scan
            return WorldState(time=at, objects=())
        core = self._mhf._core
        if (
            core is not None
            and type(state) is CoreState
            and state.engine is core
            and type(self._state) is CoreState
        ):
            # paper: the best hypothesis's objects, whatever their existence
            floor = floor if self._mhf.mht else 0.0
            asked = _new_tuple(_Asked, (floor, cls, near, label, states))  # _Asked(...)
            found = self._core_world(state, book, at, asked)
            # WorldState(time=at, objects=...), one per query
            return made_without_init(
                WorldState, {"time": at, "objects": tuple(_unique_labels(found))}
            )
        asked = _Asked(floor, cls, near, label, states)
        if len(state.tracks) <= _UNPAUSED_QUERY:
            found = self._spec_world(state, book, at, asked)
        else:
            with collector_paused():  # many objects made, none in a cycle
                found = self._spec_world(state, book, at, asked)
        # WorldState(time=at, objects=...), one per query
        return made_without_init(WorldState, {"time": at, "objects": tuple(_unique_labels(found))})

    def _spec_world(
        self,
        state: StateView,
        book: BookView,
        at: float,
        asked: _Asked,
    ) -> list[WorldObject]:
        """:meth:`world`'s objects from the state's Python values (the Python engine's
        path, the specification of :meth:`_core_world`), in id order."""
        floor, cls, near, label, states = asked
        dim = self._knowledge.world.dimension
        marginals, predicted = self._marginals(at, state)
        if self._mhf.mht:
            marginals = self._same_objects(
                marginals, predicted.position, predicted.position_covariance
            )
        if not self._mhf.mht:
            best = {state.tracks[k].lineage for k in state.best.tracks}
            marginals = {lineage: m for lineage, m in marginals.items() if lineage in best}
            floor = 0.0
        covered = self.taxonomy.covers(cls) if cls is not None else None
        objects = []
        # Python floats of every row at once (float() of each numpy scalar was most of
        # a large world's query time)
        rows = predicted.position.tolist(), predicted.position_covariance.tolist()
        for marginal in marginals.values():
            track, i = marginal.track, marginal.row
            if marginal.existence < floor or track.created > at + 1e-9:
                continue
            if covered is not None and track.cls not in covered:
                continue
            if label is not None and track.label != label:
                continue
            position = predicted.position[i]
            if (
                near is not None
                and float(np.linalg.norm(position - np.asarray(near[:dim]))) > near[dim]
            ):
                continue
            mean = predicted.state_mean[i]
            obj = self._world_object(
                track,
                marginal.existence,
                at,
                (tuple(rows[0][i]), tuple(map(tuple, rows[1][i]))),
                tuple(mean[dim : 2 * dim].tolist()) if mean.shape[0] > dim else None,
                predicted.mu[i].tolist(),
                book,
            )
            if states is not None and (
                obj.confidence is None or obj.confidence.state not in states
            ):
                continue
            objects.append(obj)
        objects.sort(key=_id_of)
        return objects

    def _core_world(
        self,
        state: CoreState,
        book: BookView,
        at: float,
        asked: _Asked,
    ) -> list[WorldObject]:
        """:meth:`world`'s objects, their marginals, the most probable version of each
        and its prediction to ``at`` made in the core (``Engine.world_at``:
        :meth:`_marginals` and, ``mht``, :meth:`_same_objects` there; ``paper``, the
        most probable hypothesis's objects), in id order."""
        core = self._mhf._core
        assert core is not None and isinstance(self._state, CoreState)
        if state.track_count <= _UNPAUSED_QUERY:
            return self._core_objects(core.engine, state, book, at, asked)
        # the core's rows are Python values too, several containers a row: made with the
        # collector paused as well (semwm.collector)
        with collector_paused():  # many objects made, none in a cycle
            return self._core_objects(core.engine, state, book, at, asked)

    def _core_objects(
        self,
        engine: Any,
        state: CoreState,
        book: BookView,
        at: float,
        asked: _Asked,
    ) -> list[WorldObject]:
        """:meth:`_core_world`'s objects, in id order: each one's values as
        :meth:`_world_object` makes them, made in the core (``Engine.world_at``) but
        for its confidence's state; its confidence carried to ``at`` there too when the
        core holds the book."""
        held = book.core if type(book) is CoreBook else None
        rows = engine.world_at(
            state, self._state, at, self._published, self._ids, held, TENTATIVE_IDS, SHOWN_FLOOR
        )
        floor, cls, near, label, states = asked
        covered = self.taxonomy.covers(cls) if cls is not None else None
        dim = self._knowledge.world.dimension
        classes = self._knowledge.classes if self._mhf.mht else None
        objects = []
        for lineage, existence, created, position, fields, value in rows:
            if not existence >= floor or created > at + 1e-9:
                continue
            if covered is not None and fields["cls"] not in covered:
                continue
            if label is not None and fields["label"] != label:
                continue
            if (
                near is not None
                and float(np.linalg.norm(np.asarray(position) - np.asarray(near[:dim]))) > near[dim]
            ):
                continue
            if classes is not None:  # mht: the confidence (confidence_of)
                spec = classes[fields["cls"]]
                if value is None:  # a book the core does not hold
                    value = book.at(lineage, at, spec)
                state_now = state_of(value, spec)
                if states is not None and state_now not in states:
                    continue
                # Confidence(value, state_now)
                fields["confidence"] = made_without_init(
                    Confidence, {"value": value, "state": state_now}
                )
            elif states is not None:  # paper: no confidence, so none in a state asked for
                continue
            objects.append(made_without_init(WorldObject, fields))  # WorldObject(**fields)
        objects.sort(key=_id_of)
        return objects

    def rate_report(self) -> list[StreamReport]:
        """Per source and detector, the clutter and detection rates its data shows beside
        the knowledge's, with a warning where they differ by more than 3x
        (:meth:`semwm.mhf.rates.ObservedRates.report`)."""
        return self._state.observed.report(self._knowledge)

    def object(self, object_id: int, time: float | None = None) -> WorldObject | None:
        """One object of the world by its id, or ``None``. A tentative id
        (:data:`~semwm.world_types.TENTATIVE_IDS`) finds its object while it is tentative,
        and under its published id once it is published."""
        if object_id > TENTATIVE_IDS:
            lineage = object_id - TENTATIVE_IDS - 1
            if self._pending:
                with self._including_pending():
                    published = self._ids.get(lineage)
            else:
                published = self._ids.get(lineage)
            wanted = published if published is not None else object_id
            objects = self.world(time, min_existence=_TENTATIVE_FLOOR).objects
            return next((o for o in objects if o.id == wanted), None)
        return next((o for o in self.world(time).objects if o.id == object_id), None)

    def _world_object(
        self,
        track: Track,
        existence: float,
        at: float,
        position: tuple[tuple[float, ...], tuple[tuple[float, ...], ...]],
        velocity: tuple[float, ...] | None,
        mu: Sequence[float],
        book: BookView | None = None,
    ) -> WorldObject:
        """The object ``track`` shows at ``at``: ``position`` its predicted position and
        covariance, ``velocity`` its predicted velocity (``None`` for a filter without
        one), ``mu`` its mode probabilities; ``book``: the confidences to read
        (default: the current ones)."""
        flt = self._mhf.factory.filter_for(track.cls)
        modes = None
        if flt.modes > 1:
            modes = dict(zip(flt.mode_names, mu, strict=True))
        object_id = self._ids.get(track.lineage)
        tentative = object_id is None
        if object_id is None:
            # below the publishing threshold and asked for (min_existence): a tentative
            # id, TENTATIVE_IDS + 1 + the number of the detection that started it.
            # Queries change nothing, so a replay of the same detections publishes the
            # same ids.
            object_id = TENTATIVE_IDS + 1 + track.lineage
        mht = self._mhf.mht
        return made_without_init(  # WorldObject(...), one per object of every query
            WorldObject,
            {
                "id": object_id,
                "cls": track.cls,
                "label": track.label,
                "position": position[0],
                "velocity": velocity,
                "covariance": position[1],
                "existence": min(1.0, existence),
                "last_seen": track.last_seen,
                "created": track.created,
                "mode_probabilities": modes,
                "class_probabilities": (
                    self._mhf.associator.class_model.as_dict(track.class_probs) if mht else None
                ),
                "confidence": self.confidence_of(track, at, book) if mht else None,
                "tentative": tentative,
            },
        )

    def confidence_of(self, track: Track, time: float, book: BookView | None = None) -> Confidence:
        """An object's confidence (paper 004) at ``time``: :mod:`semwm.confidence`."""
        spec = self._knowledge.classes[track.cls]
        value = (self._book if book is None else book).at(track.lineage, time, spec)
        # Confidence(value, state), one per object of every query
        return made_without_init(Confidence, {"value": value, "state": state_of(value, spec)})

    def hypotheses(self, k: int = 10) -> list[HypothesisSummary]:
        """The ``k`` most probable hypotheses with their probabilities and objects:
        :meth:`HypothesesView.best` of :meth:`hypotheses_view`."""
        if k < 1:
            raise ValueError(f"k must be at least 1; got {k}")
        return self.hypotheses_view().best(k)

    def hypotheses_view(self) -> HypothesesView:
        """What :meth:`hypotheses` reads, taken now: the state (immutable: a scan makes
        a new one) and a copy of the public ids. Held scans (:attr:`hold`) are
        included, as in every query. Its :meth:`HypothesesView.best` does the search
        and builds the answer without the model, so a service takes the view under
        its lock and does the rest after (issue 30: a read never holds the world
        longer than a scan)."""
        if self._pending:  # every accepted detection included, nothing committed
            with self._including_pending():
                view = self.hypotheses_view()
            return replace(view, committed=self._state)
        return HypothesesView(
            self._state, dict(self._ids), self._knowledge.world.dimension, self._state
        )


@dataclass(frozen=True)
class HypothesesView:
    """The hypotheses of a world model at one moment (:meth:`WorldModel.hypotheses_view`).

    ``state`` is the MHF state queries answer from (held scans included),
    ``committed`` the processed one the counts are of (they are the same without a
    hold); both are immutable, and ``ids`` (lineage -> public id) is this view's own
    copy, so nothing the model does later changes the view.
    """

    state: StateView
    ids: Mapping[int, int]
    dimension: int
    committed: StateView

    @property
    def hypothesis_count(self) -> int:
        """:attr:`WorldModel.hypothesis_count` at the view's moment."""
        return self.committed.hypothesis_count

    @property
    def cluster_count(self) -> int:
        """:attr:`WorldModel.cluster_count` at the view's moment."""
        return self.committed.cluster_count

    @property
    def log10_joint_hypotheses(self) -> float:
        """:attr:`WorldModel.log10_joint_hypotheses` at the view's moment."""
        return self.committed.log10_joint_count

    def best(self, k: int = 10) -> list[HypothesisSummary]:
        """The ``k`` most probable hypotheses with their probabilities and objects.

        k-best of the product of the clusters' sorted hypothesis lists, best first. A
        global hypothesis is the best one with some clusters moved to a lower rank,
        written as its changes ``((position, rank), ...)`` over the clusters that have
        alternatives, ordered by the cost of their first step down (``position`` in
        that order). Each combination has one parent, and at most three children,
        none more probable than it: the last change one rank lower; a change at the
        next position; a last change of rank 1 moved to the next position (its step
        costs no less, by the order). So a best-first search pops them in order with
        work O(C + k (log k + n)) for C clusters and n objects, not O(k C): only the
        ``k + 1`` cheapest first steps are ever sorted (issue 30: ``limit=1000`` over
        2,822 clusters took 110 s).
        """
        if k < 1:
            raise ValueError(f"k must be at least 1; got {k}")
        state = self.state
        dim = self.dimension
        best = state.best
        steps = [
            (c.hypotheses[0].log_weight - c.hypotheses[1].log_weight, index)
            for index, c in enumerate(state.clusters)
            if len(c.hypotheses) > 1
        ]
        multi = [state.clusters[i].hypotheses for _, i in heapq.nsmallest(k + 1, steps)]
        first_step = [h[0].log_weight - h[1].log_weight for h in multi]
        found: list[tuple[float, frozenset[int]]] = []
        heap: list[tuple[float, int, tuple[tuple[int, int], ...]]] = [(-best.log_weight, 0, ())]
        counter = 0
        while heap and len(found) < k:
            negative, _, changes = heapq.heappop(heap)
            tracks = set(best.tracks)
            for position, rank in changes:
                tracks -= multi[position][0].tracks
                tracks |= multi[position][rank].tracks
            found.append((-negative, frozenset(tracks)))
            children: list[tuple[float, tuple[tuple[int, int], ...]]] = []
            last = changes[-1][0] if changes else -1
            if changes:
                position, rank = changes[-1]
                options = multi[position]
                if rank + 1 < len(options):  # the last change one rank lower
                    step = options[rank].log_weight - options[rank + 1].log_weight
                    children.append((negative + step, (*changes[:-1], (position, rank + 1))))
                if rank == 1 and position + 1 < len(multi):  # moved to the next position
                    step = first_step[position + 1] - first_step[position]
                    children.append((negative + step, (*changes[:-1], (position + 1, 1))))
            if last + 1 < len(multi):  # a change at the next position
                children.append((negative + first_step[last + 1], (*changes, (last + 1, 1))))
            for weight, child in children:
                counter += 1
                heapq.heappush(heap, (weight, counter, child))
        positions: dict[int, tuple[float, ...]] = {}  # each version's position, once
        summaries = []
        for log_weight, keys in found:
            objects = []
            for key in sorted(keys):
                track = state.tracks[key]
                x = positions.get(key)
                if x is None:
                    x = positions[key] = tuple(float(v) for v in _summary_position(track, dim)[0])
                objects.append(
                    HypothesisObject(
                        id=self.ids.get(track.lineage),
                        track=track.lineage,
                        cls=track.cls,
                        label=track.label,
                        position=x,
                        existence=state.existence.get(key, 1.0),
                    )
                )
            summaries.append(
                HypothesisSummary(
                    probability=math.exp(log_weight),
                    log10_probability=log_weight / math.log(10.0),
                    objects=tuple(objects),
                )
            )
        return summaries


def _remap_classes(state: StateView, old: tuple[str, ...], new: tuple[str, ...]) -> MHFState:
    """Carry every version's class distribution over to a changed class list: mass on a
    class that is gone is dropped, a new class starts at 0 (renormalised)."""
    state = as_python(state)  # new Python values (either engine)
    if old == new:
        return state
    source = {name: i for i, name in enumerate(old)}
    columns = [source.get(name) for name in new]

    def remap(track: Track) -> Track:
        probs = np.array([track.class_probs[i] if i is not None else 0.0 for i in columns])
        total = float(probs.sum())
        if total <= 0.0:
            probs = np.array([1.0 if name == track.cls else 0.0 for name in new])
            total = float(probs.sum()) or 1.0
        return replace(track, class_probs=probs / total)

    tracks = {key: remap(track) for key, track in state.tracks.items()}
    return replace(state, tracks=tracks)


def _coinciding(delta: FloatArray, Pa: FloatArray, Pb: FloatArray) -> npt.NDArray[np.bool_]:
    """Whether pairs of Gaussian position estimates are one object: their
    Bhattacharyya distance is at most ``_SAME_OBJECT_GATE / 4``.

    .. math::
       4 D_B = \\delta^T (P_a + P_b)^{-1} \\delta
               + 2 \\ln \\frac{\\det \\tfrac{1}{2}(P_a + P_b)}{\\sqrt{\\det P_a \\det P_b}}

    With equal covariances the log term is 0 and this is the Mahalanobis test of the
    means. The log term (>= 0) keeps an estimate that has lost its object (a covariance
    of tens of metres, under which every estimate nearby is "within the gate") from
    being taken for a well-localised one: they are not the same distribution.

    ``delta`` ``(M, d)``: ``x_a - x_b``; ``Pa``, ``Pb`` ``(M, d, d)``.
    """
    total = Pa + Pb
    d2 = mahalanobis_squared(delta, total)
    _, log_det_mean = np.linalg.slogdet(0.5 * total)
    _, log_det_a = np.linalg.slogdet(Pa)
    _, log_det_b = np.linalg.slogdet(Pb)
    spread = 2.0 * log_det_mean - log_det_a - log_det_b  # 2 ln(det S / sqrt(det Pa det Pb))
    result: npt.NDArray[np.bool_] = d2 + spread <= _SAME_OBJECT_GATE
    return result


def _unique_labels(objects: list[WorldObject]) -> list[WorldObject]:
    """A label names one object of the world: where two carry it, the more likely (then
    the more recently seen) keeps it and the other is listed without a label."""
    holder: dict[str, WorldObject] = {}
    for obj in objects:
        if obj.label is None:
            continue
        other = holder.get(obj.label)
        if other is None or (obj.existence, obj.last_seen) > (other.existence, other.last_seen):
            holder[obj.label] = obj
    return [
        o if o.label is None or holder[o.label] is o else replace(o, label=None) for o in objects
    ]
