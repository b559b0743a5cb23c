"""GET /health, POST /reset, settings, start-up, OpenAPI, and no 5xx from any odd input."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from api_helpers import scene, snapshot
from fastapi.testclient import TestClient

from api.app import create_app
from api.settings import Settings


def test_health(seeded: TestClient, knowledge_file: Path) -> None:
    body = seeded.get("/health").json()
    assert body["status"] == "ok"
    assert body["knowledge"] == knowledge_file.name  # its path only with a token
    assert body["time"] == 2.5
    assert body["objects"] == 3
    assert body["hypotheses"] >= 1


def test_reset_empties_the_world_and_keeps_the_knowledge(seeded: TestClient) -> None:
    knowledge = seeded.get("/knowledge").json()
    response = seeded.post("/reset")
    assert response.status_code == 200
    assert response.json() == {"status": "reset", "time": None}
    assert seeded.get("/world").json() == {"time": None, "objects": []}
    assert seeded.get("/health").json()["objects"] == 0
    assert seeded.get("/knowledge").json() == knowledge
    # After a reset, old times are accepted again.
    assert seeded.post("/detections", json={"detections": scene(0.0)}).status_code == 200


def test_settings_from_environment(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    monkeypatch.setenv("SEMWM_KNOWLEDGE", str(tmp_path / "k.yaml"))
    monkeypatch.setenv("SEMWM_PORT", "9123")
    monkeypatch.setenv("SEMWM_REORDER_WINDOW", "1.5")
    monkeypatch.setenv("SEMWM_MAX_BATCH", "7")
    monkeypatch.setenv("SEMWM_WRITE_BACK", "true")
    settings = Settings()
    assert settings.knowledge == tmp_path / "k.yaml"
    assert (settings.host, settings.port) == ("127.0.0.1", 9123)
    assert (settings.reorder_window, settings.max_batch, settings.write_back) == (1.5, 7, True)
    assert Settings(port=80).port == 80  # the command line wins over the environment


def test_app_factory_builds_the_world_in_the_lifespan(knowledge_file: Path) -> None:
    app = create_app(
        Settings(knowledge=knowledge_file, reorder_window=0.25, allowed_hosts=("testserver",))
    )
    assert not hasattr(app.state, "world")  # nothing heavy before start-up
    with TestClient(app) as client:
        assert client.get("/health").json()["knowledge"] == knowledge_file.name
        assert app.state.world.knowledge.source is not None


def test_app_without_knowledge_refuses_to_start() -> None:
    with pytest.raises(RuntimeError, match="SEMWM_KNOWLEDGE"), TestClient(create_app(Settings())):
        pass


def test_openapi_has_an_example_for_every_body(client: TestClient) -> None:
    schema = client.get("/openapi.json").json()
    bodies = 0
    for path, operations in schema["paths"].items():
        for method, operation in operations.items():
            body = operation.get("requestBody")
            if body is None:
                continue
            bodies += 1
            content = body["content"]["application/json"]
            assert content.get("examples"), f"{method.upper()} {path} has no body example"
    assert bodies >= 2
    components = schema["components"]["schemas"]
    assert components["DetectionIn"]["examples"]
    assert components["DetectionBatch"]["examples"]
    assert client.get("/docs").status_code == 200


ODD_BODIES = [
    '{"time": 1e308, "class": "Cup", "position": [1e308, -1e308]}',
    '{"time": 1, "class": "Cup", "position": [1e-320, 0], '
    '"covariance": [[1e-300, 0], [0, 1e-300]]}',
    '{"time": 1, "class": "Cup", "position": [1, 2], "covariance": [[1e300, 0], [0, 1e300]]}',
    '{"time": 1, "class": "Cup", "position": [1, 2], "covariance": [[1, 0], [0]]}',
    '{"time": 1, "class": "Cup", "position": [1, 2], "covariance": [1, 0]}',
    '{"time": true, "class": 5, "position": {"x": 1}}',
    '{"time": 1, "class": "Cup", "position": [1, 2], "sensor_position": [1, 2, 3, 4]}',
    '{"time": 1, "class": "Cup", "position": [1, 2], "source": 12}',
    '{"detections": [null, 1, "x", []]}',
    '{"detections": null}',
    '{"time": 1, "class": "Cup", "position": [1, 2]' + " " * 10 + "}" * 100,
    "[" * 5000 + "]" * 5000,
    '"just a string"',
    "NaN",
    json.dumps({"time": -1e9, "class": "Robot", "position": [0, 0], "label": "x" * 10000}),
]


@pytest.mark.parametrize("content", ODD_BODIES, ids=range(len(ODD_BODIES)))
def test_no_input_gives_a_5xx(knowledge_file: Path, content: str) -> None:
    app = create_app(Settings(knowledge=knowledge_file, allowed_hosts=("testserver",)))
    with TestClient(app, raise_server_exceptions=False) as client:
        before = snapshot(client)
        response = client.post(
            "/detections", content=content, headers={"content-type": "application/json"}
        )
        assert response.status_code < 500, response.text
        if response.status_code >= 400:
            assert snapshot(client) == before
        for path in ("/world", "/hypotheses", "/health", "/world/objects/1"):
            assert client.get(path).status_code < 500
        assert client.get("/world", params={"time": 1e308}).status_code < 500
