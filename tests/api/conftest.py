"""Fixtures of the API tests: an app over a world model built in code, and helpers."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any

import api_knowledge as knowledge_data
import pytest
from fastapi import FastAPI
from fastapi.testclient import TestClient

from api.app import create_app
from api.deps import get_world
from api.service import WorldService
from api.settings import Settings
from semwm.knowledge.loader import dump_document
from semwm.world import WorldModel

MAX_BATCH = 20


@pytest.fixture
def knowledge_file(tmp_path: Path) -> Path:
    path = tmp_path / "knowledge.yaml"
    dump_document(knowledge_data.document(), path)
    return path


def make_app(service: WorldService, **settings: Any) -> FastAPI:
    settings.setdefault("allowed_hosts", ("testserver",))
    app = create_app(Settings(knowledge=service.knowledge_path, max_batch=MAX_BATCH, **settings))
    app.dependency_overrides[get_world] = lambda: service
    return app


@pytest.fixture
def service(knowledge_file: Path) -> WorldService:
    model = WorldModel(knowledge_data.knowledge(str(knowledge_file)), reorder_window=0.5)
    return WorldService(model, knowledge_file)


@pytest.fixture
def client(service: WorldService) -> Iterator[TestClient]:
    with TestClient(make_app(service)) as test_client:
        yield test_client


def scene(t: float) -> list[dict[str, Any]]:
    """One scan of robot r1: a cup, a coke can and itself moving along x."""
    return [
        {"time": t, "class": "Cup", "position": [1.0, 2.0], "source": "r1"},
        {"time": t, "class": "CokeCan", "position": [3.0, 2.0], "source": "r1"},
        {"time": t, "class": "Robot", "position": [0.2 * t, 0.0], "label": "r1", "source": "r1"},
    ]


@pytest.fixture
def seeded(client: TestClient) -> TestClient:
    """A client whose world holds a cup, a coke can and a moving robot (time 2.5 s)."""
    for step in range(6):
        response = client.post("/detections", json={"detections": scene(step * 0.5)})
        assert response.status_code == 200, response.text
    return client


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
