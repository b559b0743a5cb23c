"""The world model behind one lock: what the routes talk to.

:class:`WorldService` owns the :class:`semwm.WorldModel` of the process. Every
call that reads or changes it takes the same lock, so concurrent requests are
applied one after the other and a read sees a consistent snapshot (every
detection acknowledged before it, none half-applied). Domain errors become
:mod:`api.errors` values with HTTP field paths; the routes only translate.
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections import OrderedDict
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from contextlib import AbstractContextManager, ExitStack, contextmanager, nullcontext
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Generic, Literal, Protocol, TypeVar, cast

from pydantic import ValidationError

from api.errors import (
    ApiError,
    ConflictError,
    InvalidError,
    KnowledgeFileError,
    Loc,
    NotFoundError,
    Overloaded,
    StorageUnavailable,
    validation_items,
)
from api.ordered_lock import TimeOrderedLock
from api.stages import stage
from semwm import IngestResult, WorldModel, load_knowledge
from semwm.clock import Exchange
from semwm.detection import (
    BeforeHistoryError,
    Detection,
    DetectionError,
    DetectionProblem,
    OutOfOrderError,
    SensorReport,
)
from semwm.knowledge import ClassSpec, Knowledge, KnowledgeDocument, KnowledgeError, resolve
from semwm.mhf.rates import StreamReport
from semwm.persistence.records import (
    Record,
    action_record,
    batch_record,
    knowledge_record,
    reset_record,
)
from semwm.sources import (
    DEFAULT_ORDER_TOLERANCE,
    Placement,
    SourceRegistry,
    SourceStatus,
    Span,
    TimeGuard,
    TimeGuardError,
    plain_span,
)
from semwm.team import LocalModel
from semwm.validation import ClassesHeld
from semwm.world import IgnoredDetection
from semwm.world_types import HypothesisSummary, WorldObject, WorldState

T = TypeVar("T")
logger = logging.getLogger("api")


@dataclass(frozen=True)
class WorldChange:
    """A change applied to the world, as told to the listeners of a :class:`WorldService`.

    Attributes
    ----------
    kind
        ``"detections"`` (a batch was applied), ``"reset"``, ``"knowledge"`` (a class
        edit or a reload) or ``"action"`` (a kick, paper 004).
    detections
        The applied batch as :meth:`semwm.WorldModel.ingest` took it (``"detections"`` only).
    applied, ignored
        Detections used, and accepted but beyond their detector's range.
    time
        The world time after the change (s).
    seconds
        Wall-clock time the change took under the lock (s).
    """

    kind: Literal["detections", "reset", "knowledge", "action"]
    detections: tuple[Mapping[str, Any], ...] = ()
    applied: int = 0
    ignored: int = 0
    time: float | None = None
    seconds: float = 0.0
    ignored_detections: tuple[IgnoredDetection, ...] = ()


ChangeListener = Callable[[WorldChange], None]
"""Called after each committed change, under the service's lock: keep it short (queue, count).
Unlike a :class:`ChangeHook` it cannot refuse the change; it only hears of it."""


class WorldBusy(Exception):
    """Nothing was done, because it would have meant waiting and the caller chose not to:
    the world's lock is taken (or, for :func:`api.routes.detections.apply_json`, the body
    needs its full check first). Do it again where waiting is allowed."""


COMMIT_HEADER = "X-Semwm-Commit"
"""The response header numbering accepted changes 1, 2, ... in the order they were applied."""


@dataclass(frozen=True)
class Committed(Generic[T]):
    """What a change of the world returned, with its place in the commit order.

    ``commit`` numbers the accepted changes of the service 1, 2, ... in the order they
    were applied; ``replayed`` is true when an idempotency key had been seen and the
    earlier answer is given again (nothing was applied).
    """

    value: T
    commit: int
    replayed: bool = False
    dropped: bool = False  # a late scan of a 'late: drop' source: nothing applied


def _save(model: WorldModel) -> dict[str, Any]:
    """The model's attributes, with top-level containers copied: enough to restore it.

    The tracking state itself is immutable; only the model's own dicts and lists are
    changed in place, so a shallow copy of each restores the model exactly.
    """
    return {
        name: value.copy() if isinstance(value, dict | list | set) else value
        for name, value in vars(model).items()
    }


def _restore(model: WorldModel, saved: dict[str, Any]) -> None:
    vars(model).clear()
    vars(model).update(saved)


def _save_object(obj: object) -> dict[str, Any]:
    """An object's attributes, top-level containers copied (as :func:`_save`)."""
    return {
        name: value.copy() if isinstance(value, dict | list | set) else value
        for name, value in vars(obj).items()
    }


def _restore_object(obj: object, saved: dict[str, Any]) -> None:
    vars(obj).clear()
    vars(obj).update(saved)


def known_list(names: Sequence[str]) -> str:
    return ", ".join(sorted(names)) or "none"


def detection_loc(path: Sequence[str | int], batch: bool) -> Loc:
    """The HTTP field path of a :class:`DetectionProblem` path (relative to the batch)."""
    if path and path[0] == "sensor":
        return ("body", *path)
    if batch:
        return ("body", "detections", *path)
    rest = tuple(path[1:]) if path and path[0] == 0 else tuple(path)
    return ("body", *rest)


