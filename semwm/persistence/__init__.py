"""Persistence: a journal of every accepted change, snapshots, replay and recordings.

* :class:`DurableWorld` — a world model whose changes are journaled (SQLite, WAL)
  before they are acknowledged, restored after a crash to the world it published.
* :class:`Replayer`, :func:`model_digest` — records fed back through a world model;
  a digest of the published world to compare two worlds.
* :mod:`semwm.persistence.records` — the record format and its JSON Lines form.
* :mod:`semwm.persistence.mcap_io` — MCAP recordings (``pip install "semwm[mcap]"``).
"""

from semwm.persistence.durable import DurableWorld, KnowledgeConflict, Recovery
from semwm.persistence.journal import SYNC_POLICIES, Journal, StoreError, SyncPolicy, WriteFailed
from semwm.persistence.records import (
    Record,
    RecordError,
    batch_record,
    config_record,
    knowledge_record,
    read_jsonl,
    reset_record,
)
from semwm.persistence.replay import Replayer, model_digest, world_digest

__all__ = [
    "SYNC_POLICIES",
    "DurableWorld",
    "Journal",
    "KnowledgeConflict",
    "Record",
    "RecordError",
    "Recovery",
    "Replayer",
    "StoreError",
    "SyncPolicy",
    "WriteFailed",
    "batch_record",
    "config_record",
    "knowledge_record",
    "model_digest",
    "read_jsonl",
    "reset_record",
    "world_digest",
]
