"""Operations: /metrics (parsed with prometheus_client), request ids, JSON logs, offline docs."""

from __future__ import annotations

import json
import logging
import logging.config
import re
from typing import Any

import pytest
from api_helpers import make_app, scene
from fastapi.testclient import TestClient
from prometheus_client.parser import text_string_to_metric_families

from api.logs import JsonFormatter, RequestIdFilter, logging_config, usable_request_id
from api.metrics import detections_in, refusal_reason
from api.service import WorldChange, WorldService


def scrape(client: TestClient) -> dict[tuple[str, tuple[tuple[str, str], ...]], float]:
    """Every sample of ``GET /metrics``: (name, sorted labels) -> value."""
    response = client.get("/metrics")
    assert response.status_code == 200
    assert response.headers["content-type"].startswith("text/plain")
    samples = {}
    for family in text_string_to_metric_families(response.text):
        for sample in family.samples:
            samples[(sample.name, tuple(sorted(sample.labels.items())))] = sample.value
    return samples


def value(samples: dict[Any, float], name: str, **labels: str) -> float:
    return samples.get((name, tuple(sorted(labels.items()))), 0.0)


def test_metrics_counters_move_with_posted_detections(client: TestClient) -> None:
    before = scrape(client)
    assert value(before, "semwm_detections_accepted_total") == 0
    assert value(before, "semwm_knowledge_version") == 1

    for step in range(3):
        assert client.post("/detections", json={"detections": scene(step * 0.5)}).status_code == 200
    # refused: 2 detections with a problem (422), then 1 too old (409)
    bad = [{"time": 1.5, "class": "Mug", "position": [0, 0]}, scene(1.5)[0]]
    assert client.post("/detections", json={"detections": bad}).status_code == 422
    assert client.post("/detections", json=scene(0.0)[0]).status_code == 409
    headers = {"content-type": "application/json"}
    assert client.post("/detections", content=b"{not json", headers=headers).status_code == 422
    assert (
        client.post(
            "/detections", content=b"{}", headers={"content-type": "text/plain"}
        ).status_code
        == 415
    )

    after = scrape(client)
    assert value(after, "semwm_detections_accepted_total") == 9
    assert value(after, "semwm_detections_refused_total", reason="invalid") == 2 + 1
    assert value(after, "semwm_detections_refused_total", reason="out_of_order") == 1
    assert value(after, "semwm_detections_refused_total", reason="unsupported_media_type") == 1
    assert value(after, "semwm_ingest_latency_seconds_count") == 3 + 4
    assert value(after, "semwm_ingest_apply_seconds_count") == 3
    assert value(after, "semwm_ingest_latency_seconds_bucket", le="+Inf") == 7
    world = client.get("/world").json()
    health = client.get("/health").json()
    assert value(after, "semwm_objects") == len(world["objects"]) == 3
    assert value(after, "semwm_stored_hypotheses") == health["hypotheses"]
    assert value(after, "semwm_clusters") >= 1
    assert value(after, "semwm_stored_hypotheses") >= value(after, "semwm_clusters")
    assert value(after, "semwm_joint_hypotheses_log10") == pytest.approx(
        health["hypotheses_log10_joint"]
    )
    assert value(after, "semwm_world_time_seconds") == 1.0


def test_metrics_count_knowledge_versions(client: TestClient) -> None:
    assert client.post("/knowledge/reload").status_code == 200
    assert value(scrape(client), "semwm_knowledge_version") == 2
    client.post("/reset")
    assert value(scrape(client), "semwm_knowledge_version") == 2


@pytest.mark.parametrize(
    ("body", "count"),
    [
        (b'{"detections": [{}, {}, {}]}', 3),
        (b'{"time": 1}', 1),
        (b"not json", 1),
        (b'{"detections": "x"}', 1),
        (b'{"detections": []}', 1),
    ],
)
def test_a_refused_body_counts_its_detections(body: bytes, count: int) -> None:
    assert detections_in(body) == count


