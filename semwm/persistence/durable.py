"""A world model whose every accepted change is journaled before it is acknowledged.

>>> world = DurableWorld.open("data", load_knowledge("knowledge/sim1.yaml"))  # doctest: +SKIP
>>> world.ingest([{"time": 0.0, "class": "Cup", "position": [1.0, 2.0]}])      # doctest: +SKIP

Each change (batch, knowledge replacement, reset, reorder-window change) is
appended to the journal in the same SQLite transaction that is committed only if
the world model accepted it: a refused batch leaves neither the world nor the
journal changed. Every ``snapshot_every`` records the model's state is
snapshotted; when more than ``compact_every`` records sit in the database, those
covered by the newest snapshot are moved to a gzip archive (never deleted, so an
old snapshot can always be rebuilt from the records).

Opening an existing data directory restores the newest snapshot this code can
read and replays the records after it; a damaged record ends the journal there
(it and everything after it are cut and reported in :attr:`recovery`).
"""

from __future__ import annotations

import logging
import os
import sqlite3
import threading
from collections.abc import Iterable, Iterator, Mapping
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any, Literal

from semwm.detection import Detection
from semwm.knowledge.model import Knowledge, KnowledgeDocument
from semwm.persistence.journal import Damage, Journal, StoreError, SyncPolicy, WriteFailed
from semwm.persistence.records import (
    DamagedRecord,
    Record,
    RecordError,
    action_record,
    batch_record,
    config_record,
    knowledge_record,
    reset_record,
    write_jsonl,
)
from semwm.persistence.replay import Replayer, model_digest
from semwm.persistence.snapshot import SnapshotMismatch, restore_snapshot, take_snapshot
from semwm.validation import ClassesHeld, DetectionInput, as_batch
from semwm.world import IngestResult, WorldModel

logger = logging.getLogger("semwm.persistence")

OnDamage = Literal["refuse", "truncate"]
KnowledgeFrom = Literal["file", "journal", "refuse"]


class KnowledgeConflict(StoreError):
    """The knowledge given conflicts with the journal's; the message names the classes
    and the ways out."""


def knowledge_difference(journal: KnowledgeDocument, given: KnowledgeDocument) -> str:
    """What differs between the journal's knowledge and the given one, in words."""
    ours = {c.name: c for c in journal.classes}
    theirs = {c.name: c for c in given.classes}
    parts = []
    added = sorted(set(ours) - set(theirs))
    removed = sorted(set(theirs) - set(ours))
    changed = sorted(n for n in set(ours) & set(theirs) if ours[n] != theirs[n])
    if added:
        parts.append(f"classes only in the journal: {', '.join(added)}")
    if removed:
        parts.append(f"classes only in the file: {', '.join(removed)}")
    if changed:
        parts.append(f"classes that differ: {', '.join(changed)}")
    for name in ("world", "detectors", "known_objects"):
        if getattr(journal, name) != getattr(given, name):
            parts.append(f"{name} differ")
    return "; ".join(parts) or "the documents differ"


ON_DAMAGE: tuple[str, ...] = ("refuse", "truncate")


@dataclass
class Recovery:
    """What opening the data directory did (also logged)."""

    new: bool = False
    snapshot_seq: int | None = None
    replayed: int = 0
    skipped_snapshots: list[str] = field(default_factory=list)
    cut: str | None = None
    cut_records: int = 0
    knowledge_changed: bool = False
    damage: list[str] = field(default_factory=list)
    lost: list[int] | None = None  # [first, last] seq of records known lost

    @property
    def damaged(self) -> bool:
        return bool(self.damage) or self.cut is not None

    def to_dict(self) -> dict[str, Any]:
        return {**vars(self), "damage": list(self.damage)}

    def note(self, damage: Damage) -> None:
        for problem in damage.problems:
            logger.error("%s", problem)
        self.damage.extend(damage.problems)
        if damage.lost is not None:
            first, last = damage.lost
            if self.lost is not None:
                first, last = min(first, self.lost[0]), max(last, self.lost[1])
            self.lost = [first, last]


