"""POST /detections: accepted input, and every bad input refused with its path, changing nothing."""

from __future__ import annotations

import json
from typing import Any

import pytest
from api_helpers import MAX_BATCH, locs, snapshot
from fastapi.testclient import TestClient

OK = {"time": 3.0, "class": "Cup", "position": [1.0, 2.0], "source": "r1"}


def with_(**changes: Any) -> dict[str, Any]:
    return {**OK, **changes}


def batch(bad: dict[str, Any], at: int = 3, size: int = 5) -> dict[str, Any]:
    items: list[dict[str, Any]] = [dict(OK) for _ in range(size)]
    items[at] = bad
    return {"detections": items}


def test_single_detection_is_applied(client: TestClient) -> None:
    response = client.post("/detections", json=OK)
    assert response.status_code == 200
    assert response.json() == {"applied": 1, "time": 3.0, "ignored": 0, "ignored_detections": []}
    assert client.get("/health").json()["time"] == 3.0


def test_batch_is_applied_whole(client: TestClient) -> None:
    body = {"detections": [with_(time=1.0), with_(time=1.2, **{"class": "CokeCan"})]}
    response = client.post("/detections", json=body)
    assert response.status_code == 200
    assert response.json()["applied"] == 2
    assert response.json()["time"] == 1.2


def test_optional_fields_are_accepted(client: TestClient) -> None:
    detection = with_(
        covariance=[[0.01, 0.0], [0.0, 0.02]],
        detector="lidar",
        label="cup-7",
        sensor_position=[0.0, 0.0],
    )
    response = client.post("/detections", json=detection)
    assert response.status_code == 200, response.text
    assert response.json()["applied"] == 1


def test_detection_beyond_detector_range_is_ignored_not_refused(client: TestClient) -> None:
    detection = with_(detector="lidar", sensor_position=[10.0, 10.0])
    response = client.post("/detections", json=detection)
    assert response.status_code == 200
    assert response.json()["ignored"] == 1


# (id, raw body, expected 422 locations); raw bodies so that NaN/Infinity reach the server.
NAN_TIME = '{"time": NaN, "class": "Cup", "position": [1, 2]}'
INF_IN_BATCH = json.dumps(batch(with_(position=[1.0, 1.0]))).replace("[1.0, 1.0]", "[Infinity, 1]")
NEG_INF_COV = json.dumps(with_(covariance=[[1.0, 0.0], [0.0, 1.0]])).replace(
    "[0.0, 1.0]]", "[0.0, -Infinity]]"
)

BAD_JSON: list[tuple[str, Any, list[list[str | int]]]] = [
    ("time-nan", NAN_TIME, [["body", "time"]]),
    ("position-infinite-in-batch", INF_IN_BATCH, [["body", "detections", 3, "position", 0]]),
    ("covariance-negative-infinity", NEG_INF_COV, [["body", "covariance", 1, 1]]),
    ("position-3d-in-2d-world", with_(position=[1.0, 2.0, 3.0]), [["body", "position"]]),
    (
        "position-3d-in-batch",
        batch(with_(position=[1, 2, 3])),
        [["body", "detections", 3, "position"]],
    ),
    ("position-1d", with_(position=[1.0]), [["body", "position"]]),
    (
        "position-not-numbers",
        with_(position=["a", "b"]),
        [["body", "position", 0], ["body", "position", 1]],
    ),
    ("unknown-class", with_(**{"class": "Mug"}), [["body", "class"]]),
    ("empty-class", with_(**{"class": ""}), [["body", "class"]]),
    ("unknown-detector", with_(detector="radar"), [["body", "detector"]]),
    ("covariance-ragged", with_(covariance=[[1.0, 0.0], [0.0]]), [["body", "covariance"]]),
    ("covariance-wrong-shape", with_(covariance=[[1.0, 0.0]]), [["body", "covariance"]]),
    (
        "covariance-3x3",
        with_(covariance=[[1, 0, 0], [0, 1, 0], [0, 0, 1]]),
        [["body", "covariance"]],
    ),
    ("covariance-not-pd", with_(covariance=[[1.0, 2.0], [2.0, 1.0]]), [["body", "covariance"]]),
    (
        "covariance-in-batch",
        batch(with_(covariance=[[0, 0], [0, 0]]), at=0),
        [["body", "detections", 0, "covariance"]],
    ),
    ("time-string", with_(time="soon"), [["body", "time"]]),
    ("missing-position", {"time": 1.0, "class": "Cup"}, [["body", "position"]]),
    ("unknown-field", with_(colour="red"), [["body", "colour"]]),
    ("empty-batch", {"detections": []}, [["body", "detections"]]),
    ("oversized-batch", {"detections": [OK] * (MAX_BATCH + 1)}, [["body", "detections"]]),
    ("batch-not-a-list", {"detections": {"a": 1}}, [["body", "detections"]]),
    ("batch-extra-key", {"detections": [OK], "robot": "r1"}, [["body", "robot"]]),
    ("body-a-list", [OK], [["body"]]),
    ("body-a-number", 42, [["body"]]),
    ("body-null", None, [["body"]]),
]


