"""POST /detections' fast path: one validation of the raw body into the dicts the world
model takes, the same answer as the field-by-field path, and the event loop kept free."""

from __future__ import annotations

import json
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import httpx
import pytest
from pydantic import TypeAdapter

from api.app import create_app
from api.deps import get_world
from api.routes.detections import parse_body, parse_json
from api.schemas import DetectionBatch, DetectionBatchDict, DetectionDict, DetectionIn
from api.service import WorldService
from api.settings import Settings
from api.testing import serving
from semwm.persistence.records import Record

OK = {"time": 3.0, "class": "Cup", "position": [1.0, 2.0], "source": "r1"}


def _bare(schema: Any) -> Any:
    """A JSON schema without what only documents it (titles, descriptions, examples)."""
    if isinstance(schema, dict):
        return {
            k: _bare(v)
            for k, v in schema.items()
            if k not in ("title", "description", "examples", "default")
        }
    if isinstance(schema, list):
        return [_bare(v) for v in schema]
    return schema


def test_the_fast_schemas_equal_the_documented_models() -> None:
    """A field added to DetectionIn or DetectionBatch must be added to the dicts too."""
    assert _bare(TypeAdapter(DetectionDict).json_schema()) == _bare(DetectionIn.model_json_schema())
    batch = _bare(TypeAdapter(DetectionBatchDict).json_schema())
    model = _bare(DetectionBatch.model_json_schema())
    assert batch["$defs"]["DetectionDict"] == model["$defs"]["DetectionIn"]
    items = batch["properties"]["detections"]["items"]
    assert items == {"$ref": "#/$defs/DetectionDict"}
    items["$ref"] = "#/$defs/DetectionIn"
    assert batch["properties"] == model["properties"]
    assert batch["required"] == model["required"]
    assert batch["additionalProperties"] is model["additionalProperties"] is False


VALID: list[Any] = [
    OK,
    {"time": 1, "class": "Cup", "position": [1, 2]},
    {
        **OK,
        "covariance": [[0.01, 0.0], [0.0, 0.02]],
        "detector": "lidar",
        "label": "cup-7",
        "sensor_position": [0.0, 0.0],
    },
    {**OK, "source": None, "label": None},
    {"detections": [OK, {**OK, "class": "CokeCan", "position": [0.5, 1.5, 2.0]}]},
    {"detections": [OK], "batch_id": "b-1"},
    {"detections": [OK], "batch_id": None},
]


@pytest.mark.parametrize("body", VALID, ids=range(len(VALID)))
def test_the_fast_path_gives_what_the_field_by_field_path_gives(body: Any) -> None:
    fast = parse_json(json.dumps(body).encode(), max_batch=10)
    slow = parse_body(body, max_batch=10)
    assert fast is not None and not slow.errors
    assert fast.detections == [d.to_domain() for d in slow.valid]
    assert (fast.batch, fast.batch_id) == (slow.batch, slow.batch_id)


INVALID: list[bytes] = [
    b"",
    b"{not json",
    b"[" * 5000 + b"]" * 5000,
    json.dumps({**OK, "time": True}).encode(),
    json.dumps({**OK, "time": "3.0"}).encode(),
    json.dumps({**OK, "covariance": [[1.0, 0.0], [0.0]]}).encode(),
    json.dumps({**OK, "covariance": [[1e-20, 0.0], [0.0, 1.0]]}).encode(),
    json.dumps({**OK, "colour": "red"}).encode(),
    json.dumps({"detections": []}).encode(),
    json.dumps({"detections": [OK] * 11}).encode(),
    json.dumps({"detections": [OK], "robot": "r1"}).encode(),
    json.dumps({"detections": [OK], "batch_id": ""}).encode(),
    b'{"time": NaN, "class": "Cup", "position": [1, 2]}',
]


@pytest.mark.parametrize("raw", INVALID, ids=range(len(INVALID)))
def test_a_body_the_fast_path_refuses_goes_to_the_field_by_field_path(raw: bytes) -> None:
    assert parse_json(raw, max_batch=10) is None


class SlowHook:
    """A change hook (like the journal) that holds each change until ``release`` is set
    (or ``seconds`` have passed)."""

    def __init__(self, seconds: float) -> None:
        self.seconds = seconds
        self.entered = threading.Event()
        self.release = threading.Event()

    @contextmanager
    def applying(self, record: Record) -> Iterator[None]:
        self.entered.set()
        self.release.wait(self.seconds)
        yield


def test_the_event_loop_answers_while_a_batch_is_applied(service: WorldService) -> None:
    hook = SlowHook(30.0)
    service.hooks.append(hook)
    settings = Settings(knowledge=service.knowledge_path, port=0)
    app = create_app(settings)
    app.dependency_overrides[get_world] = lambda: service
    with serving(app, settings) as url:
        posted: list[httpx.Response] = []
        body = {"detections": [OK, {**OK, "class": "CokeCan"}], "batch_id": "slow"}
        poster = threading.Thread(
            target=lambda: posted.append(httpx.post(f"{url}/detections", json=body, timeout=10))
        )
        poster.start()
        assert hook.entered.wait(5)
        # the batch is held inside the world lock until /health has answered: an
        # event loop blocked by the batch would time out here (no wall-clock bound)
        try:
            health = httpx.get(f"{url}/health", timeout=10)
        finally:
            hook.release.set()
        poster.join()
    assert health.status_code == 200
    assert posted[0].status_code == 200, posted[0].text
    assert posted[0].json() == {"applied": 2, "time": 3.0, "ignored": 0, "ignored_detections": []}
    assert posted[0].headers["x-semwm-commit"] == "1"


def test_a_failed_journal_write_applies_nothing(service: WorldService) -> None:
    class Refusing:
        @contextmanager
        def applying(self, record: Record) -> Iterator[None]:
            raise OSError("disk full")
            yield

    service.hooks.append(Refusing())
    settings = Settings(knowledge=service.knowledge_path, port=0)
    app = create_app(settings)
    app.dependency_overrides[get_world] = lambda: service
    with serving(app, settings) as url:
        refused = httpx.post(f"{url}/detections", json={"detections": [OK]})
        health = httpx.get(f"{url}/health").json()
    assert refused.status_code == 500
    assert health["time"] is None and health["commit"] == 0


def test_batch_id_is_documented_and_idempotent(knowledge_file: Path) -> None:
    settings = Settings(knowledge=knowledge_file, port=0)
    app = create_app(settings)
    with serving(app, settings) as url, httpx.Client(base_url=url) as http:
        schema = http.get("/openapi.json").json()
        batch = schema["components"]["schemas"]["DetectionBatch"]
        assert "batch_id" in batch["properties"]
        body = schema["paths"]["/detections"]["post"]["requestBody"]
        assert body["required"] is True
        assert set(body["content"]["application/json"]["examples"]) == {"single", "batch"}
        first = http.post("/detections", json={"detections": [OK], "batch_id": "k"})
        again = http.post("/detections", json={"detections": [OK], "batch_id": "k"})
        assert first.json() == again.json()
        assert again.headers["idempotent-replayed"] == "true"
        assert http.get("/health").json()["commit"] == 1
        mismatch = http.post(
            "/detections", json={"detections": [OK], "batch_id": "k"},
            headers={"idempotency-key": "other"},
        )  # fmt: skip
        assert mismatch.status_code == 422
        assert mismatch.json()["detail"][0]["loc"] == ["body", "batch_id"]
