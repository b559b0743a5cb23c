"""Wiring persistence and recording into the service (``--data-dir``, ``--record``).

:func:`attach_persistence` runs inside the app's lifespan: with a data directory
it opens a :class:`~semwm.persistence.DurableWorld` (restoring the world), makes
the service use its world model and adds it as a change hook, so every accepted
change is journaled before it is acknowledged; with ``record`` it adds an MCAP
recorder. Both are closed when the server stops.
"""

from __future__ import annotations

import logging
from collections.abc import Iterator
from contextlib import ExitStack, contextmanager
from typing import Any

from fastapi import FastAPI

from api.service import WorldService
from api.settings import Settings
from semwm.knowledge.model import Knowledge

logger = logging.getLogger("api")


@contextmanager
def attach_persistence(app: FastAPI, settings: Settings) -> Iterator[None]:
    """Open the data directory and the recording for the lifetime of the app."""
    service: WorldService | None = getattr(app.state, "world", None)
    app.state.durable = None
    with ExitStack() as stack:
        if service is not None and settings.data_dir is not None:
            from semwm.persistence import DurableWorld, StoreError

            try:
                durable = DurableWorld.open(
                    settings.data_dir,
                    service.knowledge,
                    reorder_window=settings.reorder_window,
                    hold=settings.hold,
                    sync=settings.sync,
                    snapshot_every=settings.snapshot_every,
                    compact_every=settings.compact_every,
                    on_damage=settings.on_damage,
                    knowledge_from=settings.knowledge_from
                    or ("journal" if settings.write_back else "refuse"),
                )
            except StoreError as error:  # the operator's message, before the server's trace
                logger.error("not starting: %s", error)
                raise
            stack.callback(durable.close)
            service.use_model(durable.model)
            _write_back_journal_knowledge(service, durable.model.knowledge, settings)
            service.hooks.append(durable)
            service.storage_probe = durable.writable
            if durable.recovery.damaged:
                service.store_damage = (list(durable.recovery.damage), durable.recovery.lost)
            app.state.durable = durable
            logger.info("data dir %s: %s", settings.data_dir, durable.recovery.to_dict())
        if service is not None and settings.record is not None:
            from semwm.persistence.mcap_io import McapRecorder

            recorder = McapRecorder.create(settings.record, lambda: service.model)
            stack.callback(recorder.close)
            recorder.start(service.knowledge, settings.reorder_window, settings.hold)
            service.hooks.append(recorder)
            logger.info("recording to %s", settings.record)
        yield


def _write_back_journal_knowledge(
    service: WorldService, knowledge: Knowledge, settings: Settings
) -> None:
    """With ``--write-back``, the journal's knowledge in force is written to the file
    when it differs (live edits the file had not seen)."""
    path = service.knowledge_path
    if not settings.write_back or path is None or settings.knowledge_from == "file":
        return
    from semwm.knowledge.loader import dump_document, load_document

    try:
        same = load_document(path) == knowledge.document
    except Exception:  # unreadable: written anew
        same = False
    if not same:
        dump_document(knowledge.document, path)
        logger.warning("%s: written from the journal's knowledge (--write-back)", path)


def persistence_status(app: FastAPI) -> dict[str, Any] | None:
    durable = getattr(app.state, "durable", None)
    return None if durable is None else dict(durable.status())
