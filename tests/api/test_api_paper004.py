"""Paper 004 over HTTP: confidence on GET /world, empty scans with a sensor pose."""

from __future__ import annotations

from typing import Any

from fastapi.testclient import TestClient


def scan(t: float) -> dict[str, Any]:
    return {
        "detections": [
            {
                "time": t,
                "class": "Cup",
                "position": [1.0, 2.0],
                "source": "r1",
                "detector": "lidar",
            },
            {"time": t, "class": "Can", "position": [12.0, 2.0], "source": "r1"},
        ]
    }


def seeded(client: TestClient) -> None:
    for k in range(6):
        assert client.post("/detections", json=scan(0.5 * k)).status_code == 200


def existence(client: TestClient, time: float) -> dict[str, float]:
    objects = client.get("/world", params={"time": time, "min_existence": 1e-6}).json()["objects"]
    return {o["class"]: o["existence"] for o in objects}


SENSOR = {"pose": [0.0, 0.0, 0.0], "time": 3.0, "source": "r1", "detector": "lidar"}


def test_an_empty_scan_with_a_pose_is_negative_information(client: TestClient) -> None:
    seeded(client)
    before = existence(client, 3.0)
    response = client.post("/detections", json={"detections": [], "sensor": SENSOR})
    assert response.status_code == 200, response.text
    assert response.json() == {"applied": 0, "time": 3.0, "ignored": 0}
    after = existence(client, 3.0)
    assert after["Cup"] < before["Cup"] - 0.01  # 2.2 m away: inside the lidar's 5 m
    assert abs(after["Can"] - before["Can"]) < 1e-12  # 12 m away: outside


def test_an_empty_batch_without_a_sensor_is_still_refused(client: TestClient) -> None:
    response = client.post("/detections", json={"detections": []})
    assert response.status_code == 422
    assert response.json()["detail"][0]["loc"] == ["body", "detections"]


def test_a_bad_sensor_is_refused_with_its_path(client: TestClient) -> None:
    seeded(client)
    bad = {"detections": [], "sensor": {**SENSOR, "pose": [0.0, 0.0]}}
    response = client.post("/detections", json=bad)
    assert response.status_code == 422
    assert ["body", "sensor", "pose"] in [item["loc"] for item in response.json()["detail"]]
    typo = {"detections": [], "sensor": {**SENSOR, "heading": 1.0}}
    response = client.post("/detections", json=typo)
    assert response.status_code == 422
    assert ["body", "sensor", "heading"] in [item["loc"] for item in response.json()["detail"]]


def test_objects_carry_confidence_and_the_world_filters_by_it(client: TestClient) -> None:
    seeded(client)
    objects = client.get("/world").json()["objects"]
    assert {o["confidence"]["state"] for o in objects} == {"valid"}
    assert all(o["confidence"]["value"] == 1.0 for o in objects)
    # unseen for 2 s at the default rate 0.1/s: c = exp(-0.2)
    later = client.get("/world", params={"time": 4.5, "min_existence": 1e-6}).json()["objects"]
    assert later and all(abs(o["confidence"]["value"] - 0.81873) < 1e-4 for o in later)
    valid = client.get("/world", params={"confidence": "valid"}).json()["objects"]
    assert [o["id"] for o in valid] == [o["id"] for o in objects]
    others = client.get(
        "/world", params=[("confidence", "suspicious"), ("confidence", "invalid")]
    ).json()["objects"]
    assert others == []
    assert client.get("/world", params={"confidence": "dubious"}).status_code == 422
