"""Fixtures of the API tests: an app over a world model built in code (helpers they
import are in ``api_helpers``)."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import api_knowledge as knowledge_data
import pytest
from api_helpers import make_app, scene
from fastapi.testclient import TestClient

from api.service import WorldService
from semwm.knowledge.loader import dump_document
from semwm.world import WorldModel


@pytest.fixture
def knowledge_file(tmp_path: Path) -> Path:
    path = tmp_path / "knowledge.yaml"
    dump_document(knowledge_data.document(), path)
    return path


@pytest.fixture
def service(knowledge_file: Path) -> WorldService:
    model = WorldModel(knowledge_data.knowledge(str(knowledge_file)), reorder_window=0.5)
    return WorldService(model, knowledge_file)


@pytest.fixture
def client(service: WorldService) -> Iterator[TestClient]:
    with TestClient(make_app(service)) as test_client:
        yield test_client


@pytest.fixture
def seeded(client: TestClient) -> TestClient:
    """A client whose world holds a cup, a coke can and a moving robot (time 2.5 s)."""
    for step in range(6):
        response = client.post("/detections", json={"detections": scene(step * 0.5)})
        assert response.status_code == 200, response.text
    return client


def pytest_configure(config: pytest.Config) -> None:
    config.addinivalue_line(
        "markers", "slow: a fault-injection test of several seconds (runs in CI all the same)"
    )