class DurableWorld:
    """A :class:`WorldModel` with a journal and snapshots in ``data_dir``.

    Use :meth:`open`. Reads (``world``, ``hypotheses``...) go to :attr:`model`;
    changes go through :meth:`ingest`, :meth:`reset`, :meth:`replace_knowledge`,
    or, for a caller that applies them itself (the HTTP service), through
    :meth:`applying`.
    """

    def __init__(
        self,
        journal: Journal,
        model: WorldModel,
        recovery: Recovery,
        snapshot_every: int,
        compact_every: int,
    ) -> None:
        self.journal = journal
        self.model = model
        self.recovery = recovery
        self.snapshot_every = snapshot_every
        self.compact_every = compact_every
        self._lock = threading.RLock()
        self._last_snapshot = recovery.snapshot_seq or 0
        self.compactions = 0
        self.write_failures = 0  # writes refused because the store failed (a full disk...)
        self.write_error: str | None = None  # the last one's reason, until a write succeeds

    # -- opening ---------------------------------------------------------------------------
    @classmethod
    def open(
        cls,
        data_dir: str | Path,
        knowledge: Knowledge | None = None,
        *,
        reorder_window: float = 0.0,
        hold: float = 0.0,
        sync: SyncPolicy = "always",
        snapshot_every: int = 1000,
        compact_every: int = 100_000,
        on_damage: OnDamage = "truncate",
        knowledge_from: KnowledgeFrom = "file",
    ) -> DurableWorld:
        """Open (or create) ``data_dir``.

        A new directory needs ``knowledge``. In an existing one the world is restored
        as it was (held scans too: the journal replays the same ingests); then, if
        ``knowledge`` (or ``reorder_window`` or ``hold``) differs from the
        restored one, it is applied as a journaled change, like a reload.

        The store's integrity is checked first (:meth:`Journal.check`: SQLite's
        quick_check, sequence gaps, records the head file says were committed and are
        missing) and every record replayed is checked against its CRC. Damage is
        logged at ERROR and reported in :attr:`recovery` (``damage``, ``lost``);
        ``on_damage`` ``"refuse"`` raises :class:`StoreError` naming it instead of
        starting, ``"truncate"`` starts from what is intact (records after a damaged
        one are cut). A store that held records is never reported ``new``.
        """
        if snapshot_every < 1 or compact_every < 1:
            raise ValueError("snapshot_every and compact_every must be at least 1")
        if on_damage not in ON_DAMAGE:
            raise ValueError(f"on_damage must be one of {', '.join(ON_DAMAGE)}; got {on_damage!r}")
        journal = Journal(Path(data_dir), sync)
        recovery = Recovery()
        try:
            recovery.note(journal.check())
            if recovery.damage and on_damage == "refuse":
                raise StoreError(_refusal(journal, recovery))
            model = _restore(journal, recovery, on_damage)
            if model is None and knowledge is None:
                raise StoreError(f"{journal.path}: a new data directory needs knowledge")
        except BaseException:
            journal.close()
            raise
        if recovery.damaged:
            journal.write_head(journal.last_seq())  # what is left is the journal now
        if model is None:
            assert knowledge is not None
            recovery.new = not journal.existed and not recovery.damaged
            model = WorldModel(knowledge, reorder_window=reorder_window, hold=hold)
            with journal.transaction():
                journal.append(config_record(reorder_window, hold))
                journal.append(knowledge_record(knowledge))
            return cls(journal, model, recovery, snapshot_every, compact_every)
        world = cls(journal, model, recovery, snapshot_every, compact_every)
        if reorder_window != model.reorder_window or hold != model.hold:
            with world.applying(config_record(reorder_window, hold)):
                model.reorder_window = reorder_window
                model.set_hold(hold)
        if knowledge is not None and knowledge.document != model.knowledge.document:
            try:
                world._knowledge_given(knowledge, knowledge_from)
            except BaseException:
                world.close()
                raise
        return world

    def _knowledge_given(self, knowledge: Knowledge, knowledge_from: KnowledgeFrom) -> None:
        """``knowledge`` (the file's) differs from the journal's: use one of them."""
        journal = self.model.knowledge
        if knowledge_from == "journal":
            logger.warning(
                "%s: the knowledge file differs from the journal's (%s); the journal's is in force",
                self.journal.path,
                knowledge_difference(journal.document, knowledge.document),
            )
            return
        if knowledge_from == "refuse":
            raise KnowledgeConflict(
                f"{self.journal.data_dir}: the knowledge file {knowledge.source or ''} differs "
                f"from the knowledge in force in the journal (live edits since it was read: "
                f"{knowledge_difference(journal.document, knowledge.document)}). Nothing was "
                "changed. Start with --write-back to keep the journal's knowledge and write it "
                "to the file, or with --knowledge-from file to apply the file (as POST "
                "/knowledge/reload would: objects of classes it lacks refuse it)"
            )
        difference = knowledge_difference(journal.document, knowledge.document)
        try:
            with self._undoable(knowledge_record(knowledge)):
                self.model.replace_knowledge(knowledge, refuse_held=True)
        except ClassesHeld as error:
            raise KnowledgeConflict(
                f"{self.journal.data_dir}: the knowledge file {knowledge.source or ''} removes "
                f"classes that tracked objects hold: {', '.join(sorted(error.held))}; nothing "
                "was changed. Keep these classes in the file, or start with --write-back to "
                "keep the journal's knowledge"
            ) from None
        self.recovery.knowledge_changed = True
        logger.warning(
            "%s: the knowledge file differs from the journal's (%s); applied it",
            self.journal.path,
            difference,
        )

    # -- changes ---------------------------------------------------------------------------
    @contextmanager
    def applying(self, record: Record) -> Iterator[None]:
        """Journal ``record`` around the code that applies it to :attr:`model`.

        The record, the snapshot due with it (every ``snapshot_every`` records) and the
        change commit together or not at all: all are written in one transaction, which
        is rolled back if the body raises (the change was refused and never happened)
        or if a write fails (:class:`WriteFailed`, for example a full disk; the caller
        undoes the change in memory). A compaction may follow; its failure loses
        nothing (the records stay in the database) and is only logged.
        """
        with self._lock:
            snapshot_seq: int | None = None
            try:
                with self.journal.transaction():
                    seq = self.journal.append(record)
                    yield
                    if seq - self._last_snapshot >= self.snapshot_every:
                        snapshot_seq = self._save_snapshot(seq)
            except WriteFailed as error:
                self.write_failures += 1
                self.write_error = str(error)
                logger.error("%s", error)
                raise
            self.write_error = None
            if snapshot_seq is not None:
                self._last_snapshot = snapshot_seq
                if self.journal.count() > self.compact_every:
                    try:
                        self.compact()
                    except (WriteFailed, OSError) as error:
                        logger.warning("compaction failed; the records stay in the database: %s",
                                       error)  # fmt: skip

    def _save_snapshot(self, seq: int) -> int | None:
        """Snapshot the model into the open transaction; ``None`` if it does not pickle."""
        try:
            snapshot = take_snapshot(self.model, seq)
        except Exception as error:  # a state that does not pickle: journal only
            logger.error("snapshot failed (the journal still has everything): %s", error)
            return None
        self.journal.save_snapshot(snapshot)
        return seq

    def writable(self, probe_bytes: int = 64 * 1024) -> bool:
        """Whether ``probe_bytes`` can be written and synced in the data directory now
        (a probe file, removed again): after a full disk, whether space has returned.
        Needs no lock; touches nothing of the store."""
        probe = self.journal.data_dir / ".semwm-space-probe"
        try:
            if self.journal.fault is not None:
                self.journal.fault("probe")
            with probe.open("wb") as handle:
                handle.write(b"\0" * probe_bytes)
                handle.flush()
                os.fsync(handle.fileno())
            return True
        except (OSError, sqlite3.Error):
            return False
        finally:
            probe.unlink(missing_ok=True)

    @contextmanager
    def _undoable(self, record: Record) -> Iterator[None]:
        """:meth:`applying`, and the model as it was if the change or its write fails."""
        saved = {
            name: value.copy() if isinstance(value, dict | list | set) else value
            for name, value in vars(self.model).items()
        }
        try:
            with self.applying(record):
                yield
        except BaseException:
            vars(self.model).clear()
            vars(self.model).update(saved)
            raise

    def ingest(
        self,
        detections: DetectionInput | Iterable[DetectionInput],
        sensor: Mapping[str, Any] | None = None,
    ) -> IngestResult:
        """:meth:`WorldModel.ingest`, journaled (nothing is journaled when it raises, and
        the model is unchanged when the write fails: :class:`WriteFailed`)."""
        batch = [d.to_dict() if isinstance(d, Detection) else dict(d) for d in as_batch(detections)]
        with self._undoable(batch_record(batch, sensor)):
            return self.model.ingest(batch, sensor=sensor)

    def act(self, action: Mapping[str, Any]) -> list[int]:
        """:meth:`WorldModel.act` (paper 004: a kick), journaled."""
        with self._undoable(action_record(action)):
            return self.model.act(action)

    def reset(self) -> None:
        with self._undoable(reset_record()):
            self.model.reset()

    def replace_knowledge(self, knowledge: Knowledge) -> None:
        with self._undoable(knowledge_record(knowledge)):
            self.model.replace_knowledge(knowledge)

    # -- maintenance -----------------------------------------------------------------------
    def snapshot(self) -> int:
        """Snapshot the model now; returns the journal position it covers."""
        with self._lock:
            seq = self.journal.last_seq()
            try:
                snapshot = take_snapshot(self.model, seq)
            except Exception as error:  # a state that does not pickle: journal only
                logger.error("snapshot failed (the journal still has everything): %s", error)
                return self._last_snapshot
            with self.journal.transaction():
                self.journal.save_snapshot(snapshot)
            self._last_snapshot = seq
            return seq

    def compact(self) -> Path | None:
        """Snapshot, then move the records it covers to an archive."""
        with self._lock:
            through = self.snapshot()
            path = self.journal.compact(through)
            if path is not None:
                self.compactions += 1
                logger.info("journal compacted through record %d into %s", through, path)
            return path

    def records(self) -> Iterator[Record]:
        """Every record, archived and stored, in order."""
        with self._lock:
            yield from self.journal.archived_records()
            yield from self.journal.records(after=int(self.journal.meta("archived_through") or 0))

    def export_jsonl(self, handle: IO[str]) -> int:
        """Write every record as JSON Lines (what ``semwm replay`` reads)."""
        return write_jsonl(self.records(), handle)

    def digest(self) -> str:
        """The digest of the world published now (:func:`model_digest`)."""
        with self._lock:
            return model_digest(self.model)

    def status(self) -> dict[str, Any]:
        with self._lock:
            return {
                "data_dir": str(self.journal.data_dir),
                "sync": self.journal.sync,
                "last_seq": self.journal.last_seq(),
                "records_in_database": self.journal.count(),
                "snapshot_seq": self._last_snapshot or None,
                "archives": len(self.journal.archives()),
                "bytes": self.journal.size_bytes(),
                "recovery": self.recovery.to_dict(),
                "write_failures": self.write_failures,
                "write_error": self.write_error,
            }

    def close(self) -> None:
        with self._lock:
            self.journal.close()


