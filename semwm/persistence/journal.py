"""The journal and snapshot store: one SQLite database in WAL mode, plus archives.

Layout of a data directory::

    DATA_DIR/semwm.sqlite3        journal, snapshots, meta (WAL mode)
    DATA_DIR/semwm.sqlite3-wal    SQLite's write-ahead log (part of the database)
    DATA_DIR/archive/journal-<first>-<last>.jsonl.gz   records moved out by compaction

SQLite makes each append atomic (a torn write of its own pages is rolled back on
open); each record also carries a CRC-32 so damage to a committed record is
detected. Sync policies: ``always`` = ``synchronous=FULL`` (the write-ahead log is
fsynced at every commit, before the answer); ``batch`` = ``synchronous=NORMAL``
(a commit reaches the operating system before the answer, so a process crash loses
nothing; the log is fsynced at checkpoints, so a power loss can lose the commits
since the last checkpoint).
"""

from __future__ import annotations

import contextlib
import errno
import gzip
import json
import logging
import os
import sqlite3
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

from semwm.persistence.records import (
    DamagedRecord,
    ReadReport,
    Record,
    RecordError,
    checksum,
    read_jsonl,
)
from semwm.persistence.snapshot import Snapshot

logger = logging.getLogger("semwm.persistence")

SyncPolicy = Literal["always", "batch"]
SYNC_POLICIES: tuple[str, ...] = ("always", "batch")
DATABASE = "semwm.sqlite3"
HEAD = "semwm.head"
"""Beside the database: the seq of the last committed record, rewritten after each
commit (issue 30). SQLite cannot tell a write-ahead log cut short, filled with garbage
or deleted from one that never held more: its frames just end. The head file says
how far the journal reached, so records lost that way are detected and named."""
ARCHIVE = "archive"
STORE_FORMAT = 1
_SCHEMA = """
CREATE TABLE IF NOT EXISTS meta (key TEXT PRIMARY KEY, value TEXT NOT NULL);
CREATE TABLE IF NOT EXISTS journal (
    seq INTEGER PRIMARY KEY, kind TEXT NOT NULL, wall_time REAL NOT NULL,
    payload TEXT NOT NULL, crc INTEGER NOT NULL);
CREATE TABLE IF NOT EXISTS snapshots (
    seq INTEGER PRIMARY KEY, format INTEGER NOT NULL, code TEXT NOT NULL,
    knowledge TEXT NOT NULL, state BLOB NOT NULL, wall_time REAL NOT NULL);
"""


class StoreError(RuntimeError):
    """The data directory cannot be used as it is (the message says why and where)."""


@dataclass
class Damage:
    """What an integrity check of the store found (empty: nothing).

    ``problems``: one sentence each; ``lost``: the first and last seq of records the
    store should hold and does not (``None`` if none are known lost)."""

    problems: list[str] = field(default_factory=list)
    lost: tuple[int, int] | None = None

    def __bool__(self) -> bool:
        return bool(self.problems)

    def lose(self, first: int, last: int) -> None:
        if self.lost is None:
            self.lost = (first, last)
        else:
            self.lost = (min(self.lost[0], first), max(self.lost[1], last))


class WriteFailed(RuntimeError):
    """A write to the store failed and nothing of it was kept (the transaction was rolled
    back). ``full``: the disk (or the file system's quota) is full; writes can succeed
    again once space returns."""

    def __init__(self, message: str, *, full: bool) -> None:
        super().__init__(message)
        self.full = full


SQLITE_FULL = 13
"""SQLite's result code for "database or disk is full"."""

Fault = Callable[[str], None]
"""A test's fault hook: called with the step about to run (``"append"``,
``"snapshot"``, ``"commit"``; ``"probe"`` in ``DurableWorld.writable``); raising
there is what the step would raise (for example SQLite's "database or disk is full")."""


