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
import os
import sqlite3
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
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

SyncPolicy = Literal["always", "batch"]
SYNC_POLICIES: tuple[str, ...] = ("always", "batch")
DATABASE = "semwm.sqlite3"
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
                if isinstance(error, sqlite3.Error | OSError):
                    raise write_failed(self.path, error) from error
                raise
        finally:
            self._in_transaction = False

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
