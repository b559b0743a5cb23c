"""GET /knowledge, GET|PUT /knowledge/classes/{name}, POST /knowledge/reload, write-back."""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import api_knowledge
import pytest
from api_helpers import locs, make_app, snapshot
from fastapi.testclient import TestClient

from api.service import WorldService
from semwm.knowledge.loader import load_document
from semwm.world import WorldModel

MUG = {"name": "Mug", "is_a": ["Cup"], "detection_frequency": 3.0}


def test_knowledge_is_the_document(client: TestClient) -> None:
    expected = api_knowledge.document().model_dump(mode="json", by_alias=True)
    assert client.get("/knowledge").json() == expected


def test_class_is_resolved_and_raw(client: TestClient) -> None:
    body = client.get("/knowledge/classes/CokeCan").json()
    assert body["name"] == "CokeCan"
    assert body["spec"]["is_a"] == ["Can"] and body["spec"]["filter"] is None
    assert body["resolved"]["ancestors"] == ["Can"]
    assert body["resolved"]["filter"]["type"] == "kalman"
    assert body["resolved"]["detection_frequency"] == 2.0


def test_unknown_class_is_404_listing_known(client: TestClient) -> None:
    response = client.get("/knowledge/classes/Mug")
    assert response.status_code == 404
    assert "Mug" in response.json()["detail"] and "CokeCan" in response.json()["detail"]


def test_put_adds_a_class_used_from_the_next_detection(seeded: TestClient) -> None:
    response = seeded.put("/knowledge/classes/Mug", json=MUG)
    assert response.status_code == 200, response.text
    assert response.json()["resolved"]["detection_frequency"] == 3.0
    assert response.json()["resolved"]["filter"]["type"] == "kalman"
    assert response.json()["written"] is False
    assert seeded.get("/knowledge/classes/Mug").status_code == 200
    assert [c["name"] for c in seeded.get("/knowledge").json()["classes"]][-1] == "Mug"
    detection = {"time": 3.0, "class": "Mug", "position": [5.0, 5.0]}
    assert seeded.post("/detections", json=detection).status_code == 200
    mugs = seeded.get("/world", params={"class": "Cup"}).json()["objects"]
    assert "Cup" in {o["class"] for o in mugs}  # Mug is-a Cup: the query covers both


def test_put_replaces_a_class_and_its_children_inherit(client: TestClient) -> None:
    spec = client.get("/knowledge/classes/Can").json()["spec"]
    spec["detection_frequency"] = 7.0
    assert client.put("/knowledge/classes/Can", json=spec).status_code == 200
    coke = client.get("/knowledge/classes/CokeCan").json()["resolved"]
    assert coke["detection_frequency"] == 7.0


NOT_PD = [[1.0, 0.0], [0.0, -1.0]]
BAD_EDITS: list[tuple[str, str, Any, list[list[str | int]]]] = [
    ("unknown-parent", "Mug", {**MUG, "is_a": ["Glass"]}, [["body", "is_a", 0]]),
    ("not-pd-noise", "Cup", {"name": "Cup", "is_a": ["Can"], "measurement_noise": NOT_PD},
     [["body", "measurement_noise"]]),
    ("wrong-size-noise", "Cup", {"name": "Cup", "is_a": ["Can"], "measurement_noise": [[1.0]]},
     [["body", "measurement_noise"]]),
    ("cycle", "Can", {"name": "Can", "is_a": ["CokeCan"]}, None),
    ("no-filter-anywhere", "Mug", {"name": "Mug", "detection_frequency": 1.0}, [["body"]]),
    ("name-differs", "Mug", {**MUG, "name": "Glass"}, [["body", "name"]]),
    ("unknown-field", "Mug", {**MUG, "colour": "red"}, [["body", "colour"]]),
    ("negative-frequency", "Mug", {**MUG, "detection_frequency": -1},
     [["body", "detection_frequency"]]),
    ("unknown-filter-type", "Mug", {**MUG, "filter": {"type": "particle"}}, [["body", "filter"]]),
    ("missing-name", "Mug", {"is_a": ["Cup"]}, [["body", "name"]]),
    ("not-an-object", "Mug", [MUG], [["body"]]),
]  # fmt: skip


@pytest.mark.parametrize(
    ("name", "body", "expected"),
    [(n, b, e) for _, n, b, e in BAD_EDITS],
    ids=[i for i, *_ in BAD_EDITS],
)
def test_rejected_edit_is_422_and_changes_nothing(
    seeded: TestClient, name: str, body: Any, expected: list[list[str | int]] | None
) -> None:
    before = snapshot(seeded)
    response = seeded.put(f"/knowledge/classes/{name}", json=body)
    assert response.status_code == 422, response.text
    if expected is not None:
        assert locs(response)[: len(expected)] == expected
    else:
        assert locs(response)  # a cycle: located wherever the resolver finds it
    assert all(item["msg"] for item in response.json()["detail"])
    assert snapshot(seeded) == before


