"""Feeding records back through a world model, and the digest of a published world.

:class:`Replayer` applies records in order exactly as the live service applied
them, so the world it ends with is the world the service published (same ids,
classes and positions). With ``knowledge`` given, the recording is replayed into
another knowledge base: the recorded knowledge changes are then skipped, and
batches the other knowledge refuses are counted, not fatal.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass

from semwm.detection import DetectionError, OutOfOrderError
from semwm.knowledge import KnowledgeDocument, resolve
from semwm.knowledge.model import Knowledge
from semwm.persistence.records import Record, RecordError, batch_parts
from semwm.world import IngestResult, WorldModel
from semwm.world_types import WorldState


def world_digest(state: WorldState) -> str:
    """SHA-256 of the world's canonical JSON (floats exactly, keys sorted)."""
    text = json.dumps(state.to_dict(), sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()


def model_digest(model: WorldModel) -> str:
    """The digest of the world ``model`` publishes now (at its latest time)."""
    return world_digest(model.world())


def knowledge_from_payload(payload: object, where: str = "record") -> Knowledge:
    """The knowledge of a ``knowledge`` record (the document resolved again)."""
    if not isinstance(payload, dict) or "document" not in payload:
        raise RecordError(f"{where}: a knowledge record needs a 'document'")
    document = KnowledgeDocument.model_validate(payload["document"])
    source = payload.get("source")
    return resolve(document, source if isinstance(source, str) else None)


def _reason(error: DetectionError | OutOfOrderError, shown: int = 2) -> str:
    """Why a batch was refused, in one short line (the first ``shown`` problems)."""
    if isinstance(error, DetectionError) and len(error.problems) > shown:
        first = "; ".join(
            f"{'.'.join(map(str, p.path))}: {p.message}" for p in error.problems[:shown]
        )
        return f"{first} (and {len(error.problems) - shown} more)"
    return str(error)


@dataclass
class ReplayCounts:
    """What a replay did: records applied and batches refused (other knowledge)."""

    batches: int = 0
    detections: int = 0
    refused_batches: int = 0
    skipped_knowledge: int = 0
    resets: int = 0
    actions: int = 0
    refused_actions: int = 0
    first_refusal: str | None = None
    """Why the first refused batch or action was refused."""


class Replayer:
    """Applies records to a world model in order.

    Parameters
    ----------
    knowledge
        Replay into this knowledge instead of the recorded one (recorded
        knowledge changes are skipped; batches it refuses are counted).
    reorder_window, hold
        The reorder window and hold until a ``config`` record says otherwise.
    strict
        Raise on a refused batch (a journal of accepted batches never has one).
    """

    def __init__(
        self,
        knowledge: Knowledge | None = None,
        reorder_window: float = 0.0,
        strict: bool = True,
        hold: float = 0.0,
    ) -> None:
        self.override = knowledge
        self.reorder_window = reorder_window
        self.hold = hold
        self.strict = strict
        self.model: WorldModel | None = (
            WorldModel(knowledge, reorder_window=reorder_window, hold=hold) if knowledge else None
        )
        self.counts = ReplayCounts()
        self.last_seq = 0

    def apply(self, record: Record) -> IngestResult | None:
        """Apply one record; returns the ingest result of a batch."""
        where = f"record {record.seq}"
        result = None
        if record.kind == "config":
            window = float(record.payload["reorder_window"])
            self.reorder_window = window
            self.hold = float(record.payload.get("hold", 0.0))
            if self.model is not None:
                self.model.reorder_window = window
                self.model.set_hold(self.hold)
        elif record.kind == "knowledge":
            if self.override is not None:
                self.counts.skipped_knowledge += 1
            else:
                knowledge = knowledge_from_payload(record.payload, where)
                if self.model is None:
                    self.model = WorldModel(
                        knowledge, reorder_window=self.reorder_window, hold=self.hold
                    )
                else:
                    self.model.replace_knowledge(knowledge)
        elif record.kind == "reset":
            self.require(where).reset()
            self.counts.resets += 1
        elif record.kind == "batch":
            model = self.require(where)
            detections, sensor = batch_parts(record.payload)
            try:
                result = model.ingest(detections, sensor=sensor)
            except (DetectionError, OutOfOrderError) as error:
                if self.strict:
                    raise RecordError(
                        f"{where}: the batch was refused on replay: {error}"
                    ) from None
                self.counts.refused_batches += 1
                self.counts.first_refusal = self.counts.first_refusal or _reason(error)
            else:
                self.counts.batches += 1
                self.counts.detections += len(detections)
        elif record.kind == "action":
            try:
                self.require(where).act(record.payload)
            except (DetectionError, OutOfOrderError) as error:
                if self.strict:
                    raise RecordError(
                        f"{where}: the action was refused on replay: {error}"
                    ) from None
                self.counts.refused_actions += 1
                self.counts.first_refusal = self.counts.first_refusal or _reason(error)
            else:
                self.counts.actions += 1
        else:
            raise RecordError(f"{where}: unknown record kind {record.kind!r}")
        self.last_seq = record.seq
        return result

    def require(self, where: str) -> WorldModel:
        if self.model is None:
            raise RecordError(f"{where}: no knowledge record before it; cannot build a world")
        return self.model
