"""Issue 30 case 8: inputs that answered 500 (or were kept) are refused with a 422 and
change nothing; the knowledge reader bounds nesting; /health hides the file's path."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest
from api_helpers import make_app, snapshot
from fastapi.testclient import TestClient

from api.service import WorldService
from api.settings import Settings
from api.testing import running_server
from semwm.detection import MAX_TIME
from semwm.knowledge import KnowledgeError
from semwm.knowledge.loader import load_knowledge
from semwm.knowledge.yaml_format import MAX_DEPTH, read_yaml

JSON = {"content-type": "application/json"}


def _post(client: TestClient, path: str, text: str) -> Any:
    return client.post(path, content=text.encode("utf-8", "surrogatepass"), headers=JSON)


@pytest.mark.parametrize("field", ["source", "label", "detector"])
@pytest.mark.parametrize("batch", [False, True])
def test_a_lone_surrogate_in_a_name_is_422_with_its_path(
    seeded: TestClient, field: str, batch: bool
) -> None:
    before = snapshot(seeded)
    one = '{"time": 3.0, "class": "Cup", "position": [1.0, 2.0], "FIELD": "x\\ud800y"}'
    one = one.replace("FIELD", field)
    body = '{"detections": [' + one + "]}" if batch else one
    response = _post(seeded, "/detections", body)
    assert response.status_code == 422, response.text
    where = ["body", "detections", 0, field] if batch else ["body", field]
    assert where in [item["loc"] for item in response.json()["detail"]]
    assert snapshot(seeded) == before


def test_a_lone_surrogate_in_a_local_post_and_a_class_edit_is_422(seeded: TestClient) -> None:
    before = snapshot(seeded)
    body = '{"time": 3.0, "class": "Cup", "position": [1.0, 2.0], "source": "\\udfff"}'
    assert _post(seeded, "/local/r1/detections", body).status_code == 422
    edit = '{"name": "Mug", "is_a": ["Cup\\ud800"]}'
    response = seeded.put("/knowledge/classes/Mug", content=edit.encode("utf-8", "surrogatepass"),
                          headers=JSON)  # fmt: skip
    assert response.status_code == 422, response.text
    assert snapshot(seeded) == before


@pytest.mark.parametrize("pose", ["[1.0, NaN, 0.0]", "[1.0, 2.0, Infinity]", "[1.0, 2.0]"])
def test_a_sensor_pose_that_is_not_finite_is_422_before_the_journal(
    tmp_path: Path, knowledge_file: Path, pose: str
) -> None:
    """With --data-dir the journal serialised the pose before the model checked it: a
    500, and /ready said 503 until the next good write."""
    settings = Settings(knowledge=knowledge_file, data_dir=tmp_path / "data", port=0)
    with running_server(settings) as url:
        import httpx

        with httpx.Client(base_url=url) as http:
            good = {"time": 1.0, "class": "Cup", "position": [1.0, 2.0], "source": "r1"}
            assert http.post("/detections", json=good).status_code == 200
            before = http.get("/persistence").json()
            body = ('{"detections": [{"time": 2.0, "class": "Cup", "position": [1.0, 2.0], '
                    '"source": "r1"}], "sensor": {"pose": POSE}}').replace("POSE", pose)  # fmt: skip
            response = http.post("/detections", content=body, headers=JSON)
            assert response.status_code == 422, response.text
            assert response.json()["detail"][0]["loc"][:3] == ["body", "sensor", "pose"]
            assert http.get("/ready").status_code == 200
            after = http.get("/persistence").json()
            assert after["journal"]["last_seq"] == before["journal"]["last_seq"]
            assert after["digest"] == before["digest"]


def test_the_service_checks_a_sensor_view_before_any_hook_sees_it(
    service: WorldService,
) -> None:
    """The Python path of the same check (a sensor dict from MQTT or a test)."""
    seen: list[Any] = []

    class Hook:
        def applying(self, record: Any) -> Any:
            seen.append(record)
            raise AssertionError("a hook saw a refused change")

    service.hooks.append(Hook())
    from api.errors import InvalidError

    with pytest.raises(InvalidError) as refused:
        service.ingest(
            [{"time": 1.0, "class": "Cup", "position": [1.0, 2.0]}],
            batch=True,
            sensor={"pose": [1.0, float("nan"), 0.0]},
        )
    assert refused.value.errors[0]["loc"][:3] == ["body", "sensor", "pose"]
    assert seen == []


@pytest.mark.parametrize("time", [-1e15, 1e15, -MAX_TIME * 1.5, MAX_TIME * 1.5])
def test_times_are_bounded_the_same_in_the_past_and_the_future(
    knowledge_file: Path, time: float
) -> None:
    """-1e15 was accepted (and became the world's time) while +1e15 was refused; with
    no max_ahead guard both were accepted."""
    service = WorldService.from_file(knowledge_file, time_guard=None)
    service.sources.guard = type(service.sources.guard)(max_ahead=None, max_jump=None)
    with TestClient(make_app(service)) as client:
        for body in ({"time": time, "class": "Cup", "position": [1.0, 2.0]},
                     {"detections": [{"time": time, "class": "Cup", "position": [1.0, 2.0]}]}):  # fmt: skip
            response = client.post("/detections", json=body)
            assert response.status_code == 422, response.text
            assert response.json()["detail"][0]["loc"][-1] == "time"
        action = {"time": time, "near": [1.0, 2.0], "direction": [1.0, 0.0], "speed": 1.0}
        assert client.post("/actions", json=action).status_code == 422
        assert client.get("/health").json()["time"] is None
        for ok in (-MAX_TIME, MAX_TIME):
            body = {"time": ok, "class": "Cup", "position": [1.0, 2.0], "source": str(ok)}
            assert client.post("/detections", json=body).status_code in (200, 409)


def _deep_yaml(depth: int) -> str:
    return "world:\n  dimension: 2\nclasses: " + "[" * depth + "]" * depth + "\n"


def test_yaml_nested_too_deep_is_one_located_problem() -> None:
    data, _, problems = read_yaml(_deep_yaml(100_000))
    assert data is None and len(problems) == 1
    assert problems[0].line == 3 and f"deeper than {MAX_DEPTH}" in problems[0].message
    # the same nesting in block style, and just within the bound, reads
    block = "a:\n" + "".join("  " * i + "- \n" for i in range(1, MAX_DEPTH + 5))
    assert read_yaml(block)[0] is None
    within = "a: " + "[" * (MAX_DEPTH - 1) + "]" * (MAX_DEPTH - 1) + "\n"
    assert read_yaml(within)[0] is not None


def test_reload_and_validate_of_a_deep_file_name_file_and_line(
    seeded: TestClient, knowledge_file: Path
) -> None:
    before = snapshot(seeded)
    good = knowledge_file.read_text()
    knowledge_file.write_text(_deep_yaml(100_000))
    try:
        response = seeded.post("/knowledge/reload")
        assert response.status_code == 422, response.text
        (problem,) = response.json()["problems"]
        assert problem.startswith(f"{knowledge_file}:3:") and "nested deeper" in problem
        with pytest.raises(KnowledgeError):
            load_knowledge(knowledge_file)
        run = subprocess.run(
            [sys.executable, "-m", "semwm", "knowledge", "validate", str(knowledge_file)],
            capture_output=True,
            text=True,
            timeout=60,
        )
        assert run.returncode != 0
        assert "Traceback" not in run.stderr + run.stdout
        assert f"{knowledge_file}:3:" in run.stderr + run.stdout
    finally:
        knowledge_file.write_text(good)
    assert snapshot(seeded) == before


@pytest.mark.parametrize("where", ["class", "parent", "detector"])
def test_an_empty_class_or_detector_name_is_a_located_problem(
    tmp_path: Path, knowledge_file: Path, where: str
) -> None:
    import yaml

    data = yaml.safe_load(knowledge_file.read_text())
    if where == "class":
        data["classes"][0]["name"] = ""
    elif where == "parent":
        data["classes"][-1]["is_a"] = [""]
    else:
        data["detectors"][0]["name"] = ""
    path = tmp_path / "empty.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    with pytest.raises(KnowledgeError) as error:
        load_knowledge(path)
    assert any(p.line is not None and "at least 1 character" in p.message
               for p in error.value.problems), [str(p) for p in error.value.problems]  # fmt: skip


def test_health_shows_the_knowledge_files_name_not_its_path_without_a_token(
    knowledge_file: Path, service: WorldService
) -> None:
    with TestClient(make_app(service, token="w" * 32)) as client:
        assert client.get("/health").json()["knowledge"] == knowledge_file.name
        assert str(knowledge_file.parent) not in client.get("/health").text
        with_token = client.get("/health", headers={"authorization": "Bearer " + "w" * 32})
        assert with_token.json()["knowledge"] == str(knowledge_file)


def test_health_json_has_no_path_for_open_reads(client: TestClient, knowledge_file: Path) -> None:
    assert json.loads(client.get("/health").text)["knowledge"] == knowledge_file.name