def _refusal(journal: Journal, recovery: Recovery) -> str:
    lost = (
        f"records {recovery.lost[0]} to {recovery.lost[1]} are lost; "
        if recovery.lost is not None
        else ""
    )
    return (
        f"{journal.data_dir}: the store is damaged: {'; '.join(recovery.damage)}. "
        f"{lost}nothing was changed. Keep a copy of the directory, then start with "
        "--on-damage truncate to serve what is intact (docs/persistence.md, 'Damage')"
    )


def _restore(journal: Journal, recovery: Recovery, on_damage: OnDamage) -> WorldModel | None:
    """The world of the stored journal (``None`` for an empty store)."""
    replayer: Replayer | None = None
    for snapshot in journal.snapshots():
        try:
            model = restore_snapshot(snapshot)
        except SnapshotMismatch as error:
            recovery.skipped_snapshots.append(f"snapshot {snapshot.seq}: {error}")
            logger.warning(
                "snapshot %d not used: %s; rebuilding from the journal", snapshot.seq, error
            )
            continue
        replayer = Replayer(reorder_window=model.reorder_window, hold=model.hold)
        replayer.model = model
        replayer.last_seq = snapshot.seq
        recovery.snapshot_seq = snapshot.seq
        break
    if replayer is None:
        replayer = Replayer()
        first = journal.first_seq()
        archived = int(journal.meta("archived_through") or 0)
        if archived:
            for record in journal.archived_records():
                replayer.apply(record)
        elif first is not None and first > 1:
            raise StoreError(
                f"{journal.path}: the journal starts at record {first}, no archive holds the "
                "records before it and no snapshot is readable by this code: cannot rebuild"
            )
    _replay_tail(journal, replayer, recovery, on_damage)
    return replayer.model


def _replay_tail(
    journal: Journal, replayer: Replayer, recovery: Recovery, on_damage: OnDamage
) -> None:
    start = replayer.last_seq
    records = journal.records(after=start)
    while True:
        try:
            record = next(records)
        except StopIteration:
            return
        except DamagedRecord as error:
            _cut(journal, error.seq, str(error), recovery, on_damage)
            return
        try:
            replayer.apply(record)
        except RecordError as error:
            _cut(journal, record.seq, str(error), recovery, on_damage)
            return
        recovery.replayed += 1


def _cut(journal: Journal, seq: int, problem: str, recovery: Recovery, on_damage: OnDamage) -> None:
    last = journal.last_seq()
    if on_damage == "refuse":
        recovery.note(Damage([problem], (seq, last)))
        raise StoreError(_refusal(journal, recovery))
    with journal.transaction():
        count = journal.cut(seq)
    recovery.cut = problem
    recovery.cut_records = count
    recovery.note(
        Damage([f"{problem}; the journal was cut at record {seq} ({count} dropped)"], (seq, last))
    )
