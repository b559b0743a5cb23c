"""Typed dependencies of the routes."""

from __future__ import annotations

from typing import Annotated

from fastapi import Depends, Request

from api.service import WorldService
from api.settings import Settings

# Both are ``async``: FastAPI runs a plain ``def`` dependency in a worker thread, a hop
# that costs more than the attribute read.


async def get_world(request: Request) -> WorldService:
    """The process's world service, built by the app's lifespan (tests override this)."""
    service: WorldService = request.app.state.world
    return service


async def get_settings(request: Request) -> Settings:
    settings: Settings = request.app.state.settings
    return settings


WorldDep = Annotated[WorldService, Depends(get_world)]
SettingsDep = Annotated[Settings, Depends(get_settings)]
