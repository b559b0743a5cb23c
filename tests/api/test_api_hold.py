"""``semwm serve --hold`` (``SEMWM_HOLD``) against the real server: held detections are
in every answer, refusals keep their status, and a restart from the data directory
gives the same world with the same detections still held."""

from __future__ import annotations

from pathlib import Path

import httpx

from api.settings import Settings
from api.testing import running_server

SIM1 = Path(__file__).parents[2] / "knowledge" / "sim1.yaml"


def _cup(t: float, source: str = "r1") -> dict[str, object]:
    return {"time": t, "class": "Cup", "position": [1.0 + t, 2.0], "source": source}


def test_held_detections_are_answered_refused_alike_and_survive_a_restart(tmp_path: Path) -> None:
    settings = Settings(knowledge=SIM1, port=0, hold=0.5, reorder_window=0.1, data_dir=tmp_path)
    with running_server(settings) as url, httpx.Client(base_url=url, timeout=30) as client:
        for t in (0.0, 0.1, 0.2, 0.3):
            assert client.post("/detections", json={"detections": [_cup(t)]}).status_code == 200
        world = client.get("/world").json()
        assert world["time"] == 0.3 and len(world["objects"]) == 1  # all held, all answered
        assert client.get("/health").json()["time"] == 0.3
        metrics = client.get("/metrics").text
        assert "semwm_held_scans 4.0" in metrics and "semwm_replayed_scans 0.0" in metrics
        wrong = {**_cup(0.25), "class": "Nope"}
        bad = client.post("/detections", json={"detections": [_cup(0.25), wrong]})
        assert bad.status_code == 422  # validated at ingest, though it would be held
        for t in (0.4, 0.5, 0.6, 0.7, 0.8):  # 0.0-0.3 are now processed
            client.post("/detections", json={"detections": [_cup(t)]})
        late = client.post("/detections", json={"detections": [_cup(0.05, "r2")]})
        assert late.status_code == 409  # before the processed time minus the window
        before = client.get("/world").json()
    with running_server(settings) as url:
        assert httpx.get(f"{url}/world", timeout=30).json() == before
