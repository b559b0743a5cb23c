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
    assert response.json() == {"applied": 0, "time": 3.0, "ignored": 0, "ignored_detections": []}
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


def test_post_actions_kicks_the_ball_and_detections_resolve_it(client: TestClient) -> None:
    ball = {
        "name": "Ball",
        "category": "passive",
        "detection_frequency": 10.0,
        "filter": {
            "type": "kalman",
            "model": {"motion_model": "first_order", "system_noise": [[0.05, 0], [0, 0.05]]},
        },
        "measurement_noise": [[0.0025, 0], [0, 0.0025]],
        "initial_velocity_covariance": [[0.01, 0], [0, 0.01]],
    }
    assert client.put("/knowledge/classes/Ball", json=ball).status_code in (200, 201)
    for k in range(6):
        body = {"time": 0.1 * k, "class": "Ball", "position": [0.0, 0.0], "source": "r1"}
        assert client.post("/detections", json=body).status_code == 200
    (obj,) = client.get("/world", params={"class": "Ball"}).json()["objects"]
    kick = {"time": 0.5, "type": "kick", "source": "r1", "object": obj["id"]}
    response = client.post("/actions", json={**kick, "direction": [1.0, 0.0], "speed": 2.0})
    assert response.status_code == 200, response.text
    assert response.json() == {"objects": [obj["id"]], "hypotheses": 2}
    alpha = 0.3  # the passive default
    for k in range(1, 8):
        tau = 0.1 * k
        x = 2.0 * tau - alpha * tau**2 / 2
        body = {"time": 0.5 + tau, "class": "Ball", "position": [x, 0.0], "source": "r1"}
        assert client.post("/detections", json=body).status_code == 200
    (moved,) = client.get("/world", params={"class": "Ball"}).json()["objects"]
    assert moved["id"] == obj["id"]
    assert abs(moved["velocity"][0] - (2.0 - alpha * 0.7)) < 0.2
    bad = client.post("/actions", json={**kick, "direction": [1.0], "speed": 1.0})
    assert bad.status_code == 422
    assert ["body", "direction"] in [item["loc"] for item in bad.json()["detail"]]
    late = client.post("/actions", json={**kick, "time": 0.1, "direction": [1, 0], "speed": 1})
    assert late.status_code == 409
