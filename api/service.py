"""The world model behind one lock: what the routes talk to.

:class:`WorldService` owns the :class:`semwm.WorldModel` of the process. Every
call that reads or changes it takes the same lock, so concurrent requests are
applied one after the other and a read sees a consistent snapshot (every
detection acknowledged before it, none half-applied). Domain errors become
:mod:`api.errors` values with HTTP field paths; the routes only translate.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Iterator, Sequence
from contextlib import AbstractContextManager, ExitStack, contextmanager
from pathlib import Path
from typing import Any, Protocol, TypeVar

from api.errors import ConflictError, InvalidError, KnowledgeFileError, Loc, NotFoundError
from semwm import IngestResult, WorldModel, load_knowledge
from semwm.clock import Exchange
from semwm.detection import Detection, DetectionError, DetectionProblem, OutOfOrderError
from semwm.knowledge import ClassSpec, Knowledge, KnowledgeDocument, KnowledgeError, resolve
from semwm.persistence.records import Record, batch_record, knowledge_record, reset_record
from semwm.sources import SourceRegistry, SourceStatus, TimeGuard, TimeGuardError
from semwm.team import LocalModel
from semwm.world_types import HypothesisSummary, WorldObject, WorldState

T = TypeVar("T")


def known_list(names: Sequence[str]) -> str:
    return ", ".join(sorted(names)) or "none"


def detection_loc(path: Sequence[str | int], batch: bool) -> Loc:
    """The HTTP field path of a :class:`DetectionProblem` path (relative to the batch)."""
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
    clock
        The service clock (s); detections of synced sources are placed on it.
    """

    def __init__(
        self,
        model: WorldModel,
        knowledge_path: Path | None = None,
        write_back: bool = False,
        *,
        time_guard: TimeGuard | None = None,
        clock: Callable[[], float] = time.time,
    ) -> None:
        self._model = model
        self._lock = threading.Lock()
        self.knowledge_path = knowledge_path
        self.write_back = write_back
        self.hooks: list[ChangeHook] = []
        self.sources = SourceRegistry(time_guard)
        self._sources_lock = threading.Lock()  # taken inside self._lock, never around it
        self.clock = clock
        self._locals: dict[str, LocalModel] = {}  # two levels: robots' local models

    def use_model(self, model: WorldModel) -> None:
        """Serve ``model`` from now on (the one a data directory restored)."""
        with self._lock:
            self._model = model

    @property
    def model(self) -> WorldModel:
        """The world model, without the lock: for hooks, which run with it held."""
        return self._model

    @contextmanager
    def _change(self, record: Record) -> Iterator[None]:
        """Apply a change inside every hook's ``applying`` (call with the lock held)."""
        with ExitStack() as stack:
            for hook in self.hooks:
                stack.enter_context(hook.applying(record))
            yield

    @classmethod
    def from_file(
        cls,
        path: Path,
        reorder_window: float = 0.5,
        write_back: bool = False,
        time_guard: TimeGuard | None = None,
    ) -> WorldService:
        """Load ``path`` and build the world model (raises :class:`KnowledgeError`)."""
        return cls(
            WorldModel(load_knowledge(path), reorder_window=reorder_window),
            path,
            write_back,
            time_guard=time_guard,
        )

    # -- detections ---------------------------------------------------------------------------

    def ingest(self, detections: Sequence[dict[str, Any]], batch: bool) -> IngestResult:
        """Apply ``detections`` whole, or raise :class:`InvalidError`/:class:`ConflictError`."""
        with self._lock:
            now = self.clock()
            try:
                with self._sources_lock:
                    placement = self.sources.place(list(detections), now)
            except TimeGuardError as error:
                raise InvalidError(_time_items(error, batch)) from error
            try:
                placed = [
                    d.to_dict() if isinstance(d, Detection) else dict(d)
                    for d in placement.detections
                ]
                with self._change(batch_record(placed)):
                    result = self._model.ingest(placed)
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
            with self._sources_lock:
                self.sources.accepted(placement, now)
            return result

    def _synced(self, name: str) -> bool:
        clock = self.sources.clock(name)
        return clock is not None and clock.synced

    # -- two levels (paper 000) ----------------------------------------------------------------

    def local_ingest(self, robot: str, detections: Sequence[dict[str, Any]], batch: bool) -> int:
        """Apply ``detections`` to robot ``robot``'s local model (its own clock), then send
        its report (objects updated since the last one) to the global model. Returns the
        objects reported."""
        with self._lock:
            local = self._locals.get(robot)
            if local is None:
                local = LocalModel(robot, self._model.knowledge, detector=None)
            try:
                local.ingest(list(detections))
            except DetectionError as error:
                raise InvalidError(problems_to_items(error.problems, batch)) from error
            except OutOfOrderError as error:
                raise ConflictError(
                    f"{error} (local model of {robot!r}); nothing was applied"
                ) from error
            self._locals[robot] = local
            report = local.report()
        if report is None:
            return 0
        self.ingest(list(report.detections), batch=True)
        return len(report.detections)

    def local_world(self, robot: str, time: float | None = None) -> WorldState:
        with self._lock:
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

    def source_statuses(self) -> list[SourceStatus]:
        with self._sources_lock:
            return self.sources.statuses()

    def domain_problems(
        self, detections: Sequence[dict[str, Any]], index: Sequence[int], batch: bool
    ) -> list[dict[str, Any]]:
        """The domain problems of detections that passed the schema (nothing is applied)."""
        if not detections:
            return []
        with self._lock:
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

    def world(
        self,
        time: float | None = None,
        cls: str | None = None,
        near: tuple[float, ...] | None = None,
        label: str | None = None,
        min_existence: float | None = None,
    ) -> WorldState:
        with self._lock:
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
                    time=time, cls=cls, near=near, label=label, min_existence=min_existence
                )
            except ValueError as error:
                raise InvalidError.one(("query",), str(error)) from error

    def object(self, object_id: int, time: float | None = None) -> WorldObject:
        with self._lock:
            try:
                found = self._model.object(object_id, time=time)
            except ValueError as error:
                raise InvalidError.one(("query", "time"), str(error)) from error
        if found is None:
            raise NotFoundError(f"no object with id {object_id} in the world")
        return found

    def hypotheses(self, limit: int) -> tuple[dict[str, Any], list[HypothesisSummary]]:
        """The counts (stored, clusters, log10 of the joint) and the best hypotheses."""
        with self._lock:
            counts = {
                "total": self._model.hypothesis_count,
                "clusters": self._model.cluster_count,
                "log10_joint": self._model.log10_joint_hypotheses,
            }
            return counts, list(self._model.hypotheses(limit))

    def health(self) -> dict[str, Any]:
        with self._lock:
            return {
                "status": "ok",
                "knowledge": str(self.knowledge_path) if self.knowledge_path else None,
                "time": self._model.latest_time,
                "hypotheses": self._model.hypothesis_count,
                "hypotheses_log10_joint": self._model.log10_joint_hypotheses,
                "objects": self._model.object_count,
            }

    def reset(self) -> float | None:
        with self._lock, self._change(reset_record()):
            self._model.reset()
            self._locals = {}
            with self._sources_lock:
                self.sources.forget_times()
            return self._model.latest_time

    def digest(self, also: Callable[[], T] | None = None) -> tuple[str, T | None]:
        """The digest of the world published now (:func:`semwm.persistence.model_digest`),
        and ``also()`` called under the same lock (a consistent view of both)."""
        from semwm.persistence.replay import model_digest

        with self._lock:
            return model_digest(self._model), also() if also is not None else None

    # -- knowledge ----------------------------------------------------------------------------

    @property
    def knowledge(self) -> Knowledge:
        with self._lock:
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

    def put_class(self, name: str, spec: ClassSpec) -> tuple[Knowledge, bool]:
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
        with self._lock:
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
            try:
                with self._change(knowledge_record(knowledge)):
                    self._model.replace_knowledge(knowledge)
            except ValueError as error:
                raise ConflictError(
                    f"the edit conflicts with the tracked objects: {error}"
                ) from None
            written = False
            if self.write_back and self.knowledge_path is not None:
                from semwm.knowledge.loader import dump_document

                dump_document(new_document, self.knowledge_path)
                written = True
            return knowledge, written

    def reload(self) -> Knowledge:
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
        with self._lock:
            try:
                with self._change(knowledge_record(knowledge)):
                    self._model.replace_knowledge(knowledge)
            except ValueError as error:
                raise ConflictError(
                    f"the reloaded knowledge conflicts with the tracked objects: {error}"
                ) from None
        return knowledge


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
