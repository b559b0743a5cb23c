"""Ingesters, an editor, a reloader, a reader and a resetter at once against the real
server: no 5xx, and the final world equals replaying the accepted changes in their
commit order (the ``X-Semwm-Commit`` header) into a fresh service."""

from __future__ import annotations

import itertools
import math
import shutil
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import httpx

from api.schemas import WorldOut
from api.service import COMMIT_HEADER, WorldService
from api.settings import Settings
from api.testing import running_server
from semwm.knowledge import ClassSpec
from semwm.knowledge.loader import load_document

SIM1 = Path(__file__).parents[2] / "knowledge" / "sim1.yaml"
SECONDS = 2.0
MAX_REQUESTS = 400  # per client: bounded in count and time


def test_concurrent_changes_replay_to_the_same_world(tmp_path: Path) -> None:
    path = tmp_path / "sim1.yaml"
    shutil.copy(SIM1, path)
    ticks = itertools.count(1)
    tick_lock = threading.Lock()
    accepted: list[tuple[int, str, Any]] = []
    statuses: list[tuple[str, int, str]] = []
    record = threading.Lock()
    stop = math.inf  # set once the server is up: its start-up is not the clients' time

    def now() -> float:
        with tick_lock:
            return round(next(ticks) * 0.01, 6)

    def client_loop(url: str, name: str, step: Callable[[httpx.Client, int], Any]) -> None:
        with httpx.Client(base_url=url, timeout=30) as client:
            for i in range(MAX_REQUESTS):
                if time.monotonic() > stop:
                    return
                result = step(client, i)
                if result is None:
                    continue
                response, change = result
                with record:
                    statuses.append((name, response.status_code, response.text[:200]))
                    if response.status_code == 200 and COMMIT_HEADER in response.headers:
                        accepted.append((int(response.headers[COMMIT_HEADER]), name, change))

    def ingester(robot: int) -> Callable[[httpx.Client, int], Any]:
        def step(client: httpx.Client, i: int) -> Any:
            t = now()
            batch = [
                {"time": t, "class": "Cup", "position": [robot + 0.01 * (i % 3), 1.0],
                 "source": f"r{robot}"},
                {"time": t, "class": "CokeCan", "position": [robot, 2.0], "source": f"r{robot}"},
            ]  # fmt: skip
            return client.post("/detections", json={"detections": batch}), batch

        return step

    cup = next(c for c in load_document(path).classes if c.name == "Cup")

    def editor(client: httpx.Client, i: int) -> Any:
        spec = {**cup.model_dump(mode="json"), "detection_frequency": 2.0 + (i % 3)}
        time.sleep(0.02)
        return client.put("/knowledge/classes/Cup", json=spec), spec

    def reloader(client: httpx.Client, i: int) -> Any:
        time.sleep(0.05)
        return client.post("/knowledge/reload"), None

    def resetter(client: httpx.Client, i: int) -> Any:
        time.sleep(0.3)
        return client.post("/reset"), None

    def reader(client: httpx.Client, i: int) -> Any:
        return client.get("/world"), None

    settings = Settings(knowledge=path, port=0, reorder_window=2.0)
    with running_server(settings) as url:
        stop = time.monotonic() + SECONDS
        steps = {f"ingest{r}": ingester(r) for r in range(3)}
        steps |= {"edit": editor, "reload": reloader, "reset": resetter, "read": reader}
        threads = [threading.Thread(target=client_loop, args=(url, n, s)) for n, s in steps.items()]
        for thread in threads:
            thread.start()
        for thread in threads:
            thread.join()
        final = httpx.get(f"{url}/world").json()
        commit = httpx.get(f"{url}/health").json()["commit"]

    assert not [s for s in statuses if s[1] >= 500], [s for s in statuses if s[1] >= 500][:5]
    kinds = {name.rstrip("0123456789") for _, name, _ in accepted}
    assert kinds == {"ingest", "edit", "reload", "reset"}
    order = sorted(accepted)
    assert [c for c, _, _ in order] == list(range(1, commit + 1))  # every commit answered once

    replay = WorldService.from_file(path, reorder_window=2.0)
    for _, name, change in order:
        if name.startswith("ingest"):
            replay.ingest(change, batch=True)
        elif name == "edit":
            replay.put_class("Cup", ClassSpec.model_validate(change))
        elif name == "reload":
            replay.reload()
        else:
            replay.reset()
    expected = WorldOut.model_validate(replay.world().to_dict()).model_dump(by_alias=True)
    assert final == expected
