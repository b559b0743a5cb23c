"""``semwm serve --order-tolerance`` against the real server: a team's scans of one
instant that arrive in any order are processed in arrival order instead of replayed,
and the world is the one strict time order gives, to the millimetre."""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import httpx

from api.settings import Settings
from api.testing import running_server

SIM1 = Path(__file__).parents[2] / "knowledge" / "sim1.yaml"
CUPS = ((1.0, 1.0), (2.0, 1.5))


def _scan(t: float, robot: int) -> list[dict[str, Any]]:
    return [
        {"time": t, "class": "Cup", "position": [x + 0.01 * robot, y], "source": f"r{robot}"}
        for x, y in CUPS
    ]


def _metric(text: str, name: str) -> float:
    found = re.search(rf"^{name} (\S+)$", text, re.MULTILINE)
    assert found is not None, name
    return float(found.group(1))


def _run(tolerance: float | None) -> tuple[dict[str, Any], float, float]:
    options: dict[str, Any] = {} if tolerance is None else {"order_tolerance": tolerance}
    # replays are what the strict order makes here (half the scans): the overload
    # guard that refuses late scans while replays take more than a tenth of the time
    # (test_api_overload) must not decide this test by how loaded the machine is
    settings = Settings(knowledge=SIM1, port=0, reorder_window=1.0, replay_limit=1.0, **options)
    with running_server(settings) as url, httpx.Client(base_url=url, timeout=30) as client:
        for tick in range(20):
            for robot in (3, 2, 1):  # the newest stamp arrives first
                scan = _scan(100.0 + 0.1 * tick + 0.001 * robot, robot)
                assert client.post("/detections", json={"detections": scan}).status_code == 200
        metrics = client.get("/metrics").text
        world = client.get("/world", params={"time": 102.5}).json()
        sources = {
            s["name"]: s["in_arrival_order"] for s in client.get("/sources").json()["sources"]
        }
    assert sum(sources.values()) == _metric(metrics, "semwm_arrival_order_scans")
    assert sources["r3"] == 0  # the newest of each instant: always in order
    return (
        world,
        _metric(metrics, "semwm_replayed_scans"),
        _metric(metrics, "semwm_arrival_order_scans"),
    )


def test_concurrent_scans_are_processed_in_arrival_order_with_the_strict_orders_world() -> None:
    relaxed, replayed, in_arrival_order = _run(None)  # the default: 5 ms
    assert replayed == 0.0
    assert in_arrival_order == 40.0  # r2 and r1 of each of the 20 instants
    strict, strict_replayed, none_moved = _run(0.0)
    assert strict_replayed == 20 * (1 + 2) and none_moved == 0.0  # r2 replays r3; r1 both
    assert len(relaxed["objects"]) == len(strict["objects"]) == 2
    for a, b in zip(relaxed["objects"], strict["objects"], strict=True):
        assert a["id"] == b["id"] and a["class"] == b["class"]
        assert max(abs(p - q) for p, q in zip(a["position"], b["position"], strict=True)) < 1e-3


def test_synchronised_scans_in_source_order_keep_their_times() -> None:
    """A team's sensors stamping the same instant, arriving in source order: nothing is
    moved or replayed, and each scan keeps its stamp (one prediction step per instant)."""
    settings = Settings(knowledge=SIM1, port=0, reorder_window=1.0)
    with running_server(settings) as url, httpx.Client(base_url=url, timeout=30) as client:
        for tick in range(5):
            for robot in (1, 2, 3):
                scan = _scan(100.0 + 0.1 * tick, robot)
                assert client.post("/detections", json={"detections": scan}).json()["time"] == (
                    100.0 + 0.1 * tick
                )
        metrics = client.get("/metrics").text
    assert _metric(metrics, "semwm_replayed_scans") == 0.0
    assert _metric(metrics, "semwm_arrival_order_scans") == 0.0
