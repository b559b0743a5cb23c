"""POST /detections' framework-free path (api.ingest_fast) answers exactly as the route.

Each case runs the same requests against two real servers on fresh worlds, one with
the fast path and one without, and compares status, body and the headers the route
sets, then what they left (``/health``, ``/sources``); a spy checks that accepted
batches really took the fast path.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Iterator
from concurrent.futures import ThreadPoolExecutor
from contextlib import ExitStack, contextmanager
from pathlib import Path
from typing import Any

import httpx
import pytest

import api.ingest_fast
from api.app import create_app
from api.deps import get_world
from api.service import WorldService
from api.settings import Settings
from api.testing import serving

ROOT = Path(__file__).resolve().parents[2]
OK = {"time": 3.0, "class": "Cup", "position": [1.0, 2.0], "source": "r1"}
HEADERS = ("content-type", "x-semwm-commit", "idempotent-replayed")

Request = tuple[str, dict[str, Any]]  # (method path, httpx keyword arguments)


@contextmanager
def _servers() -> Iterator[dict[bool, str]]:
    """A server with the fast path (``True``) and one without, each on its own world."""
    with ExitStack() as stack:
        urls = {}
        for fast in (True, False):
            service = WorldService.from_file(ROOT / "knowledge" / "sim1.yaml")
            settings = Settings(knowledge=service.knowledge_path, port=0, max_body=4096)
            app = create_app(settings, fast_ingest=fast)
            app.dependency_overrides[get_world] = _returning(service)
            urls[fast] = stack.enter_context(serving(app, settings))
        yield urls


def _returning(service: WorldService) -> Any:
    return lambda: service  # no parameters: FastAPI would read them as query fields


def _answers(url: str, requests: list[Request]) -> list[tuple[int, Any, dict[str, str]]]:
    answers = []
    with httpx.Client(base_url=url, timeout=20) as http:
        for path, options in requests:
            response = http.post(path, **options)
            try:
                body: Any = response.json()
            except ValueError:
                body = response.text
            headers = {k: response.headers[k] for k in HEADERS if k in response.headers}
            answers.append((response.status_code, body, headers))
        # what the requests left behind: the world, and each source's counts (a refusal
        # is counted once for its source)
        health = http.get("/health").json()
        answers.append((0, {k: health[k] for k in ("time", "commit", "objects")}, {}))
        answers.append((0, http.get("/sources").json(), {}))
    return answers


CASES: dict[str, list[Request]] = {
    "accepted batch and single": [
        ("/detections", {"json": {"detections": [OK, {**OK, "class": "CokeCan"}]}}),
        ("/detections", {"json": {**OK, "time": 3.5}}),
    ],
    "idempotent retry": [
        ("/detections", {"json": {"detections": [OK]}, "headers": {"Idempotency-Key": "k1"}}),
        ("/detections", {"json": {"detections": [OK]}, "headers": {"Idempotency-Key": "k1"}}),
        ("/detections", {"json": {"detections": [{**OK, "time": 4.0}], "batch_id": "b"}}),
        ("/detections", {"json": {"detections": [{**OK, "time": 4.0}], "batch_id": "b"}}),
    ],
    "invalid batch: field paths": [
        ("/detections", {"json": {"detections": [OK, {**OK, "position": [1.0]}]}}),
        ("/detections", {"json": {"detections": [{**OK, "class": "Unicorn"}]}}),
        ("/detections", {"content": b"{not json", "headers": {"content-type": "application/json"}}),
    ],
    "out of order": [
        ("/detections", {"json": {**OK, "time": 10.0}}),
        ("/detections", {"json": {**OK, "time": 1.0}}),
    ],
    "malformed idempotency key": [
        ("/detections", {"json": OK, "headers": {"Idempotency-Key": "k" * 201}}),
        ("/detections", {"json": OK, "headers": {"Idempotency-Key": ""}}),
    ],
    "too large a body": [
        ("/detections", {"json": {"detections": [{**OK, "time": 3.0 + i} for i in range(80)]}}),
    ],
}


@pytest.mark.parametrize("case", sorted(CASES))
def test_the_fast_path_answers_as_the_route(case: str, monkeypatch: pytest.MonkeyPatch) -> None:
    taken: list[int] = []
    real = api.ingest_fast.apply_json  # type: ignore[attr-defined]

    def spy(*args: Any, **options: Any) -> Any:
        answer = real(*args, **options)  # a WorldBusy (tried on the loop) is not counted
        taken.append(1)
        return answer

    monkeypatch.setattr(api.ingest_fast, "apply_json", spy)
    with _servers() as urls:
        fast = _answers(urls[True], CASES[case])
        plain = _answers(urls[False], CASES[case])
    assert fast == plain
    statuses = [status for status, _, _ in fast[:-2]]
    if case in ("accepted batch and single", "idempotent retry"):
        assert set(statuses) == {200} and len(taken) == len(statuses)
    else:
        assert any(status >= 400 for status in statuses)
    if case == "too large a body":
        assert statuses == [413] and not taken  # the guard stopped it while it was read


def test_batches_are_applied_in_a_worker_thread_with_the_request_context() -> None:
    """The fast path leaves the event loop for the world's work and carries the request's
    context there (its request id reaches the log lines the service writes)."""
    import asyncio
    import threading

    from api.logs import request_id_var

    def seen() -> tuple[str | None, str]:
        return request_id_var.get(), threading.current_thread().name

    async def post() -> tuple[str | None, str]:
        request_id_var.set("req-42")
        return await api.ingest_fast._in_worker(seen)

    request_id, thread = asyncio.run(post())
    assert request_id == "req-42"
    assert thread.startswith("semwm-ingest")
    assert thread != threading.current_thread().name


def _applies(monkeypatch: pytest.MonkeyPatch) -> list[tuple[str, bool]]:
    """Each body the fast path applied: the thread it ran in and whether it could wait
    for the world (a try on the event loop that found the world busy is not listed)."""
    seen: list[tuple[str, bool]] = []
    real = api.ingest_fast.apply_json  # type: ignore[attr-defined]

    def spy(*args: Any, wait: bool = True) -> Any:
        answer = real(*args, wait=wait)
        seen.append((threading.current_thread().name, wait))
        return answer

    monkeypatch.setattr(api.ingest_fast, "apply_json", spy)
    return seen


@contextmanager
def _serving(service: WorldService) -> Iterator[str]:
    settings = Settings(knowledge=service.knowledge_path, port=0)
    app = create_app(settings)
    app.dependency_overrides[get_world] = _returning(service)
    with serving(app, settings) as url:
        yield url


def _world() -> WorldService:
    return WorldService.from_file(ROOT / "knowledge" / "sim1.yaml")


def test_a_small_batch_on_a_free_world_is_applied_on_the_event_loop(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """No hand-over to a thread when nobody holds the world; a large body goes to one."""
    seen = _applies(monkeypatch)
    large = {"detections": [{**OK, "time": 4.0} for _ in range(100)]}
    assert len(str(large)) > api.ingest_fast.INLINE_BODY
    with _serving(_world()) as url, httpx.Client(base_url=url, timeout=20) as http:
        assert http.post("/detections", json={"detections": [OK]}).status_code == 200
        assert http.post("/detections", json=large).status_code == 200
        assert http.get("/health").json()["commit"] == 2
    assert seen[0] == ("semwm-uvicorn", False)  # serving()'s thread runs the event loop
    assert seen[1][0].startswith("semwm-ingest") and seen[1][1]


def test_while_the_world_is_busy_a_batch_waits_in_a_thread_and_the_loop_keeps_answering(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    seen = _applies(monkeypatch)
    world = _world()
    with _serving(world) as url, ThreadPoolExecutor(1) as pool:
        world._lock.acquire()  # a long change holds the world
        try:
            posted = pool.submit(httpx.post, f"{url}/detections", json=OK, timeout=20)
            time.sleep(0.3)
            assert not posted.done()  # it waits for the world, in an ingest thread ...
            health = httpx.get(f"{url}/health", timeout=5)  # ... and the loop is free
            assert health.status_code == 200 and health.json()["commit"] == 0
        finally:
            world._lock.release()
        assert posted.result().status_code == 200
    assert len(seen) == 1 and seen[0][0].startswith("semwm-ingest") and seen[0][1]


def test_with_a_hook_batches_are_applied_in_a_thread(monkeypatch: pytest.MonkeyPatch) -> None:
    """A hook (the journal) may write to disk: never on the event loop."""
    seen = _applies(monkeypatch)
    world = _world()
    records: list[Any] = []

    class Recorder:
        @contextmanager
        def applying(self, record: Any) -> Iterator[None]:
            records.append(record)
            yield

    world.hooks.append(Recorder())
    with _serving(world) as url:
        assert httpx.post(f"{url}/detections", json=OK, timeout=20).status_code == 200
    assert len(records) == 1
    assert len(seen) == 1 and seen[0][0].startswith("semwm-ingest")
