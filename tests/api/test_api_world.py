"""GET /world, /world/objects/{id}, /hypotheses: answers and refused queries."""

from __future__ import annotations

import math

import pytest
from api_helpers import locs, snapshot
from fastapi.testclient import TestClient


def by_class(objects: list[dict[str, object]]) -> dict[object, dict[str, object]]:
    return {o["class"]: o for o in objects}


def test_empty_world(client: TestClient) -> None:
    assert client.get("/world").json() == {"time": None, "objects": []}


def test_world_holds_every_object_with_its_fields(seeded: TestClient) -> None:
    body = seeded.get("/world").json()
    assert body["time"] == 2.5
    objects = by_class(body["objects"])
    assert set(objects) == {"Cup", "CokeCan", "Robot"}
    cup = objects["Cup"]
    assert set(cup) == {
        "id", "class", "label", "position", "velocity", "covariance",
        "existence", "last_seen", "created", "mode_probabilities", "class_probabilities",
        "confidence", "tentative",
    }  # fmt: skip
    assert cup["tentative"] is False
    assert cup["class_probabilities"]["Cup"] > 0.9
    assert sum(cup["class_probabilities"].values()) == pytest.approx(1.0, abs=0.01)
    assert cup["position"] == pytest.approx([1.0, 2.0], abs=1e-6)
    assert cup["velocity"] is None and cup["mode_probabilities"] is None
    assert cup["last_seen"] == 2.5
    assert 0.0 < cup["existence"] <= 1.0  # type: ignore[operator]
    robot = objects["Robot"]
    assert robot["label"] == "r1"
    assert len(robot["velocity"]) == 2  # type: ignore[arg-type]
    modes = robot["mode_probabilities"]
    assert isinstance(modes, dict) and math.isclose(sum(modes.values()), 1.0)


def test_time_predicts_the_objects(seeded: TestClient) -> None:
    now = by_class(seeded.get("/world").json()["objects"])["Robot"]
    # 2 s after the newest scan: no scan has missed the robot since, so it is predicted
    # and only its leave rate lowers its existence (issue 28: the future applies no
    # misses that never happened)
    later_body = seeded.get("/world", params={"time": 4.5}).json()
    assert later_body["time"] == 4.5
    assert by_class(later_body["objects"])["Robot"]["existence"] > 0.5
    later_body = seeded.get("/world", params={"time": 2.7}).json()
    later = by_class(later_body["objects"])["Robot"]
    assert later["position"][0] > now["position"][0]  # type: ignore[index]
    assert later["covariance"][0][0] > now["covariance"][0][0]  # type: ignore[index]
    assert later["existence"] < now["existence"]  # type: ignore[operator]


def test_a_time_before_the_history_is_a_409(seeded: TestClient) -> None:
    """The world as it was before the reorder history is not known: 409 naming the
    times, never the current world labelled with the past time."""
    answer = seeded.get("/world", params={"time": 1.0})
    assert answer.status_code == 409, answer.text
    assert "reorder" in answer.json()["detail"]
    assert seeded.get("/world/objects/1", params={"time": 1.0}).status_code == 409
    assert seeded.get("/world", params={"time": -3.0}).json()["objects"] == []  # before all


def test_class_filter_is_taxonomy_aware(seeded: TestClient) -> None:
    cans = seeded.get("/world", params={"class": "Can"}).json()["objects"]
    assert [o["class"] for o in cans] == ["CokeCan"]
    cups = seeded.get("/world", params={"class": "Cup"}).json()["objects"]
    assert [o["class"] for o in cups] == ["Cup"]
    assert seeded.get("/world", params={"class": "BeerCan"}).json()["objects"] == []


def test_near_and_label_filters(seeded: TestClient) -> None:
    near = seeded.get("/world", params={"near": "1,2,0.5"}).json()["objects"]
    assert [o["class"] for o in near] == ["Cup"]
    wide = seeded.get("/world", params={"near": "2, 2, 1.5"}).json()["objects"]
    assert sorted(o["class"] for o in wide) == ["CokeCan", "Cup"]
    labelled = seeded.get("/world", params={"label": "r1"}).json()["objects"]
    assert [o["class"] for o in labelled] == ["Robot"]


