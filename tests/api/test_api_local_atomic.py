"""Issue 30 case 7: ``POST /local/{robot}/detections`` is all or nothing, like
``POST /detections``, and local models are bounded by the sources they count as."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from api_helpers import make_app, snapshot
from fastapi.testclient import TestClient

from api.service import WorldService


def cup(t: float, source: str = "rob1") -> dict[str, Any]:
    return {"time": t, "class": "Cup", "position": [1.0, 2.0], "source": source}


def test_a_local_post_whose_report_the_world_refuses_changes_no_model(client: TestClient) -> None:
    assert client.post("/local/rob1/detections", json=cup(5.0)).status_code == 200
    local_before = client.get("/local/rob1/world").json()
    assert local_before["time"] == 5.0
    # another source moves the world on: the robot's next report is too old for it
    assert client.post("/detections", json=cup(100.0, "r9")).status_code == 200
    before = snapshot(client)
    response = client.post("/local/rob1/detections", json=cup(6.0))
    assert response.status_code == 409, response.text
    assert "rob1" in response.json()["detail"] and "nothing was applied" in response.text
    assert client.get("/local/rob1/world").json() == local_before  # the 409 kept nothing
    assert snapshot(client) == before


def test_a_new_robot_refused_with_409_keeps_no_local_model(client: TestClient) -> None:
    assert client.post("/detections", json=cup(100.0, "r9")).status_code == 200
    before = snapshot(client)
    assert client.post("/local/rob2/detections", json=cup(1.0, "rob2")).status_code == 409
    assert client.get("/local/rob2/world").status_code == 404
    assert snapshot(client) == before


def test_robots_beyond_max_sources_are_refused_and_keep_nothing(knowledge_file: Path) -> None:
    service = WorldService.from_file(knowledge_file, max_sources=3)
    with TestClient(make_app(service)) as client:
        assert client.post("/detections", json=cup(0.5, "r9")).status_code == 200
        answers = [
            client.post(f"/local/rob{i}/detections", json=cup(1.0 + 0.01 * i, f"rob{i}"))
            for i in range(10)
        ]
        assert [a.status_code for a in answers] == [200, 200] + [422] * 8
        assert answers[2].json()["detail"][0]["loc"] == ["path", "robot"]
        assert "at most 3" in answers[2].json()["detail"][0]["msg"]
        for i in range(10):
            expected = 200 if i < 2 else 404
            assert client.get(f"/local/rob{i}/world").status_code == expected
        # a known robot goes on; a reset drops local models with the sources
        assert client.post("/local/rob1/detections", json=cup(1.5, "rob1")).status_code == 200
        assert client.post("/reset").status_code == 200
        assert client.get("/local/rob1/world").status_code == 404
        assert client.post("/local/rob7/detections", json=cup(2.0, "rob7")).status_code == 200
