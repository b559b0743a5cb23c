"""Snapshots of a world model's internal state, tagged so newer code never misreads them.

A snapshot is a pickle of the world model's state (every attribute except the
knowledge and the filter built from it, which are rebuilt from the knowledge
document stored beside it). It is tagged with :data:`SNAPSHOT_FORMAT` and with
:data:`CODE_TAG`, a SHA-256 over the source of the modules whose classes the
pickle holds (``semwm/world*.py``, ``semwm/mhf``, ``semwm/filters``,
``semwm/knowledge``). Any change to that code changes the tag, and a snapshot
with another tag is not loaded: the world is rebuilt from the journal instead.
"""

from __future__ import annotations

import hashlib
import pickle
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from semwm.knowledge.model import Knowledge
from semwm.persistence.records import payload_text
from semwm.persistence.replay import knowledge_from_payload
from semwm.world import WorldModel

SNAPSHOT_FORMAT = 1
# rebuilt from the knowledge document, with the engine of the process that restores
_DERIVED = ("_knowledge", "_mhf", "_region_bounds", "_reader", "engine")


def _code_tag() -> str:
    root = Path(__file__).resolve().parent.parent
    files = sorted(
        [*root.glob("world*.py"), *root.glob("detection.py"), *root.glob("validation.py")]
        + [p for sub in ("mhf", "filters", "knowledge") for p in (root / sub).rglob("*.py")]
    )
    digest = hashlib.sha256()
    for path in files:
        digest.update(path.relative_to(root).as_posix().encode())
        digest.update(path.read_bytes())
    return digest.hexdigest()[:16]


CODE_TAG = _code_tag()


class SnapshotMismatch(Exception):
    """A snapshot this code must not read (other format or code); rebuild instead."""


@dataclass(frozen=True)
class Snapshot:
    """A stored snapshot: the journal position it covers and its bytes."""

    seq: int
    format: int
    code: str
    knowledge: str
    state: bytes


def take_snapshot(model: WorldModel, seq: int) -> Snapshot:
    """The state of ``model`` after journal record ``seq``."""
    state = {k: v for k, v in vars(model).items() if k not in _DERIVED}
    knowledge = model.knowledge
    text = payload_text(
        {"document": knowledge.document.model_dump(mode="json"), "source": knowledge.source}
    )
    return Snapshot(seq, SNAPSHOT_FORMAT, CODE_TAG, text, pickle.dumps(state, protocol=5))


def restore_snapshot(snapshot: Snapshot) -> WorldModel:
    """The world model of ``snapshot``; :class:`SnapshotMismatch` if this code must not
    read it (other format, other code, or a state with other attributes)."""
    if snapshot.format != SNAPSHOT_FORMAT:
        raise SnapshotMismatch(
            f"snapshot format {snapshot.format}, this code reads {SNAPSHOT_FORMAT}"
        )
    if snapshot.code != CODE_TAG:
        raise SnapshotMismatch(f"snapshot written by code {snapshot.code}, this is {CODE_TAG}")
    import json

    knowledge: Knowledge = knowledge_from_payload(json.loads(snapshot.knowledge), "snapshot")
    try:
        state: dict[str, Any] = pickle.loads(snapshot.state)
    except Exception as error:  # a damaged or foreign pickle: rebuild, never misread
        raise SnapshotMismatch(f"snapshot does not unpickle: {error}") from None
    model = WorldModel(
        knowledge,
        reorder_window=float(state.get("reorder_window", 0.0)),
        hold=float(state.get("_hold", 0.0)),
    )
    expected = {k for k in vars(model) if k not in _DERIVED}
    if set(state) != expected:
        raise SnapshotMismatch(
            f"snapshot attributes {sorted(set(state) ^ expected)} differ from this code's"
        )
    vars(model).update(state)
    return model
