"""Helpers the API tests import (a module of its own: ``from conftest import`` finds
whichever ``conftest`` pytest imported last when several test directories run)."""

from __future__ import annotations

from typing import Any

from fastapi import FastAPI
from fastapi.testclient import TestClient

from api.app import create_app
from api.deps import get_world
from api.service import WorldService
from api.settings import Settings

MAX_BATCH = 20


def make_app(service: WorldService, **settings: Any) -> FastAPI:
    settings.setdefault("allowed_hosts", ("testserver",))
    app = create_app(Settings(knowledge=service.knowledge_path, max_batch=MAX_BATCH, **settings))
    app.dependency_overrides[get_world] = lambda: service
    return app


def scene(t: float) -> list[dict[str, Any]]:
    """One scan of robot r1: a cup, a coke can and itself moving along x."""
    return [
        {"time": t, "class": "Cup", "position": [1.0, 2.0], "source": "r1"},
        {"time": t, "class": "CokeCan", "position": [3.0, 2.0], "source": "r1"},
        {"time": t, "class": "Robot", "position": [0.2 * t, 0.0], "label": "r1", "source": "r1"},
    ]


def snapshot(client: TestClient) -> dict[str, Any]:
    """Everything a refused request must leave as it was."""
    return {
        "world": client.get("/world").json(),
        "hypotheses": client.get("/hypotheses", params={"limit": 1000}).json(),
        "health": client.get("/health").json(),
        "knowledge": client.get("/knowledge").json(),
    }


def locs(response: Any) -> list[list[str | int]]:
    return [item["loc"] for item in response.json()["detail"]]
