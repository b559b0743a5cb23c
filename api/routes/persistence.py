"""``GET /persistence``: the digest of the published world and the journal's state."""

from __future__ import annotations

from typing import Any

from fastapi import APIRouter, Request

from api.deps import WorldDep
from api.persistence import persistence_status

router = APIRouter(tags=["system"])


@router.get("/persistence", summary="World digest and journal state")
def get_persistence(world: WorldDep, request: Request) -> dict[str, Any]:
    """``digest``: SHA-256 of the world published now (equal digests, equal worlds:
    ids, classes, positions, covariances); ``journal``: the data directory's state
    (records, snapshot, archives, what the last start recovered), ``null`` without
    ``--data-dir``."""
    digest, journal = world.digest(lambda: persistence_status(request.app))
    return {"digest": digest, "journal": journal}
