"""``GET /health`` and ``POST /reset``."""

from __future__ import annotations

from fastapi import APIRouter

from api.deps import WorldDep
from api.schemas import HealthOut, ResetOut

router = APIRouter(tags=["system"])


@router.get("/health", response_model=HealthOut, summary="Liveness and a summary")
def health(world: WorldDep) -> HealthOut:
    """``ok`` with the knowledge file, the world time and the hypothesis and object counts."""
    return HealthOut.model_validate(world.health())


@router.post("/reset", response_model=ResetOut, summary="Forget every object")
def reset(world: WorldDep) -> ResetOut:
    """Empty the world: every hypothesis and object is dropped; the knowledge stays."""
    return ResetOut(time=world.reset())