def test_refusal_reasons() -> None:
    assert refusal_reason(422) == "invalid"
    assert refusal_reason(409) == "out_of_order"
    assert refusal_reason(418) == "http_418"


def test_service_listeners_see_applied_changes_in_order(service: WorldService) -> None:
    seen: list[WorldChange] = []
    remove = service.add_listener(seen.append)
    service.ingest(scene(0.0), batch=True)
    with pytest.raises(Exception, match="reorder"):
        service.ingest(scene(-5.0), batch=True)  # refused: nothing told
    service.reset()
    remove()
    service.ingest(scene(1.0), batch=True)  # removed: not told
    assert [c.kind for c in seen] == ["detections", "reset"]
    assert seen[0].applied == 3 and seen[0].time == 0.0 and len(seen[0].detections) == 3
    assert seen[0].seconds > 0


def test_listeners_keep_what_was_applied_though_the_caller_changes_its_dicts(
    service: WorldService,
) -> None:
    """A caller's dicts are copied (it may reuse them); a request's own (``owned``, as
    the routes pass them) are kept as they are, with no copy per detection."""
    seen: list[WorldChange] = []
    service.add_listener(seen.append)
    mine = scene(0.0)
    service.ingest(mine, batch=True)
    for d in mine:
        d["position"] = [99.0, 99.0]
    assert all(d["position"] != [99.0, 99.0] for d in seen[0].detections)
    owned = scene(0.5)
    service.ingest(owned, batch=True, owned=True)
    assert list(seen[1].detections) == owned and seen[1].detections[0] is owned[0]


def test_a_failing_listener_does_not_undo_the_change(service: WorldService) -> None:
    def broken(change: WorldChange) -> None:
        raise RuntimeError("boom")

    service.add_listener(broken)
    assert service.ingest(scene(0.0), batch=True).value.applied == 3
    assert service.stats()["objects"] == 3


# -- request ids and logs ----------------------------------------------------------------------


def test_request_id_is_echoed_or_made(client: TestClient, caplog: pytest.LogCaptureFixture) -> None:
    with caplog.at_level(logging.INFO, logger="semwm.access"):
        given = client.get("/health", headers={"X-Request-ID": "robot1-42"})
        made = client.get("/world")
        refused = client.get("/world/objects/999", headers={"X-Request-ID": "bad id with spaces"})
    assert given.headers["x-request-id"] == "robot1-42"
    assert re.fullmatch(r"[0-9a-f]{32}", made.headers["x-request-id"])
    assert re.fullmatch(r"[0-9a-f]{32}", refused.headers["x-request-id"])
    lines = [r for r in caplog.records if r.name == "semwm.access"]
    assert [(r.method, r.path, r.status) for r in lines] == [
        ("GET", "/health", 200),
        ("GET", "/world", 200),
        ("GET", "/world/objects/999", 404),
    ]
    assert lines[0].request_id == "robot1-42"
    assert "id=robot1-42" in lines[0].getMessage()


def test_usable_request_ids() -> None:
    assert usable_request_id("a" * 128) == "a" * 128
    assert usable_request_id("a" * 129) != "a" * 129
    assert usable_request_id("") != ""
    assert usable_request_id("tab\there") != "tab\there"


def test_json_log_lines(capsys: pytest.CaptureFixture[str]) -> None:
    config = logging_config("json", "info")
    logging.config.dictConfig(config)
    try:
        logger = logging.getLogger("semwm.access")
        logger.info("hello %s", "world", extra={"request_id": "r1", "status": 200, "path": "/x"})
        try:
            raise ValueError("bad")
        except ValueError:
            logging.getLogger("api").exception("failed")
    finally:
        logging.config.dictConfig({"version": 1, "disable_existing_loggers": False})
        for name in ("uvicorn", "uvicorn.error", "api", "semwm", "semwm.access"):
            logging.getLogger(name).handlers.clear()
            logging.getLogger(name).propagate = True
    lines = [json.loads(line) for line in capsys.readouterr().err.splitlines()]
    assert lines[0]["message"] == "hello world"
    assert lines[0]["request_id"] == "r1" and lines[0]["status"] == 200
    assert lines[0]["level"] == "info" and lines[0]["logger"] == "semwm.access"
    assert "request_id" not in lines[1]
    assert "ValueError: bad" in lines[1]["exception"]