def is_full(error: BaseException) -> bool:
    """Whether ``error`` says the disk is full (SQLite's SQLITE_FULL, or ENOSPC/EDQUOT)."""
    if isinstance(error, sqlite3.Error):
        code = getattr(error, "sqlite_errorcode", None)
        return (code is not None and code & 0xFF == SQLITE_FULL) or "full" in str(error)
    return isinstance(error, OSError) and error.errno in (errno.ENOSPC, errno.EDQUOT)


def write_failed(path: Path, error: BaseException) -> WriteFailed:
    """``error`` of a write to ``path`` as :class:`WriteFailed`."""
    full = is_full(error)
    what = "the disk is full" if full else "the write failed"
    return WriteFailed(f"{path}: {what} ({error}); nothing of the change was stored", full=full)


class Journal:
    """The SQLite store of a data directory.

    Not thread-safe by itself: the caller serialises every call (the service holds
    its lock; :class:`~semwm.persistence.durable.DurableWorld` has its own).
    """

    def __init__(self, data_dir: Path, sync: SyncPolicy = "always") -> None:
        if sync not in SYNC_POLICIES:
            raise ValueError(f"sync must be one of {', '.join(SYNC_POLICIES)}; got {sync!r}")
        self.data_dir = Path(data_dir)
        self.data_dir.mkdir(parents=True, exist_ok=True)
        self.sync = sync
        self.path = self.data_dir / DATABASE
        self.head_path = self.data_dir / HEAD
        self.existed = self.path.exists() or self.head_path.exists()
        self._head: int | None = None
        try:
            self._db = sqlite3.connect(self.path, isolation_level=None, check_same_thread=False)
            self._db.execute("PRAGMA journal_mode=WAL")
            self._db.execute(f"PRAGMA synchronous={'FULL' if sync == 'always' else 'NORMAL'}")
            self._db.executescript(_SCHEMA)
        except sqlite3.DatabaseError as error:
            raise StoreError(f"{self.path}: not a usable SQLite database: {error}") from None
        found = self.meta("format")
        if found is None:
            self.set_meta("format", str(STORE_FORMAT))
        elif found != str(STORE_FORMAT):
            raise StoreError(
                f"{self.path}: store format {found}; this code reads format {STORE_FORMAT}"
            )
        self._in_transaction = False
        self.fault: Fault | None = None

    # -- meta ------------------------------------------------------------------------------
    def meta(self, key: str) -> str | None:
        row = self._db.execute("SELECT value FROM meta WHERE key = ?", (key,)).fetchone()
        return None if row is None else str(row[0])

    def set_meta(self, key: str, value: str) -> None:
        self._db.execute("INSERT OR REPLACE INTO meta VALUES (?, ?)", (key, value))

    # -- appending -------------------------------------------------------------------------
    @contextmanager
    def transaction(self) -> Iterator[None]:
        """Everything inside is committed together, or rolled back on an exception.

        A store error (a full disk, an I/O error) in the body or at the commit rolls
        everything back and raises :class:`WriteFailed`: the transaction is over either
        way, so the next one can start (a failed ``COMMIT`` used to leave it open).
        """
        try:
            self._db.execute("BEGIN IMMEDIATE")
        except (sqlite3.Error, OSError) as error:
            raise write_failed(self.path, error) from error
        self._in_transaction = True
        try:
            try:
                yield
                self._fault("commit")
                self._db.execute("COMMIT")
            except BaseException as error:
                self._rollback()
                self._head = None
                if isinstance(error, sqlite3.Error | OSError):
                    raise write_failed(self.path, error) from error
                raise
        finally:
            self._in_transaction = False
        if self._head is not None:
            self.write_head(self._head)
            self._head = None

    # -- the head file and integrity -------------------------------------------------------
    def write_head(self, seq: int) -> None:
        """Note ``seq`` as the last committed record (not synced: after a power loss the
        head can only be older than the database, which is never taken for damage)."""
        try:
            fd = os.open(self.head_path, os.O_WRONLY | os.O_CREAT, 0o644)
            try:
                os.pwrite(fd, f"{seq:020d}\n".encode(), 0)
            finally:
                os.close(fd)
        except OSError as error:  # the head is a check, not the data: go on without it
            logger.warning("%s: cannot write the head file (%s)", self.head_path, error)

    def read_head(self) -> int | None:
        """The seq the head file names, ``None`` without a readable one."""
        try:
            text = self.head_path.read_bytes()[:21].decode("ascii")
            return int(text.strip())
        except (OSError, ValueError):
            return None

    def check(self) -> Damage:
        """The store's integrity: SQLite's ``quick_check``, gaps in the sequence numbers,
        and records the head file says were committed but are missing. Reads only."""
        damage = Damage()
        try:
            rows = [str(r[0]) for r in self._db.execute("PRAGMA quick_check").fetchall()]
        except sqlite3.DatabaseError as error:
            rows = [str(error)]
        if rows != ["ok"]:
            damage.problems.append(
                f"{self.path}: SQLite's integrity check failed: {'; '.join(rows[:5])}"
            )
        archived = int(self.meta("archived_through") or 0)
        previous = archived
        gaps = self._db.execute(
            "SELECT seq, prev FROM (SELECT seq, LAG(seq) OVER (ORDER BY seq) AS prev "
            "FROM journal) WHERE prev IS NOT NULL AND seq != prev + 1"
        ).fetchall()
        first = self.first_seq()
        if first is not None and previous and first != previous + 1:
            gaps.insert(0, (first, previous))
        for seq, prev in gaps:
            damage.problems.append(
                f"{self.path}: journal records {prev + 1} to {seq - 1} are missing"
            )
            damage.lose(int(prev) + 1, int(seq) - 1)
        head = self.read_head()
        last = self.last_seq()
        if head is not None and head > last:
            damage.problems.append(
                f"{self.path}: the journal ends at record {last}, but record {head} was "
                f"committed ({self.head_path.name}): the write-ahead log or the database "
                "lost records (cut, overwritten or deleted)"
            )
            damage.lose(last + 1, head)
        return damage

    def _rollback(self) -> None:
        if self._db.in_transaction:
            # SQLite may have rolled back itself (a failed COMMIT can)
            with contextlib.suppress(sqlite3.Error):
                self._db.execute("ROLLBACK")

    def _fault(self, step: str) -> None:
        if self.fault is not None:
            self.fault(step)

    def append(self, record: Record) -> int:
        """Store ``record`` after the last one; returns its ``seq``."""
        text = record.payload_json()
        self._fault("append")
        seq = self.last_seq() + 1
        self._db.execute(
            "INSERT INTO journal (seq, kind, wall_time, payload, crc) VALUES (?, ?, ?, ?, ?)",
            (seq, record.kind, record.wall_time or time.time(), text, checksum(record.kind, text)),
        )
        self._head = seq  # written to the head file once committed
        return seq

    # -- reading ---------------------------------------------------------------------------
    def last_seq(self) -> int:
        row = self._db.execute("SELECT MAX(seq) FROM journal").fetchone()
        stored = int(row[0]) if row[0] is not None else 0
        return max(stored, int(self.meta("archived_through") or 0))

    def first_seq(self) -> int | None:
        row = self._db.execute("SELECT MIN(seq) FROM journal").fetchone()
        return None if row[0] is None else int(row[0])

    def count(self) -> int:
        return int(self._db.execute("SELECT COUNT(*) FROM journal").fetchone()[0])

    def records(self, after: int = 0) -> Iterator[Record]:
        """Stored records with ``seq > after`` in order; :class:`RecordError` at a
        damaged one (its message names the seq)."""
        cursor = self._db.execute(
            "SELECT seq, kind, wall_time, payload, crc FROM journal WHERE seq > ? ORDER BY seq",
            (after,),
        )
        for seq, kind, wall_time, text, crc in cursor:
            if checksum(kind, text) != crc:
                raise DamagedRecord(seq, f"{self.path}: journal record {seq}: checksum mismatch")
            try:
                payload = json.loads(text)
            except json.JSONDecodeError:
                raise DamagedRecord(seq, f"{self.path}: journal record {seq}: not JSON") from None
            yield Record(int(seq), str(kind), payload, float(wall_time), text)

    def cut(self, from_seq: int) -> int:
        """Delete the records from ``from_seq`` on (and snapshots past them); returns how
        many records."""
        cursor = self._db.execute("DELETE FROM journal WHERE seq >= ?", (from_seq,))
        self._db.execute("DELETE FROM snapshots WHERE seq >= ?", (from_seq,))
        self._head = from_seq - 1
        return int(cursor.rowcount)

    # -- snapshots -------------------------------------------------------------------------
    def save_snapshot(self, snapshot: Snapshot, keep: int = 2) -> None:
        """Store ``snapshot``; only the ``keep`` newest stay."""
        self._fault("snapshot")
        self._db.execute(
            "INSERT OR REPLACE INTO snapshots VALUES (?, ?, ?, ?, ?, ?)",
            (
                snapshot.seq,
                snapshot.format,
                snapshot.code,
                snapshot.knowledge,
                snapshot.state,
                time.time(),
            ),
        )
        self._db.execute(
            "DELETE FROM snapshots WHERE seq NOT IN "
            "(SELECT seq FROM snapshots ORDER BY seq DESC LIMIT ?)",
            (keep,),
        )

    def snapshots(self) -> list[Snapshot]:
        """Stored snapshots, newest first."""
        rows = self._db.execute(
            "SELECT seq, format, code, knowledge, state FROM snapshots ORDER BY seq DESC"
        ).fetchall()
        return [Snapshot(int(s), int(f), str(c), str(k), bytes(b)) for s, f, c, k, b in rows]

    # -- archives and compaction -----------------------------------------------------------
    @property
    def archive_dir(self) -> Path:
        return self.data_dir / ARCHIVE

    def archives(self) -> list[Path]:
        return sorted(self.archive_dir.glob("journal-*.jsonl.gz"))

    def archived_records(self) -> Iterator[Record]:
        """Every archived record in order; :class:`RecordError` on a damaged archive."""
        expected = 1
        for path in self.archives():
            report = ReadReport()
            with gzip.open(path, "rt", encoding="utf-8", newline="") as handle:
                for record in read_jsonl(handle, report):
                    if record.seq != expected:
                        raise RecordError(f"{path}: record {record.seq}, expected {expected}")
                    expected += 1
                    yield record
            if not report.clean:
                raise RecordError(f"{path}: {report.problem}")

    def compact(self, through: int) -> Path | None:
        """Move the records with ``seq <= through`` into a gzip JSON Lines archive.

        The archive is written and fsynced before the records leave the database, so
        a crash in between leaves them in both (the next compaction overwrites the
        archive). Returns the archive written, or ``None`` when there was nothing.
        """
        first = self.first_seq()
        if first is None or first > through:
            return None
        self.archive_dir.mkdir(exist_ok=True)
        target = self.archive_dir / f"journal-{first:012d}-{through:012d}.jsonl.gz"
        partial = target.with_suffix(".partial")
        with partial.open("wb") as raw:
            with gzip.GzipFile(fileobj=raw, mode="wb", mtime=0) as zipped:
                for record in self.records(after=first - 1):
                    if record.seq > through:
                        break
                    zipped.write(record.to_line().encode())
            raw.flush()
            os.fsync(raw.fileno())
        partial.replace(target)
        with self.transaction():
            self._db.execute("DELETE FROM journal WHERE seq <= ?", (through,))
            self.set_meta("archived_through", str(through))
        return target

    def size_bytes(self) -> int:
        """Bytes on disk: the database, its write-ahead log and the archives."""
        files = [self.path, self.path.with_name(DATABASE + "-wal"), *self.archives()]
        return sum(p.stat().st_size for p in files if p.exists())

    def close(self) -> None:
        self._db.close()
