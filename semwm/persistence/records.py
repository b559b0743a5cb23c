"""Journal records: what changed the world, in the order it was applied.

A record is one accepted change: a detection batch, a knowledge replacement, a
reset, or a settings change (the reorder window). The world model is
deterministic given its changes in order, so the records alone rebuild it (ids
included). Each record carries a CRC-32 of its kind and payload, so a record
damaged on disk is detected instead of replayed.

The JSON Lines form (one record per line) is what ``semwm replay`` reads and
the journal export writes; :func:`read_jsonl` stops at a torn or damaged line
and reports it.
"""

from __future__ import annotations

import json
import zlib
from collections.abc import Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any, Literal

from semwm.knowledge.model import Knowledge

Kind = Literal["batch", "knowledge", "reset", "config"]
KINDS: tuple[str, ...] = ("batch", "knowledge", "reset", "config", "action")


def payload_text(payload: Any) -> str:
    """The canonical JSON text of a payload (what the CRC covers)."""
    return json.dumps(payload, separators=(",", ":"), sort_keys=True, allow_nan=False)


def checksum(kind: str, text: str) -> int:
    """CRC-32 of ``kind`` and the payload text."""
    return zlib.crc32(f"{kind}\n{text}".encode())


@dataclass(frozen=True)
class Record:
    """One accepted change.

    Attributes
    ----------
    seq
        Position in the journal (1, 2, ...); 0 for a change not yet stored.
    kind
        ``batch`` (payload: list of detections as dicts, or ``{"detections": [...],
        "sensor": {...}}`` for a scan with its sensor's view), ``knowledge`` (payload:
        ``{"document": ..., "source": ...}``), ``reset`` (payload ``null``), ``config``
        (payload: ``{"reorder_window": s}``, with ``"hold": s`` when not 0) or
        ``action`` (payload: the action as ``POST /actions`` took it).
    payload
        JSON-compatible value.
    wall_time
        When it was accepted (s since the epoch); informative only.
    """

    seq: int
    kind: str
    payload: Any
    wall_time: float = 0.0
    text: str = field(default="", compare=False, repr=False)

    def payload_json(self) -> str:
        return self.text or payload_text(self.payload)

    @property
    def crc(self) -> int:
        return checksum(self.kind, self.payload_json())

    def to_line(self) -> str:
        """The record as one JSON Lines line (with its newline)."""
        return (
            json.dumps(
                {
                    "seq": self.seq,
                    "kind": self.kind,
                    "wall_time": self.wall_time,
                    "payload": self.payload,
                    "crc": self.crc,
                },
                separators=(",", ":"),
                allow_nan=False,
            )
            + "\n"
        )


def batch_record(
    detections: Sequence[Mapping[str, Any]], sensor: Mapping[str, Any] | None = None
) -> Record:
    """A batch change; ``detections`` (and ``sensor``) as :meth:`semwm.WorldModel.ingest`
    took them. The payload is the list of detections, or ``{"detections", "sensor"}``
    for a scan that says where its sensor looked (paper 004)."""
    listed = [dict(d) for d in detections]
    if sensor is None:
        return Record(0, "batch", listed)
    return Record(0, "batch", {"detections": listed, "sensor": dict(sensor)})


def batch_parts(payload: Any) -> tuple[list[dict[str, Any]], dict[str, Any] | None]:
    """The detections and the sensor view (or ``None``) of a batch record's payload."""
    if isinstance(payload, dict):
        return list(payload["detections"]), payload.get("sensor")
    return list(payload), None


def action_record(action: Mapping[str, Any]) -> Record:
    """An action (paper 004: a kick) as :meth:`semwm.WorldModel.act` took it."""
    return Record(0, "action", dict(action))


def knowledge_record(knowledge: Knowledge) -> Record:
    """A knowledge change: the whole document (resolved again on replay)."""
    document = knowledge.document.model_dump(mode="json")
    return Record(0, "knowledge", {"document": document, "source": knowledge.source})


def reset_record() -> Record:
    return Record(0, "reset", None)


def config_record(reorder_window: float, hold: float = 0.0) -> Record:
    """The settings that change how batches apply; ``hold`` only when not 0 (journals
    written before the hold existed read the same)."""
    payload: dict[str, float] = {"reorder_window": reorder_window}
    if hold:
        payload["hold"] = hold
    return Record(0, "config", payload)


class RecordError(ValueError):
    """A record that cannot be used: where it is and why."""


class DamagedRecord(RecordError):
    """A stored record whose checksum or JSON does not hold (``seq`` names it)."""

    def __init__(self, seq: int, message: str) -> None:
        self.seq = seq
        super().__init__(message)


@dataclass
class ReadReport:
    """What reading a record stream found: good records and where it stopped."""

    records: int = 0
    problem: str | None = None

    @property
    def clean(self) -> bool:
        return self.problem is None


def parse_line(line: str, where: str) -> Record:
    """One JSON Lines line as a :class:`Record`; :class:`RecordError` naming ``where``."""
    try:
        data = json.loads(line)
    except json.JSONDecodeError as error:
        raise RecordError(f"{where}: not a JSON record ({error.msg})") from None
    if not isinstance(data, dict):
        raise RecordError(f"{where}: a record must be a JSON object")
    missing = [k for k in ("seq", "kind", "payload", "crc") if k not in data]
    if missing:
        raise RecordError(f"{where}: record lacks {', '.join(missing)}")
    kind = data["kind"]
    if kind not in KINDS:
        raise RecordError(f"{where}: unknown record kind {kind!r}; known: {', '.join(KINDS)}")
    record = Record(int(data["seq"]), kind, data["payload"], float(data.get("wall_time", 0.0)))
    if record.crc != data["crc"]:
        raise RecordError(f"{where}: checksum mismatch (record damaged)")
    return record


def read_jsonl(source: Path | IO[str], report: ReadReport | None = None) -> Iterator[Record]:
    """The records of a JSON Lines file, in order, up to the first bad line.

    A last line without its newline (a write torn by power loss), an unparsable
    line or a checksum mismatch ends the stream there; ``report.problem`` says
    which line and why (``FILE:LINE: ...``). Blank lines are skipped.
    """
    report = report if report is not None else ReadReport()
    if isinstance(source, Path):
        with source.open(encoding="utf-8", newline="") as handle:
            yield from _read(handle, str(source), report)
    else:
        yield from _read(source, getattr(source, "name", "<stream>"), report)


def _read(handle: IO[str], name: str, report: ReadReport) -> Iterator[Record]:
    for number, line in enumerate(handle, start=1):
        where = f"{name}:{number}"
        if not line.endswith("\n"):
            report.problem = f"{where}: torn last line (no newline); cut here"
            return
        if not line.strip():
            continue
        try:
            record = parse_line(line, where)
        except RecordError as error:
            report.problem = f"{error}; cut here"
            return
        report.records += 1
        yield record


def write_jsonl(records: Iterable[Record], handle: IO[str]) -> int:
    """Write ``records`` as JSON Lines; returns how many."""
    count = 0
    for record in records:
        handle.write(record.to_line())
        count += 1
    return count
