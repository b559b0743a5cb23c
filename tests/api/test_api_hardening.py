"""Regression tests of issue 15 (stuck, corrupted, open to a web page) and issue 13's
tokens and limits, each against the real server (uvicorn on a free loopback port)."""

from __future__ import annotations

import shutil
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import httpx
import pytest

from api.app import create_app
from api.deps import get_world
from api.service import COMMIT_HEADER, WorldService
from api.settings import Settings
from api.testing import running_server, serving
from semwm.knowledge.loader import load_knowledge
from semwm.world import WorldModel

SIM1 = Path(__file__).parents[2] / "knowledge" / "sim1.yaml"
TOKEN = "write-token-123"
READ = "read-token-456"
JSON = {"content-type": "application/json"}


@pytest.fixture
def sim1(tmp_path: Path) -> Path:
    path = tmp_path / "sim1.yaml"
    shutil.copy(SIM1, path)
    return path


@contextmanager
def server(knowledge: Path, **options: Any) -> Iterator[httpx.Client]:
    settings = Settings(knowledge=knowledge, port=0, **options)
    with running_server(settings) as url, httpx.Client(base_url=url, timeout=30) as client:
        yield client


@contextmanager
def served(service: WorldService, **options: Any) -> Iterator[httpx.Client]:
    """The real server over ``service`` (so a test can reach into it)."""
    settings = Settings(knowledge=service.knowledge_path, port=0, **options)
    app = create_app(settings)
    app.dependency_overrides[get_world] = lambda: service
    with serving(app, settings) as url, httpx.Client(base_url=url, timeout=30) as client:
        yield client


def cup(t: float, x: float = 1.0, y: float = 1.0, cls: str = "Cup") -> dict[str, Any]:
    return {"time": t, "class": cls, "position": [x, y], "source": "cam"}


def state(client: httpx.Client) -> dict[str, Any]:
    """What a refused request must leave as it was."""
    return {
        "world": client.get("/world").json(),
        "hypotheses": client.get("/hypotheses", params={"limit": 1000}).json(),
        "knowledge": client.get("/knowledge").json(),
        "time": client.get("/health").json()["time"],
    }


# -- defect 1: a change is all-or-nothing and keeps the model consistent with its knowledge ----


def mug_sequence(client: httpx.Client) -> None:
    """Issue 15's sequence up to the reload: a Mug class added over HTTP, a Mug seen."""
    assert client.post("/reset").status_code == 200
    put = client.put("/knowledge/classes/Mug", json={"name": "Mug", "is_a": ["Cup"]})
    assert put.status_code == 200, put.text
    for t in (4.4, 4.9, 4.9, 5.4):
        assert client.post("/detections", json=cup(t, 2.0, 1.0)).status_code == 200
    mug = client.post("/detections", json=cup(5.4, 2.0, 1.0, "Mug"))
    assert mug.status_code == 200


def test_a_reload_that_drops_a_class_objects_hold_is_409_naming_them(sim1: Path) -> None:
    with server(sim1) as client:
        mug_sequence(client)
        before = state(client)
        reload = client.post("/knowledge/reload")
        assert reload.status_code == 409, reload.text
        assert "Mug" in reload.json()["detail"] and "reset" in reload.json()["detail"]
        assert state(client) == before
        for t in (6.6, 6.7, 6.8, 9.0):  # the sequence that used to give stuck 500s
            assert client.post("/detections", json=cup(t, 2.0, 1.0)).status_code == 200
        assert client.get("/world").status_code == 200
        assert client.post("/reset").status_code == 200
        assert client.post("/knowledge/reload").status_code == 200
        assert "Mug" not in client.get("/knowledge").json()["classes"]