def test_rejected_edit_with_nan_is_422(seeded: TestClient) -> None:
    before = snapshot(seeded)
    content = '{"name": "Mug", "is_a": ["Cup"], "detection_frequency": NaN}'
    response = seeded.put(
        "/knowledge/classes/Mug", content=content, headers={"content-type": "application/json"}
    )
    assert response.status_code == 422
    assert locs(response) == [["body", "detection_frequency"]]
    assert snapshot(seeded) == before


def test_edit_breaking_a_subclass_is_reported_there(seeded: TestClient) -> None:
    # Can without a filter: CokeCan and BeerCan inherit nothing and have no filter either.
    before = snapshot(seeded)
    response = seeded.put("/knowledge/classes/Can", json={"name": "Can", "detection_frequency": 2})
    assert response.status_code == 422
    assert ["knowledge", "classes", 1] in locs(response)  # CokeCan, by its document path
    assert snapshot(seeded) == before


def test_reload_rereads_the_file(client: TestClient, knowledge_file: Path) -> None:
    text = knowledge_file.read_text().replace("clutter_frequency: 0.01", "clutter_frequency: 0.2")
    knowledge_file.write_text(text)
    response = client.post("/knowledge/reload")
    assert response.status_code == 200, response.text
    assert response.json()["classes"] == ["Can", "CokeCan", "BeerCan", "Cup", "Robot"]
    assert client.get("/knowledge").json()["detectors"][0]["clutter_frequency"] == 0.2


@pytest.mark.parametrize(
    "content",
    [
        "world:\n  dimension: 2\nclasses:\n  - name: Cup\n    is_a: [Glass]\ndetectors: []\n",
        "classes: [\n",
        "",
    ],
    ids=["unresolvable", "not-yaml", "empty"],
)
def test_broken_file_keeps_the_running_knowledge(
    seeded: TestClient, knowledge_file: Path, content: str
) -> None:
    before = snapshot(seeded)
    knowledge_file.write_text(content)
    response = seeded.post("/knowledge/reload")
    assert response.status_code == 422, response.text
    body = response.json()
    assert "unchanged" in body["detail"]
    assert body["problems"]
    name = re.escape(str(knowledge_file))
    assert all(re.match(rf"{name}(:\d+)?: \S", p) for p in body["problems"]), body["problems"]
    assert snapshot(seeded) == before


def test_missing_file_keeps_the_running_knowledge(seeded: TestClient, knowledge_file: Path) -> None:
    before = snapshot(seeded)
    knowledge_file.unlink()
    response = seeded.post("/knowledge/reload")
    assert response.status_code == 422
    assert str(knowledge_file) in response.json()["problems"][0]
    assert snapshot(seeded) == before


def test_write_back_writes_accepted_edits_only(knowledge_file: Path) -> None:
    model = WorldModel(api_knowledge.knowledge(str(knowledge_file)), reorder_window=0.5)
    service = WorldService(model, knowledge_file, write_back=True)
    with TestClient(make_app(service)) as client:
        response = client.put("/knowledge/classes/Mug", json=MUG)
        assert response.status_code == 200
        assert response.json()["written"] is True
        assert "Mug" in [c.name for c in load_document(knowledge_file).classes]
        text = knowledge_file.read_text()
        bad = {**MUG, "is_a": ["Glass"]}
        assert client.put("/knowledge/classes/Mug", json=bad).status_code == 422
        assert knowledge_file.read_text() == text
        assert client.post("/knowledge/reload").status_code == 200
        assert client.get("/knowledge/classes/Mug").status_code == 200


def test_changing_the_filter_of_tracked_classes_gives_no_5xx(seeded: TestClient) -> None:
    imm = seeded.get("/knowledge/classes/Robot").json()["spec"]
    kalman = seeded.get("/knowledge/classes/Can").json()["spec"]
    assert seeded.put("/knowledge/classes/Cup", json={**imm, "name": "Cup"}).status_code == 200
    assert (
        seeded.put("/knowledge/classes/Robot", json={**kalman, "name": "Robot"}).status_code == 200
    )
    assert seeded.get("/world").status_code == 200
    detections = [
        {"time": 3.0, "class": "Cup", "position": [1.0, 2.0], "source": "r1"},
        {"time": 3.0, "class": "Robot", "position": [0.6, 0.0], "label": "r1", "source": "r1"},
    ]
    assert seeded.post("/detections", json={"detections": detections}).status_code == 200
    classes = {o["class"]: o for o in seeded.get("/world").json()["objects"]}
    assert classes["Cup"]["mode_probabilities"] is not None  # now an IMM class
    assert seeded.get("/hypotheses").status_code == 200