@pytest.mark.parametrize(
    ("body", "expected"), [(b, e) for _, b, e in BAD_JSON], ids=[i for i, _, _ in BAD_JSON]
)
def test_bad_detection_is_refused_and_changes_nothing(
    seeded: TestClient, body: Any, expected: list[list[str | int]]
) -> None:
    before = snapshot(seeded)
    if isinstance(body, str):
        response = seeded.post(
            "/detections", content=body, headers={"content-type": "application/json"}
        )
    else:
        response = seeded.post("/detections", json=body)
    assert response.status_code == 422, response.text
    assert locs(response) == expected
    assert all(item["msg"] for item in response.json()["detail"])
    assert snapshot(seeded) == before


def test_batch_reports_every_problem_and_applies_nothing(seeded: TestClient) -> None:
    before = snapshot(seeded)
    items = [dict(OK) for _ in range(6)]
    items[1] = with_(**{"class": "Mug"})
    items[3] = with_(position=[1.0, 2.0, 3.0])
    items[5] = with_(time="x")
    response = seeded.post("/detections", json={"detections": items})
    assert response.status_code == 422
    assert locs(response) == [
        ["body", "detections", 1, "class"],
        ["body", "detections", 3, "position"],
        ["body", "detections", 5, "time"],
    ]
    unknown = response.json()["detail"][0]["msg"]
    assert "Mug" in unknown and "CokeCan" in unknown  # names the known classes
    assert snapshot(seeded) == before


@pytest.mark.parametrize(
    ("content", "content_type"),
    [
        ('{"time": 1.0, "class": ', "application/json"),
        ("", "application/json"),
        ("time=1", "application/json"),
        ("\xff\xfe", "application/json"),
    ],
    ids=["truncated-json", "empty-body", "not-json", "not-utf8"],
)
def test_malformed_body_is_422(seeded: TestClient, content: str, content_type: str) -> None:
    before = snapshot(seeded)
    response = seeded.post(
        "/detections", content=content.encode("latin-1"), headers={"content-type": content_type}
    )
    assert response.status_code == 422, response.text
    assert locs(response)[0][0] == "body"
    assert snapshot(seeded) == before


def test_too_old_detection_is_409_naming_the_latest_time(seeded: TestClient) -> None:
    before = snapshot(seeded)
    response = seeded.post("/detections", json=with_(time=1.0))
    assert response.status_code == 409
    assert "latest processed time 2.5 s" in response.json()["detail"]
    assert snapshot(seeded) == before


def test_too_old_detection_in_a_batch_applies_nothing(seeded: TestClient) -> None:
    before = snapshot(seeded)
    response = seeded.post("/detections", json={"detections": [with_(time=3.0), with_(time=0.0)]})
    assert response.status_code == 409
    assert snapshot(seeded) == before


def test_late_detection_inside_the_reorder_window_is_accepted(seeded: TestClient) -> None:
    response = seeded.post("/detections", json=with_(time=2.2))
    assert response.status_code == 200
    assert response.json()["time"] == 2.5


def test_validation_error_echoes_non_finite_input_as_text(client: TestClient) -> None:
    response = client.post(
        "/detections", content=NAN_TIME, headers={"content-type": "application/json"}
    )
    assert response.status_code == 422
    assert response.json()["detail"][0]["input"] == "nan"


def test_a_bare_json_array_is_refused_with_the_batch_shape(seeded: TestClient) -> None:
    before = snapshot(seeded)
    response = seeded.post("/detections", json=[OK, with_(time=3.1)])
    assert response.status_code == 422
    (item,) = response.json()["detail"]
    assert item["loc"] == ["body"]
    assert '{"detections": [...]}' in item["msg"] and "bare JSON array" in item["msg"]
    assert snapshot(seeded) == before