def test_replace_knowledge_forgets_published_objects_of_a_removed_class() -> None:
    """The Python API's defined behaviour: objects of a removed class are dropped, and
    ingestion goes on (it raised KeyError in the id hand-over)."""
    base = load_knowledge(SIM1)
    document = base.document
    mug = {"name": "Mug", "is_a": ("Cup",)}
    from semwm.knowledge import KnowledgeDocument, resolve

    with_mug = resolve(
        KnowledgeDocument.model_validate({**dict(document), "classes": (*document.classes, mug)})
    )
    wm = WorldModel(with_mug, reorder_window=0.5)
    for t in (4.4, 4.9, 4.9, 5.4):
        wm.ingest(cup(t, 2.0, 1.0))
    wm.ingest(cup(5.4, 2.0, 1.0, "Mug"))
    wm.replace_knowledge(base)
    for t in (6.6, 6.7, 6.8, 9.0):
        wm.ingest(cup(t, 2.0, 1.0))
        assert all(o.cls in base.classes for o in wm.world().objects)


def test_a_failed_change_applies_nothing_and_ready_reports_it(
    sim1: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    service = WorldService.from_file(sim1, reorder_window=0.5)
    with served(service) as client:
        assert client.post("/detections", json=cup(1.0)).status_code == 200
        before = state(client)

        def broken(self: WorldModel, *args: object) -> None:
            raise KeyError("injected")

        with monkeypatch.context() as patch:  # publishing fails, on either engine's path
            patch.setattr(WorldModel, "_publish", broken)
            patch.setattr(WorldModel, "_published_core", broken)
            failed = client.post("/detections", json=cup(2.0, 3.0, 3.0))
            assert failed.status_code == 500
            assert client.get("/ready").status_code == 503
            assert "KeyError" in client.get("/ready").json()["reasons"][0]
        assert state(client) == before  # the 500 applied nothing: time is still 1.0
        retry = client.post("/detections", json=cup(2.0, 3.0, 3.0))
        assert retry.status_code == 200 and retry.json()["time"] == 2.0
        assert client.get("/ready").json() == {"status": "ready", "reasons": []}


# -- defect 3 and issue 13 item 2: browsers, hosts and tokens ----------------------------------


def test_a_web_page_cannot_write(sim1: Path) -> None:
    with server(sim1) as client:
        assert client.post("/detections", json=cup(1.0)).status_code == 200
        before = state(client)
        page = {"origin": "http://evil.example", "content-type": "text/plain"}
        for path in ("/reset", "/knowledge/reload"):
            refused = client.post(path, headers=page)
            assert refused.status_code == 403, refused.text
            assert "--cors-origin" in refused.json()["detail"]
        plain = client.post("/reset", headers={"content-type": "text/plain"}, content="x")
        assert plain.status_code == 415
        assert "application/json" in plain.json()["detail"]
        form = client.post("/detections", data={"time": "1"})  # form-encoded
        assert form.status_code == 415
        rebinding = client.get("/world", headers={"host": "evil.example"})
        assert rebinding.status_code == 400
        assert state(client) == before
        own = client.post("/reset", headers={"origin": str(client.base_url).rstrip("/")})
        assert own.status_code == 200  # the service's own pages (/docs) may write


def test_an_allowed_origin_gets_cors_and_may_write(sim1: Path) -> None:
    origin = "http://robot-ui.local:3000"
    with server(sim1, cors_origins=(origin,)) as client:
        preflight = client.options(
            "/detections",
            headers={"origin": origin, "access-control-request-method": "POST",
                     "access-control-request-headers": "content-type"},
        )  # fmt: skip
        assert preflight.status_code == 200
        assert preflight.headers["access-control-allow-origin"] == origin
        posted = client.post("/detections", json=cup(1.0), headers={"origin": origin})
        assert posted.status_code == 200
        assert posted.headers["access-control-allow-origin"] == origin
        other = client.post("/reset", headers={"origin": "http://other.example"})
        assert other.status_code == 403


def test_with_a_token_every_write_needs_it(sim1: Path) -> None:
    auth = {"authorization": f"Bearer {TOKEN}"}
    with server(sim1, token=TOKEN) as client:
        assert client.post("/detections", json=cup(1.0), headers=auth).status_code == 200
        before = state(client)
        writes = [
            ("POST", "/detections", cup(2.0)),
            ("PUT", "/knowledge/classes/Mug", {"name": "Mug", "is_a": ["Cup"]}),
            ("POST", "/knowledge/reload", None),
            ("POST", "/reset", None),
        ]
        for method, path, body in writes:
            for headers in ({}, {"authorization": "Bearer wrong-token"}):
                refused = client.request(method, path, json=body, headers=headers)
                assert refused.status_code == 401, (method, path, refused.text)
                assert refused.headers["www-authenticate"].startswith("Bearer")
        assert state(client) == before
        for method, path, body in writes:
            assert client.request(method, path, json=body, headers=auth).status_code == 200


def test_a_read_token_guards_reads_and_health_details(sim1: Path) -> None:
    with server(sim1, token=TOKEN, read_token=READ) as client:
        assert client.get("/world").status_code == 401
        assert client.get("/health").json() == {
            "status": "ok", "engine": None, "knowledge": None, "time": None,
            "hypotheses": None, "objects": None, "commit": None, "hypotheses_log10_joint": None,
            "store_damage": None, "lost_records": None,
        }  # fmt: skip
        assert client.get("/ready").status_code == 200
        for token in (READ, TOKEN):
            headers = {"authorization": f"Bearer {token}"}
            assert client.get("/world", headers=headers).status_code == 200
            assert client.get("/health", headers=headers).json()["knowledge"] == str(sim1)
            assert client.get("/health", headers=headers).json()["engine"] in ("python", "rust")
        read_only = {"authorization": f"Bearer {READ}"}
        assert client.post("/reset", headers=read_only).status_code == 401


# -- defect 4: liveness apart from the lock, readiness that sees a stuck model -----------------


def test_health_never_waits_for_the_world_and_ready_sees_it_stuck(sim1: Path) -> None:
    service = WorldService.from_file(sim1, stuck_after=0.2)
    with served(service) as client:
        held = threading.Event()
        release = threading.Event()

        def hold() -> None:
            with service._locked():  # a long ingest
                held.set()
                release.wait(20)

        holder = threading.Thread(target=hold)
        holder.start()
        try:
            assert held.wait(5)
            time.sleep(0.3)
            health = client.get("/health", timeout=5)
            assert health.status_code == 200 and health.json()["status"] == "ok"
            ready = client.get("/ready", timeout=5)
            assert ready.status_code == 503
            assert "held the world" in ready.json()["reasons"][0]
        finally:
            release.set()
            holder.join()
        assert client.get("/ready").status_code == 200


# -- defect 8: write-back atomic with the change --------------------------------------------------


def test_a_failed_write_back_changes_nothing(tmp_path: Path) -> None:
    folder = tmp_path / "k"
    folder.mkdir()
    path = folder / "sim1.yaml"
    shutil.copy(SIM1, path)
    with server(path, write_back=True) as client:
        written = client.put("/knowledge/classes/Cup2", json={"name": "Cup2", "is_a": ["Cup"]})
        assert written.status_code == 200 and written.json()["written"] is True
        assert "Cup2" in path.read_text(encoding="utf-8")
        shutil.rmtree(folder)
        before = state(client)
        refused = client.put("/knowledge/classes/Cup3", json={"name": "Cup3", "is_a": ["Cup"]})
        assert refused.status_code == 409, refused.text
        assert "cannot write the knowledge file" in refused.json()["detail"]
        assert state(client) == before
        assert client.get("/knowledge/classes/Cup3").status_code == 404


# -- defect 9 and issue 13 item 3: strict, bounded input ---------------------------------------


@pytest.mark.parametrize(
    "change",
    [
        {"time": "12.3"},
        {"time": True},
        {"position": ["1e0", "2"]},
        {"sensor_position": [False, True]},
        {"position": [1e308, 0.0]},
        {"covariance": [[1e-300, 0.0], [0.0, 1e-300]]},
        {"covariance": [[1e9, 0.0], [0.0, 1.0]]},
        {"source": "s" * 10_000},
        {"label": "l" * 257},
        {"class": "C" * 257},
        {"detector": "d" * 257},
    ],
    ids=lambda c: f"{next(iter(c))}-{str(next(iter(c.values())))[:12]}",
)
def test_loose_or_absurd_values_are_422_naming_the_field(
    sim1: Path, change: dict[str, Any]
) -> None:
    with server(sim1) as client:
        refused = client.post("/detections", json={**cup(1.0), **change})
        assert refused.status_code == 422, refused.text
        field = next(iter(change))
        assert any(item["loc"][:2] == ["body", field] for item in refused.json()["detail"])
        assert client.get("/health").json()["time"] is None


def test_a_20_mb_body_is_413_and_a_chunked_one_is_cut_off(sim1: Path) -> None:
    with server(sim1) as client:
        big = b'{"time": 1, "class": "Cup", "position": [1, 1], "source": "' + b"s" * 20_000_000
        refused = client.post("/detections", content=big + b'"}', headers=JSON)
        assert refused.status_code == 413
        assert f"limited to {4 * 1024 * 1024} bytes" in refused.json()["detail"]

        def chunks() -> Iterator[bytes]:
            for _ in range(100):
                yield b" " * 100_000

        cut = client.post("/detections", content=chunks(), headers=JSON)
        assert cut.status_code == 413
        assert client.get("/health").json()["time"] is None


def test_sources_held_in_memory_are_bounded(sim1: Path) -> None:
    with server(sim1, max_sources=2) as client:
        for i, source in enumerate(("a", "b", "a")):
            body = {**cup(1.0 + i), "source": source}
            assert client.post("/detections", json=body).status_code == 200
        refused = client.post("/detections", json={**cup(5.0), "source": "c"})
        assert refused.status_code == 422
        assert refused.json()["detail"][0]["loc"] == ["body", "source"]
        assert client.post("/reset").status_code == 200
        assert client.post("/detections", json={**cup(5.0), "source": "c"}).status_code == 200


# -- defect 10: methods, OpenAPI, idempotency ----------------------------------------------------


def test_options_and_405_list_every_method_of_the_path(sim1: Path) -> None:
    with server(sim1) as client:
        options = client.options("/knowledge/classes/Cup")
        assert options.status_code == 204
        assert set(options.headers["allow"].split(", ")) == {"GET", "HEAD", "OPTIONS", "PUT"}
        wrong = client.delete("/knowledge/classes/Cup")
        assert wrong.status_code == 405
        assert "PUT" in wrong.headers["allow"] and "GET" in wrong.headers["allow"]


def test_an_empty_class_query_is_described_by_the_schema(sim1: Path) -> None:
    with server(sim1) as client:
        schema = client.get("/openapi.json").json()
        parameters = schema["paths"]["/world"]["get"]["parameters"]
        cls = next(p for p in parameters if p["name"] == "class")
        assert any(option.get("minLength") == 1 for option in cls["schema"]["anyOf"])
        assert client.get("/world", params={"class": ""}).status_code == 422


def test_a_repeated_batch_is_applied_once(sim1: Path) -> None:
    with server(sim1) as client:
        key = {"idempotency-key": "robot1-000042"}
        first = client.post("/detections", json=cup(1.0), headers=key)
        again = client.post("/detections", json=cup(1.0), headers=key)
        assert first.status_code == again.status_code == 200
        assert again.json() == first.json()
        assert again.headers[COMMIT_HEADER] == first.headers[COMMIT_HEADER]
        assert again.headers["idempotent-replayed"] == "true"
        batch = {"batch_id": "b-7", "detections": [cup(2.0, 3.0, 3.0)]}
        assert client.post("/detections", json=batch).status_code == 200
        assert client.post("/detections", json=batch).headers["idempotent-replayed"] == "true"
        assert client.get("/health").json()["commit"] == 2
        assert client.get("/health").json()["time"] == 2.0