def problems_to_items(
    problems: Sequence[DetectionProblem], batch: bool, index: Sequence[int] | None = None
) -> list[dict[str, Any]]:
    """Detection problems as 422 items; ``index`` maps positions of a sub-batch back."""
    items = []
    for problem in problems:
        path = list(problem.path)
        if index is not None and path and isinstance(path[0], int) and path[0] < len(index):
            path[0] = index[path[0]]
        items.append(
            {"loc": list(detection_loc(path, batch)), "msg": problem.message, "type": "detection"}
        )
    return items


class ChangeHook(Protocol):
    """Told of every change around its application (journal, recorder)."""

    def applying(self, record: Record) -> AbstractContextManager[None]:
        """Wraps the code that applies ``record``; the body raising means it was refused."""
        ...


class WorldService:
    """A :class:`WorldModel` shared by every request, with its knowledge file.

    Parameters
    ----------
    model
        The world model (built by the app's lifespan, or by a test).
    knowledge_path
        The file the knowledge came from: what ``POST /knowledge/reload`` re-reads
        and write-back writes. ``None`` when the knowledge was built in code.
    write_back
        Write accepted class edits to ``knowledge_path``.
    time_guard
        Bounds on detection times (:class:`semwm.sources.TimeGuard`).
    order_tolerance
        Scans of different sources at most this many seconds older than the newest
        processed scan are processed in arrival order, their time moved just after it,
        instead of replayed (:mod:`semwm.sources`; 0: strict time order). Not with a
        hold (it orders them itself).
    clock
        The service clock (s); detections of synced sources are placed on it.
    """

    def __init__(
        self,
        model: WorldModel,
        knowledge_path: Path | None = None,
        write_back: bool = False,
        *,
        max_sources: int = 1000,
        idempotency_keys: int = 1024,
        stuck_after: float = 30.0,
        time_guard: TimeGuard | None = None,
        order_tolerance: float = DEFAULT_ORDER_TOLERANCE,
        clock: Callable[[], float] = time.time,
    ) -> None:
        if not (math.isfinite(order_tolerance) and order_tolerance >= 0.0):
            raise ValueError(f"order_tolerance must be a finite number >= 0; got {order_tolerance}")
        self._model = model
        self._lock = TimeOrderedLock()  # queued scans enter in time order: no replay
        self.knowledge_path = knowledge_path
        self.write_back = write_back
        self.max_sources = max_sources
        self.idempotency_keys = idempotency_keys
        self.stuck_after = stuck_after
        self._commit = 0
        self._busy_since: float | None = None
        self._failure: str | None = None
        self._sources: set[str] = set()
        self._recent: OrderedDict[str, Committed[IngestResult]] = OrderedDict()
        self._warned_ignored: set[tuple[str | None, str]] = set()
        self._summary = self._summarise()
        self.hooks: list[ChangeHook] = []
        self._listeners: list[ChangeListener] = []
        self.knowledge_version = 1
        self.sources = SourceRegistry(time_guard)
        self.order_tolerance = order_tolerance
        self.arrival_order_scans = 0  # scans placed in arrival order (since start or reset)
        self._sources_lock = threading.Lock()  # taken inside self._lock, never around it
        self.clock = clock
        self._locals: dict[str, LocalModel] = {}  # two levels: robots' local models
        self._storage_problem: str | None = None  # the store refused the last write
        self.storage_probe: Callable[[], bool] | None = None  # can the store write again?
        self.retry_after = 5  # s: Retry-After of a write the store refused
        self.storage_refusals = 0
        self.max_waiting = 64  # writes queued for the world beyond which new ones get 503
        self.hypothesis_objects = 100_000  # the most objects one GET /hypotheses lists
        self.shed = 0  # writes refused so (since start)
        # late scans refused (409) instead of replayed while replays took more than
        # replay_limit of the last replay_window s (issue 30: a replay storm)
        self.replay_limit = 0.1
        self.replay_window = 1.0  # s
        self.shed_late = 0
        self._replaying = 0.0  # the share of time spent replaying, as of _replaying_at
        self._replaying_at = time.monotonic()
        self.dropped_late = 0  # scans of 'late: drop' sources dropped (since start)
        # the damage the data directory's last start found: problems, [first, last] lost
        self.store_damage: tuple[list[str], list[int] | None] | None = None

    def use_model(self, model: WorldModel) -> None:
        """Serve ``model`` from now on (the one a data directory restored)."""
        with self._locked():
            self._model = model
            self._summary = self._summarise()

    @property
    def engine(self) -> str:
        """The engine the served model runs (``python`` or ``rust``); no lock needed."""
        return self._model.engine

    @property
    def model(self) -> WorldModel:
        """The world model, without the lock: for hooks, which run with it held."""
        return self._model

    @contextmanager
    def _hooked(self, record: Record) -> Iterator[None]:
        """Apply a change inside every hook's ``applying`` (inside :meth:`_change`).

        A store that cannot write (:class:`~semwm.persistence.journal.WriteFailed`: a
        full disk...) refuses the change: 507 or 503 with ``Retry-After``; nothing was
        stored and :meth:`_change` undoes it in memory. ``/ready`` says so until the
        store can write again (:attr:`storage_probe`) or a write succeeds."""
        if not self.hooks:
            yield
            return
        from semwm.persistence.journal import WriteFailed

        try:
            with ExitStack() as stack:
                for hook in self.hooks:
                    stack.enter_context(hook.applying(record))
                yield
        except WriteFailed as error:
            what = "the data directory's disk is full" if error.full else "the store failed"
            self._storage_problem = f"{what}: writes are refused ({error})"
            self.storage_refusals += 1
            raise StorageUnavailable(
                f"{what}: the change was not applied and nothing of it was stored ({error}); "
                f"reads are served; retry after {self.retry_after} s",
                full=error.full,
                retry_after=self.retry_after,
            ) from None
        self._storage_problem = None

    # -- listeners ----------------------------------------------------------------------------

    def add_listener(self, listener: ChangeListener) -> Callable[[], None]:
        """Call ``listener`` after every committed change; returns a function removing it.

        Listeners run under the lock, so they see changes in the order they were
        committed; one that raises is logged and does not undo the change.
        """
        with self._lock.ordered():
            self._listeners.append(listener)

        def remove() -> None:
            with self._lock.ordered():
                if listener in self._listeners:
                    self._listeners.remove(listener)

        return remove

    def _notify(self, change: WorldChange) -> None:
        for listener in list(self._listeners):
            try:
                listener(change)
            except Exception:
                logger.exception("a world change listener failed")

    def _knowledge_replaced(self) -> None:
        """Count a new knowledge version and tell the listeners (hold the lock)."""
        self.knowledge_version += 1
        self._notify(WorldChange("knowledge", time=self._model.latest_time))

    @classmethod
    def from_file(
        cls,
        path: Path,
        reorder_window: float = 0.5,
        write_back: bool = False,
        hold: float = 0.0,
        engine: str | None = None,
        **options: Any,
    ) -> WorldService:
        """Load ``path`` and build the world model (raises :class:`KnowledgeError`, and
        :class:`~semwm.filters.engine.EngineUnavailable` for ``engine="rust"`` without
        the extension)."""
        return cls(
            WorldModel(
                load_knowledge(path), reorder_window=reorder_window, hold=hold, engine=engine
            ),
            path,
            write_back,
            **options,
        )

    # -- the lock and the commit order ----------------------------------------------------------

    @contextmanager
    def _locked(self, order: float = -math.inf, wait: bool = True) -> Iterator[None]:
        """Hold the world's lock, noting since when (for ``/ready``). Waiters enter by
        smallest ``order`` (a scan's time; others ``-inf``): :class:`TimeOrderedLock`.
        ``wait`` false: raise :class:`WorldBusy` at once if the lock is taken."""
        with stage("lock"):
            if wait:
                self._lock.acquire(order)
            elif not self._lock.try_acquire():
                raise WorldBusy
        try:
            self._busy_since = time.monotonic()
            try:
                yield
            finally:
                self._busy_since = None
        finally:
            self._lock.release()

    def replay_share(self, now: float | None = None) -> float:
        """The share of recent time the world spent replaying scans (an older scan came
        after them): an exponentially weighted average over :attr:`replay_window` s
        (1 = replaying all the time). Above :attr:`replay_limit` the service is behind
        and late scans are refused, not replayed (:meth:`_refuse_late_if_behind`).

        .. math:: u(t) = \\frac{1}{\\tau} \\int_{-\\infty}^{t} r(s)\\, e^{-(t - s) / \\tau}\\, ds

        with :math:`\\tau` = :attr:`replay_window` and :math:`r(s)` 1 while replaying.
        """
        elapsed = (time.monotonic() if now is None else now) - self._replaying_at
        return self._replaying * math.exp(-max(elapsed, 0.0) / self.replay_window)

    def _count_replay(self, seconds: float, now: float | None = None) -> None:
        """Add ``seconds`` of replaying that ended ``now`` to :meth:`replay_share`."""
        now = time.monotonic() if now is None else now
        tau = self.replay_window
        self._replaying = self.replay_share(now) + (1.0 - math.exp(-seconds / tau))
        self._replaying_at = now

    @contextmanager
    def _change(self) -> Iterator[None]:
        """One change of the model, applied whole or not at all (hold :meth:`_locked`).

        Any exception (a refusal or a bug) restores the model as it was before, so a
        failed request changes nothing; a bug is remembered for ``/ready``. A change
        that completes gets the next commit number.
        """
        with stage("save"):
            saved = _save(self._model)
            sources = set(self._sources)
        try:
            yield
        except BaseException as error:
            _restore(self._model, saved)
            self._sources = sources
            if not isinstance(error, ApiError):
                self._failure = f"{type(error).__name__} in the last change; it was undone"
            raise
        self._commit += 1
        self._failure = None
        with stage("notify"):
            self._summary = self._summarise()

    def _scan_order(
        self,
        detections: Sequence[Detection | dict[str, Any]],
        sensor: dict[str, Any] | None,
        span: Span | None = None,
    ) -> float:
        """A batch's place among queued ones: its earliest time on the service clock
        (with today's clock offsets; only the order of entry depends on it).
        ``span``: the batch's :func:`~semwm.sources.plain_span`, if known."""
        earliest: dict[str | None, float] = {}  # per source: placing keeps the order
        if span is not None:  # a plain batch: every time a finite number
            earliest = {source: first for source, (first, _, _) in span.items()}

        def note(source: str | None, t: Any) -> None:
            # a time the model will refuse (not a number, infinite) does not jump ahead
            if isinstance(t, int | float) and not isinstance(t, bool) and math.isfinite(t):
                known = earliest.get(source)
                if known is None or t < known:
                    earliest[source] = t

        for d in detections if span is None else ():
            if type(d) is dict:  # the common case, without a call per detection
                source, t = d.get("source"), d.get("time")
                if type(t) is float and t - t == 0.0:  # finite
                    known = earliest.get(source)
                    if known is None or t < known:
                        earliest[source] = t
                    continue
            else:
                source, t = _stamp(d)
            note(source, t)
        if sensor is not None:
            note(sensor.get("source", _first_source(detections)), sensor.get("time"))
        with self._sources_lock:
            times = [self.sources.to_service_time(source, t) for source, t in earliest.items()]
        return min(times, default=-math.inf)

    def _summarise(self) -> dict[str, Any]:
        return {
            "time": self._model.latest_time,
            "hypotheses": self._model.hypothesis_count,
            "hypotheses_log10_joint": self._model.log10_joint_hypotheses,
            "objects": self._model.object_count,
            "commit": self._commit,
        }

    # -- detections ---------------------------------------------------------------------------

    def ingest(
        self,
        detections: Sequence[dict[str, Any]],
        batch: bool,
        key: str | None = None,
        sensor: dict[str, Any] | None = None,
        wait: bool = True,
        owned: bool = False,
    ) -> Committed[IngestResult]:
        """Apply ``detections`` whole, or raise :class:`InvalidError`/:class:`ConflictError`.

        ``key`` (an idempotency key): a key seen among the recent ones is answered as
        the first time, and nothing is applied again. ``wait`` false: raise
        :class:`WorldBusy` (nothing applied) rather than wait for the world's lock.
        ``owned``: the dicts are the service's own (made from a request's body), so the
        journal, the listeners and the model keep them as they are; else each is copied,
        as the caller may change its dicts afterwards.
        """
        with stage("service"):  # api.stages: the request's time in the service by stage
            self._shed_if_behind()
            with stage("sources"):
                span = plain_span(detections)  # once: ordering and placing both need it
                order = self._scan_order(detections, sensor, span)
            with self._locked(order, wait):
                return self._ingest_locked(detections, batch, key, sensor, owned, span)

    def _shed_if_behind(self) -> None:
        """503 with Retry-After when ``max_waiting`` writes already wait for the world:
        a queue that long means the service fell behind, and waiting longer would only
        make their scans late (replayed, or refused as too old: a storm, issue 30)."""
        waiting = self._lock.waiting
        if waiting >= self.max_waiting:
            self.shed += 1
            raise Overloaded(
                f"the service is behind: {waiting} requests wait for the world (the bound is "
                f"{self.max_waiting}); nothing was applied; retry after 1 s, or drop late "
                'scans (PUT /sources/NAME/policy {"late": "drop"})',
                retry_after=1,
            )

    def _ingest_locked(
        self,
        detections: Sequence[dict[str, Any]],
        batch: bool,
        key: str | None = None,
        sensor: dict[str, Any] | None = None,
        owned: bool = False,
        span: Span | None = None,
    ) -> Committed[IngestResult]:
        """:meth:`ingest` with the world's lock held (``span``: the batch's
        :func:`~semwm.sources.plain_span`, if known)."""
        if key is not None and key in self._recent:
            self._recent.move_to_end(key)
            earlier = self._recent[key]
            return Committed(earlier.value, earlier.commit, replayed=True)
        now = self.clock()
        try:
            with stage("sources"), self._sources_lock:
                in_order = self._model.hold == 0
                placement = self.sources.place(
                    list(detections),
                    now,
                    newest=self._model.processed_time if in_order else None,
                    tolerance=self.order_tolerance,
                    newest_source=self._model.processed_source if in_order else None,
                    span=span,
                )
                if sensor is not None and sensor.get("time") is not None:
                    owner = sensor.get("source", _first_source(detections))
                    placed_time = self.sources.to_service_time(owner, sensor["time"])
                    if isinstance(placed_time, int | float) and not isinstance(placed_time, bool):
                        placed_time = placement.moved.get(
                            (owner or None, float(placed_time)), placed_time
                        )
                    sensor = {**sensor, "time": placed_time}
        except TimeGuardError as error:
            raise InvalidError(_time_items(error, batch)) from error
        with stage("sources"):
            late = self._late_by(placement)  # once: both checks below need it
            late_to_drop = self._late_to_drop(placement, late)
        if late_to_drop:
            with self._sources_lock:
                self.sources.dropped(placement)
            self.dropped_late += 1
            dropped = IngestResult(applied=0, time=self._model.latest_time)
            return Committed(dropped, self._commit, dropped=True)
        with stage("sources"):
            self._refuse_late_if_behind(placement, late)
            # the world model takes the checked values as they are (no second validation of
            # every detection); the journal keeps their plain form
            placed: list[dict[str, Any]] = []
            values: list[Detection | dict[str, Any]] = []
            # a plain span: every detection a dict (placing keeps them dicts)
            if owned and (span is not None or all(type(d) is dict for d in placement.detections)):
                placed = cast(list[dict[str, Any]], list(placement.detections))
                values = cast(list[Detection | dict[str, Any]], placed)
            else:
                for d in placement.detections:
                    if isinstance(d, Detection):
                        placed.append(d.to_dict())
                        values.append(d)
                    else:
                        plain = dict(d)
                        placed.append(plain)
                        values.append(plain)
        if sensor is not None:
            _check_sensor(sensor)  # before the journal writes it (issue 30)
        started = time.perf_counter()
        with self._change():
            with stage("sources"):
                self._check_sources(placed, batch, placement.counts)
            try:
                # the record (a copy of every detection) only for hooks that take it
                hooked = self._hooked(batch_record(placed, sensor)) if self.hooks else nullcontext()
                with hooked:
                    replayed, began = self._model.replayed_scans, time.perf_counter()
                    with stage("model"):
                        result = self._model.ingest(values, sensor=sensor)
                    replayed = self._model.replayed_scans - replayed
                    if replayed > 0:  # its share of the time: the scans it processed again
                        took = time.perf_counter() - began
                        self._count_replay(took * replayed / (replayed + 1))
            except DetectionError as error:
                raise InvalidError(problems_to_items(error.problems, batch)) from error
            except OutOfOrderError as error:
                message = f"{error}; nothing was applied"
                with self._sources_lock:
                    self.sources.late(placement, message)
                unsynced = sorted(
                    str(s) for s in placement.counts if s is not None and not self._synced(s)
                )
                hint = (
                    f" (unsynced source(s) {', '.join(unsynced)}: sync their clocks with "
                    "POST /sources/NAME/sync, see GET /sources)"
                    if unsynced
                    else ""
                )
                raise ConflictError(message + hint) from error
        with stage("sources"), self._sources_lock:
            self.sources.accepted(placement, now)
        self._warn_ignored(result.ignored_detections)
        self.arrival_order_scans += len(placement.moved)
        if self._listeners:
            with stage("notify"):
                self._notify(
                    WorldChange(
                        "detections",
                        tuple(placed),
                        applied=result.applied,
                        ignored=result.ignored,
                        ignored_detections=result.ignored_detections,
                        time=result.time,
                        seconds=time.perf_counter() - started,
                    )
                )
        committed = Committed(result, self._commit)
        if key is not None and self.idempotency_keys > 0:
            self._recent[key] = committed
            while len(self._recent) > self.idempotency_keys:
                self._recent.popitem(last=False)
        return committed

    def _late_to_drop(self, placement: Placement, late: float | None) -> bool:
        """Whether a batch is late (older than the newest scan processed: it would be
        replayed, or refused) and every source of it asked for late scans to be
        dropped (``PUT /sources/NAME/policy {"late": "drop"}``). ``late``: its
        :meth:`_late_by`."""
        if late is None:
            return False
        with self._sources_lock:
            return all(self.sources.drops_late(s) for s in placement.counts)

    def _late_by(self, placement: Placement) -> float | None:
        """How much older than the newest scan processed a placed batch's earliest
        detection is (s), ``None`` when it is not (or under a hold, which orders scans
        itself): a late batch makes the world replay every scan after it."""
        newest = self._model.processed_time
        if newest is None or self._model.hold != 0 or not placement.counts:
            return None
        earliest = placement.earliest
        return newest - earliest if earliest < newest else None

    def _refuse_late_if_behind(self, placement: Placement, late: float | None) -> None:
        """409 at once for a late batch (it would be replayed) while the service is
        behind: replays took more than :attr:`replay_limit` of the last
        :attr:`replay_window` s. Nothing is applied; the source's ``late`` counts it.

        A replay redoes every scan after the late one, so under load each late scan
        costs more than the scans that made it late, the service falls further behind
        and more scans come late: a storm (issue 30; measured again with one core taken
        and robots that queue late frames: 14,991 scans replayed, 365 det/s
        acknowledged of 1,500, the robots 30 s behind after a 30 s run; now 783, 965
        det/s and 0.07 s: benchmarks/results/teamload_overload.md). While behind, the reorder
        window is in effect the order tolerance: a scan that is late is as final a
        409 as one beyond the window. Not a 503 with ``Retry-After``: a late scan sent
        again later is later still, and a robot that waits ``Retry-After`` before each
        of its queued scans falls further behind the others, whose scans then make all
        of its own too late (20 s trials, one core taken: 73 % 409 and 173 det/s with a
        503, 39 % and 918 det/s with this 409). ``late``: the batch's :meth:`_late_by`."""
        if late is None or late > self._model.reorder_window:
            return  # in order; or beyond the window, where the model's 409 says so
        share = self.replay_share()
        if share <= self.replay_limit:
            return
        self.shed_late += 1
        message = (
            f"the service is behind (replays took {100 * share:.0f} % of the last "
            f"{self.replay_window:g} s, more than {100 * self.replay_limit:.0f} %): this batch "
            f"is {1000 * late:.1f} ms older than the newest scan processed and is not "
            "replayed while the service is behind; nothing was applied. Send scans in time "
            'order, or drop late scans (PUT /sources/NAME/policy {"late": "drop"})'
        )
        with self._sources_lock:
            self.sources.late(placement, message)
        raise ConflictError(message)

    def _check_sources(
        self, detections: Sequence[dict[str, Any]], batch: bool, sources: Iterable[str | None]
    ) -> None:
        """Hold at most ``max_sources`` distinct sources (422 for a new one beyond).
        ``sources``: the batch's (its placement's counts), found without a pass over it."""
        new = {s for s in sources if s} - self._sources
        if len(self._sources) + len(new) > self.max_sources:
            first = next(i for i, d in enumerate(detections) if d.get("source") in new)
            raise InvalidError.one(
                (*detection_loc([first, "source"], batch),),
                f"the service holds at most {self.max_sources} distinct sources and has "
                f"{len(self._sources)}; a new source is refused (reset to start again)",
            )
        self._sources |= new

    def _synced(self, name: str) -> bool:
        clock = self.sources.clock(name)
        return clock is not None and clock.synced

    # -- two levels (paper 000) ----------------------------------------------------------------

    def local_ingest(self, robot: str, detections: Sequence[dict[str, Any]], batch: bool) -> int:
        """Apply ``detections`` to robot ``robot``'s local model (its own clock), then send
        its report (objects updated since the last one) to the global model. Returns the
        objects reported.

        All or nothing (issue 30): a refusal of the batch or of its report (422, 409)
        leaves the local model as it was (a new robot keeps none) and the global one
        unchanged. A new robot counts as a source: beyond ``max_sources`` it is refused
        (422) and keeps nothing, so local models are bounded and go with a reset."""
        with self._locked():
            local = self._locals.get(robot)
            if local is None:
                self._check_new_robot(robot)
                local = LocalModel(robot, self._model.knowledge, detector=None)
            saved_local, saved_model = _save_object(local), _save(local.model)
            try:
                try:
                    local.ingest(list(detections))
                except DetectionError as error:
                    raise InvalidError(problems_to_items(error.problems, batch)) from error
                except OutOfOrderError as error:
                    raise ConflictError(
                        f"{error} (local model of {robot!r}); nothing was applied"
                    ) from error
                report = local.report()
                reported = 0
                if report is not None:
                    try:
                        self._ingest_locked(list(report.detections), batch=True)
                    except ConflictError as error:
                        raise ConflictError(
                            f"the report of robot {robot!r}'s local model: {error.message}"
                        ) from error
                    reported = len(report.detections)
            except BaseException:
                _restore(local.model, saved_model)
                _restore_object(local, saved_local)
                raise
            self._locals[robot] = local
            return reported

    def _check_new_robot(self, robot: str) -> None:
        """A robot without a local model may start one while the sources have room."""
        sources = self._sources | set(self._locals)
        if robot not in sources and len(sources) >= self.max_sources:
            raise InvalidError.one(
                ("path", "robot"),
                f"the service holds at most {self.max_sources} distinct sources and local "
                f"models and has {len(sources)}; a new robot is refused (reset to start again)",
            )

    def local_world(self, robot: str, time: float | None = None) -> WorldState:
        with self._locked():
            local = self._locals.get(robot)
            if local is None:
                raise NotFoundError(
                    f"no local model for robot {robot!r}; robots: {known_list(list(self._locals))}"
                )
            try:
                return local.world(time)
            except ValueError as error:
                raise InvalidError.one(("query", "time"), str(error)) from error

    # -- sources ------------------------------------------------------------------------------

    def sync(self, name: str, exchange: Exchange) -> SourceStatus:
        """Add a finished sync exchange of source ``name`` (422 naming a bad time)."""
        with self._sources_lock:
            return self.sources.sync(name, exchange)

    def set_late_policy(self, name: str, late: str) -> SourceStatus:
        """Source ``name``'s scans older than the newest processed one: ``replay`` them
        (the default; older than the reorder window: 409) or ``drop`` them (200,
        nothing applied, header ``X-Semwm-Dropped: late``)."""
        with self._sources_lock:
            known = len(self.sources.statuses())
            if self.sources.status(name) is None and known >= self.max_sources:
                raise InvalidError.one(
                    ("path", "name"),
                    f"the service holds at most {self.max_sources} sources and has {known}",
                )
            return self.sources.set_late_policy(name, late)

    def source_statuses(self) -> list[SourceStatus]:
        with self._sources_lock:
            return self.sources.statuses()

    def rate_report(self) -> list[StreamReport]:
        """The rates the sources' data shows beside the knowledge's (per source and
        detector; :meth:`semwm.WorldModel.rate_report`)."""
        with self._locked():
            return self._model.rate_report()

    def domain_problems(
        self, detections: Sequence[dict[str, Any]], index: Sequence[int], batch: bool
    ) -> list[dict[str, Any]]:
        """The domain problems of detections that passed the schema (nothing is applied)."""
        if not detections:
            return []
        with self._locked():
            try:
                self._model.validate(list(detections))
            except DetectionError as error:
                return problems_to_items(error.problems, batch, index)
            except ValueError:
                return []
        return []

    # -- queries ------------------------------------------------------------------------------

    def _check_class(self, cls: str | None) -> None:
        if cls is not None and cls not in self._model.knowledge.classes:
            known = known_list(list(self._model.knowledge.classes))
            raise InvalidError.one(
                ("query", "class"), f"unknown class {cls!r}; known classes: {known}"
            )

    def _warn_ignored(self, ignored: Sequence[IgnoredDetection]) -> None:
        """Log the first ignored detection of each source and reason once, at WARNING,
        with its hint: it is usually a unit or frame mistake, and nothing else says so."""
        for item in ignored:
            key = (item.source, item.reason)
            if key in self._warned_ignored:
                continue
            self._warned_ignored.add(key)
            logger.warning(
                "source %r: a detection was ignored (%s): %s; later ones are counted in "
                "/metrics (semwm_detections_ignored_total) and listed in each answer",
                item.source,
                item.reason,
                item.message,
            )

    def world(
        self,
        time: float | None = None,
        cls: str | None = None,
        near: tuple[float, ...] | None = None,
        label: str | None = None,
        min_existence: float | None = None,
        confidence: Sequence[str] | None = None,
    ) -> WorldState:
        with self._locked():
            self._check_class(cls)
            if near is not None and len(near) - 1 != self._model.knowledge.dimension:
                dim = self._model.knowledge.dimension
                raise InvalidError.one(
                    ("query", "near"),
                    f"near must be {dim + 1} numbers (a {dim}-d centre and a radius); "
                    f"found {len(near)}",
                )
            try:
                return self._model.world(
                    time=time,
                    cls=cls,
                    near=near,
                    label=label,
                    min_existence=min_existence,
                    confidence=confidence,
                )
            except BeforeHistoryError as error:
                raise ConflictError(str(error)) from error
            except ValueError as error:
                raise InvalidError.one(("query",), str(error)) from error

    def object(self, object_id: int, time: float | None = None) -> WorldObject:
        with self._locked():
            try:
                found = self._model.object(object_id, time=time)
            except BeforeHistoryError as error:
                raise ConflictError(str(error)) from error
            except ValueError as error:
                raise InvalidError.one(("query", "time"), str(error)) from error
        if found is None:
            raise NotFoundError(f"no object with id {object_id} in the world")
        return found

    def hypotheses(self, limit: int) -> tuple[dict[str, Any], list[HypothesisSummary]]:
        """The counts (stored, clusters, log10 of the joint), the limit applied and the
        best hypotheses.

        Each hypothesis lists every object it holds, so the answer's size grows with
        ``limit`` times the objects: the limit applied is lowered so that the answer
        lists at most :attr:`hypothesis_objects` objects (issue 30; the search itself
        costs the same for any number of clusters). Under the world's lock only the
        view is taken (:meth:`WorldModel.hypotheses_view`: references to the immutable
        state and a copy of the public ids, less than a scan's publishing); the counts,
        the search and the answer are made after, while scans go on."""
        with self._locked():
            objects = max(1, self._model.object_count)
            view = self._model.hypotheses_view()
        applied = max(1, min(limit, self.hypothesis_objects // objects))
        counts = {
            "total": view.hypothesis_count,
            "clusters": view.cluster_count,
            "log10_joint": view.log10_joint_hypotheses,
            "limit": applied,
        }
        return counts, view.best(applied)

    def health(self) -> dict[str, Any]:
        """A summary of the world as of the last commit; never waits for the lock."""
        damage = self.store_damage
        return {
            "status": "ok",
            "engine": self.engine,
            "knowledge": str(self.knowledge_path) if self.knowledge_path else None,
            **self._summary,
            "store_damage": damage[0] if damage else None,
            "lost_records": damage[1] if damage else None,
        }

    def stats(self) -> dict[str, Any]:
        """Counts for monitoring: objects, stored hypotheses, clusters, knowledge version..."""
        with self._locked():
            return {
                "time": self._model.latest_time,
                "objects": self._model.object_count,
                "hypotheses": self._model.hypothesis_count,
                "hypotheses_log10_joint": self._model.log10_joint_hypotheses,
                "clusters": self._model.cluster_count,
                "tracks": self._model.track_count,
                "held_scans": self._model.pending_scans,
                "replayed_scans": self._model.replayed_scans,
                "arrival_order_scans": self.arrival_order_scans,
                "knowledge_version": self.knowledge_version,
            }

    def readiness(self) -> list[str]:
        """Why the service cannot take requests now (empty: ready); never waits."""
        reasons = []
        since = self._busy_since
        if since is not None and time.monotonic() - since > self.stuck_after:
            reasons.append(
                f"one request has held the world for {time.monotonic() - since:.1f} s "
                f"(more than {self.stuck_after:g} s)"
            )
        if self._failure is not None:
            reasons.append(self._failure)
        problem = self._storage_problem
        if problem is not None:
            probe = self.storage_probe
            if probe is not None and probe():
                self._storage_problem = None  # space returned: writes will go through
            else:
                reasons.append(problem)
        return reasons

    def act(self, action: dict[str, Any]) -> Committed[tuple[list[int], int]]:
        """Apply an action (paper 004: a kick); 422 or 409 and nothing changed on a refusal.
        Journaled like a batch (``--data-dir``, ``--record``)."""
        with self._locked():
            with self._change():
                try:
                    with self._hooked(action_record(action)):
                        moved = self._model.act(action)
                except DetectionError as error:
                    raise InvalidError(
                        [
                            {"loc": ["body", *p.path], "msg": p.message, "type": "action"}
                            for p in error.problems
                        ]
                    ) from error
                except OutOfOrderError as error:
                    raise ConflictError(f"{error}; nothing was applied") from error
            self._notify(WorldChange("action", time=self._model.latest_time))
            return Committed((moved, self._model.hypothesis_count), self._commit)

    def reset(self) -> Committed[float | None]:
        with self._locked():
            with self._change(), self._hooked(reset_record()):
                self._model.reset()
                self.arrival_order_scans = 0
                self._sources = set()
                self._locals = {}
                with self._sources_lock:
                    self.sources.forget_times()
            self._notify(WorldChange("reset", time=self._model.latest_time))
            return Committed(self._model.latest_time, self._commit)

    def digest(self, also: Callable[[], T] | None = None) -> tuple[str, T | None]:
        """The digest of the world published now (:func:`semwm.persistence.model_digest`),
        and ``also()`` called under the same lock (a consistent view of both)."""
        from semwm.persistence.replay import model_digest

        with self._locked():
            return model_digest(self._model), also() if also is not None else None

    # -- knowledge ----------------------------------------------------------------------------

    @property
    def knowledge(self) -> Knowledge:
        with self._locked():
            return self._model.knowledge

    def class_view(self, name: str) -> tuple[Knowledge, ClassSpec]:
        """The knowledge and the spec of class ``name`` (404 listing the known ones)."""
        knowledge = self.knowledge
        for spec in knowledge.document.classes:
            if spec.name == name and name in knowledge.classes:
                return knowledge, spec
        raise NotFoundError(
            f"unknown class {name!r}; known classes: {known_list(list(knowledge.classes))}"
        )

    def put_class(self, name: str, spec: ClassSpec) -> Committed[tuple[Knowledge, bool]]:
        """Replace or add class ``name``; applied from the next detection.

        The new document is resolved like a file; problems become a 422 and nothing
        changes. Returns the new knowledge and whether it was written back.
        """
        if spec.name != name:
            raise InvalidError.one(
                ("body", "name"),
                f"the class name in the body ({spec.name!r}) differs from the one in the path "
                f"({name!r})",
            )
        with self._locked():
            with self._change():
                document = self._model.knowledge.document
                classes = list(document.classes)
                where = next((i for i, c in enumerate(classes) if c.name == name), None)
                if where is None:
                    where = len(classes)
                    classes.append(spec)
                else:
                    classes[where] = spec
                new_document = KnowledgeDocument.model_validate(
                    {**dict(document), "classes": tuple(classes)}
                )
                source = self._model.knowledge.source
                try:
                    knowledge = resolve(new_document, source)
                except KnowledgeError as error:
                    raise InvalidError(
                        [_knowledge_item(p.path, p.message, where) for p in error.problems]
                    ) from error
                written = False
                with self._hooked(knowledge_record(knowledge)):
                    self._replace_knowledge(knowledge, "the edit")
                    if self.write_back and self.knowledge_path is not None:
                        self._write_back(new_document, self.knowledge_path)
                        written = True
            self._knowledge_replaced()
            return Committed((knowledge, written), self._commit)

    def _replace_knowledge(self, knowledge: Knowledge, what: str) -> None:
        """Use ``knowledge``; 409 if tracked objects hold a class it lacks (the model
        checks per cluster: :meth:`WorldModel.replace_knowledge`)."""
        try:
            self._model.replace_knowledge(knowledge, refuse_held=True)
        except ClassesHeld as error:
            named = "; ".join(
                f"{cls} (objects {', '.join(str(i) for i in sorted(i for i in ids if i))}"
                f"{' and unpublished ones' if None in ids else ''})"
                for cls, ids in sorted(error.held.items())
            )
            raise ConflictError(
                f"{what} removes classes that tracked objects hold: {named}; nothing changed. "
                "Keep these classes, or POST /reset first"
            ) from None
        except ValueError as error:
            raise ConflictError(f"{what} conflicts with the tracked objects: {error}") from None

    @staticmethod
    def _write_back(document: KnowledgeDocument, path: Path) -> None:
        """Write ``document`` to ``path`` atomically; a failure is a 409, nothing changed."""
        from semwm.knowledge.loader import dump_document

        try:
            dump_document(document, path)
        except OSError as error:
            raise ConflictError(
                f"cannot write the knowledge file {path} ({error.strerror or error}); "
                "the edit was not applied"
            ) from None

    def reload(self) -> Committed[Knowledge]:
        """Re-read the knowledge file; a broken file leaves the running knowledge as it is."""
        path = self.knowledge_path
        if path is None:
            raise ConflictError("this service has no knowledge file to reload")
        try:
            knowledge = load_knowledge(path)
        except KnowledgeError as error:
            raise KnowledgeFileError(
                f"{path} has {len(error.problems)} problem(s); the running knowledge is unchanged",
                [str(p) for p in error.problems],
            ) from error
        except OSError as error:
            raise KnowledgeFileError(
                f"cannot read {path}; the running knowledge is unchanged",
                [f"{path}: {error.strerror or error}"],
            ) from error
        with self._locked():
            with self._change(), self._hooked(knowledge_record(knowledge)):
                self._replace_knowledge(knowledge, "the reloaded knowledge")
            self._knowledge_replaced()
            return Committed(knowledge, self._commit)


def _time_items(error: TimeGuardError, batch: bool) -> list[dict[str, Any]]:
    """Time-guard refusals as 422 items at each detection's ``time``."""
    return [
        {"loc": list(detection_loc((p.index, "time"), batch)), "msg": p.message, "type": p.kind}
        for p in error.problems
    ]


def _knowledge_item(path: Sequence[str | int], message: str, index: int) -> dict[str, Any]:
    """A knowledge problem as a 422 item: inside the edited class, relative to the body."""
    parts = list(path)
    if len(parts) >= 2 and parts[0] == "classes" and parts[1] == index:
        loc: list[str | int] = ["body", *parts[2:]]
    else:
        loc = ["knowledge", *parts]
    return {"loc": loc, "msg": message, "type": "knowledge", "path": parts}


def _check_sensor(sensor: Mapping[str, Any]) -> None:
    """A sensor view's values (finite pose...), checked before anything journals them:
    422 at ``["body", "sensor", ...]``."""
    try:
        SensorReport.model_validate(sensor)
    except ValidationError as error:
        raise InvalidError(validation_items(error.errors(), ("body", "sensor"))) from None


def _first_source(detections: Sequence[dict[str, Any] | Detection]) -> str | None:
    """The source of a batch's first detection (a sensor view's default source)."""
    for d in detections:
        source = d.source if isinstance(d, Detection) else d.get("source")
        return source if isinstance(source, str) else None
    return None


def _stamp(d: dict[str, Any] | Detection) -> tuple[str | None, Any]:
    """A detection's (source, time) as sent."""
    if isinstance(d, Detection):
        return d.source, d.time
    return d.get("source"), d.get("time")