def test_object_by_id(seeded: TestClient) -> None:
    for obj in seeded.get("/world").json()["objects"]:
        response = seeded.get(f"/world/objects/{obj['id']}")
        assert response.status_code == 200
        assert response.json() == obj


def test_unknown_object_is_404_naming_the_id(seeded: TestClient) -> None:
    response = seeded.get("/world/objects/987")
    assert response.status_code == 404
    assert "987" in response.json()["detail"]


def test_hypotheses(seeded: TestClient) -> None:
    body = seeded.get("/hypotheses", params={"limit": 3}).json()
    assert body["total"] >= len(body["hypotheses"]) >= 1
    assert len(body["hypotheses"]) <= 3
    probabilities = [h["probability"] for h in body["hypotheses"]]
    assert probabilities == sorted(probabilities, reverse=True)
    best = body["hypotheses"][0]["objects"]
    assert {o["class"] for o in best} == {"Cup", "CokeCan", "Robot"}
    assert set(best[0]) == {"id", "track", "class", "label", "position", "existence"}
    assert body["clusters"] >= 1
    # the joint count is the product of the clusters' counts, never above total^clusters
    assert 0.0 <= body["log10_joint"] <= body["clusters"] * math.log10(body["total"]) + 1e-9
    for h in body["hypotheses"]:
        assert h["log10_probability"] == pytest.approx(math.log10(h["probability"]))


BAD_QUERIES = [
    ("/world", {"class": "Mug"}, ["query", "class"]),
    ("/world", {"time": "nan"}, ["query", "time"]),
    ("/world", {"time": "inf"}, ["query", "time"]),
    ("/world", {"time": "-Infinity"}, ["query", "time"]),
    ("/world", {"time": "later"}, ["query", "time"]),
    ("/world", {"near": "1,2"}, ["query", "near"]),
    ("/world", {"near": "1,2,3,4,5"}, ["query", "near"]),
    ("/world", {"near": "1,2,3,4"}, ["query", "near"]),  # 3-d centre in a 2-d world
    ("/world", {"near": "a,b,c"}, ["query", "near"]),
    ("/world", {"near": "nan,1,1"}, ["query", "near"]),
    ("/world", {"near": "1,1,-1"}, ["query", "near"]),
    ("/world/objects/1", {"time": "nan"}, ["query", "time"]),
    ("/world/objects/one", {}, ["path", "object_id"]),
    ("/hypotheses", {"limit": 0}, ["query", "limit"]),
    ("/hypotheses", {"limit": "all"}, ["query", "limit"]),
    ("/hypotheses", {"limit": 10**6}, ["query", "limit"]),
]


@pytest.mark.parametrize(
    ("path", "params", "loc"),
    BAD_QUERIES,
    ids=[f"{p}?{'&'.join(f'{k}={v}' for k, v in q.items())}" for p, q, _ in BAD_QUERIES],
)
def test_bad_query_is_422_with_its_location(
    seeded: TestClient, path: str, params: dict[str, object], loc: list[str]
) -> None:
    before = snapshot(seeded)
    response = seeded.get(path, params=params)  # type: ignore[arg-type]
    assert response.status_code == 422, response.text
    assert locs(response) == [loc]
    assert snapshot(seeded) == before


def test_unknown_class_lists_the_known_ones(seeded: TestClient) -> None:
    message = seeded.get("/world", params={"class": "Mug"}).json()["detail"][0]["msg"]
    for name in ("Can", "CokeCan", "BeerCan", "Cup", "Robot"):
        assert name in message


def test_sources_report_the_rates_their_data_shows(seeded: TestClient) -> None:
    """GET /sources: per source and detector, the data's rates beside the knowledge's."""
    body = seeded.get("/sources").json()
    rates = [r for s in body["sources"] for r in s["rates"]]
    assert rates, body
    first = rates[0]
    assert {"detector", "clutter_hz", "knowledge_clutter_hz", "detection_hz", "warnings"} <= set(
        first
    )
    assert first["seconds"] >= 0.0