def test_json_formatter_without_handler_config() -> None:
    record = logging.LogRecord("api", logging.WARNING, __file__, 1, "x=%d", (3,), None)
    RequestIdFilter().filter(record)
    entry = json.loads(JsonFormatter().format(record))
    assert entry["message"] == "x=3" and entry["level"] == "warning"
    assert entry["time"].endswith("+00:00")


@pytest.mark.parametrize(("fmt", "level"), [("xml", "info"), ("json", "loud")])
def test_bad_log_settings_are_named(fmt: str, level: str) -> None:
    with pytest.raises(ValueError, match="must be one of"):
        logging_config(fmt, level)  # type: ignore[arg-type]


# -- offline docs and the page -----------------------------------------------------------------


def test_docs_and_redoc_load_only_packaged_assets(client: TestClient) -> None:
    for page in ("/docs", "/redoc"):
        html = client.get(page).text
        assert "cdn" not in html.lower() and "https://" not in html
        assets = re.findall(r'(?:src|href)="([^"]+)"', html)
        assert assets, page
        for asset in assets:
            response = client.get(asset)
            assert response.status_code == 200, asset
            assert len(response.content) > 1000, asset
    assert client.get("/docs/oauth2-redirect").status_code == 200
    assert client.get("/openapi.json").json()["paths"]["/world/stream"]


def test_the_page_and_its_assets_are_served(client: TestClient) -> None:
    html = client.get("/").text
    assert "<svg" in html and "https://" not in html
    for asset in re.findall(r'(?:src|href)="(static/[^"]+)"', html):
        response = client.get(f"/{asset}")
        assert response.status_code == 200, asset
        assert "https://" not in response.text


def test_docs_assets_stay_open_with_a_read_token(service: WorldService) -> None:
    with TestClient(make_app(service, read_token="reader-secret")) as guarded:
        assert guarded.get("/world").status_code == 401
        html = guarded.get("/docs").text
        for asset in re.findall(r'(?:src|href)="([^"]+)"', html):
            assert guarded.get(asset).status_code == 200, asset
        assert guarded.get("/static/live.js").status_code == 200
        assert guarded.get("/metrics").status_code == 401


def test_health_and_metrics_say_which_engine_runs(knowledge_file: Any, engine: str) -> None:
    """``/health`` (to readers) and ``/metrics`` (``semwm_engine_info``) name the engine,
    and the service serves the same world with either."""
    import api_knowledge as knowledge_data

    from semwm.world import WorldModel

    model = WorldModel(
        knowledge_data.knowledge(str(knowledge_file)), reorder_window=0.5, engine=engine
    )
    with TestClient(make_app(WorldService(model, knowledge_file))) as client:
        for step in range(6):
            assert (
                client.post("/detections", json={"detections": scene(step * 0.5)}).status_code
                == 200
            )
        assert client.get("/health").json()["engine"] == engine
        samples = scrape(client)
        assert value(samples, "semwm_engine_info", engine=engine) == 1.0
        other = "python" if engine == "rust" else "rust"
        assert value(samples, "semwm_engine_info", engine=other) == 0.0
        assert len(client.get("/world").json()["objects"]) == 3


def test_settings_take_the_engine_from_the_environment(monkeypatch: pytest.MonkeyPatch) -> None:
    from api.settings import Settings

    monkeypatch.setenv("SEMWM_ENGINE", " Rust")
    assert Settings().engine == "rust"
    monkeypatch.setenv("SEMWM_ENGINE", "numba")
    with pytest.raises(ValueError, match="engine"):
        Settings()
