"""Issue 30 case 6: one clock-sync request must not break a source.

``{"sent": -6e-8, "received": 1.797e308, ...}`` used to be stored, then overflowed
the offset's uncertainty: that request, every later ``GET /sources`` and every
detection of the source answered 500, and ``POST /reset`` did not clear it.
"""

from __future__ import annotations

from typing import Any

import pytest
from fastapi.testclient import TestClient

from api.service import WorldService
from semwm.clock import MAX_CLOCK, ClockEstimate, Exchange, ExchangeError
from semwm.sources import SourceRegistry

HUGE = 1.797e308


def _sources(client: TestClient) -> list[dict[str, Any]]:
    response = client.get("/sources")
    assert response.status_code == 200, response.text
    return list(response.json()["sources"])


@pytest.mark.parametrize(
    ("body", "fields"),
    [
        (
            {"sent": -6e-8, "received": HUGE, "replied": HUGE, "returned": HUGE},
            ["received", "replied", "returned"],
        ),
        ({"sent": -HUGE, "received": 0.0, "replied": 0.0, "returned": 1.0}, ["sent"]),
        ({"sent": 0.0, "received": 1.0, "replied": 1.0, "returned": 2e12}, ["returned"]),
        ({"sent": 5.0, "received": 2.0, "replied": 1.0, "returned": 6.0}, ["replied"]),
        ({"sent": 5.0, "received": 1.0, "replied": 1.0, "returned": 4.0}, ["returned"]),
    ],
)
def test_a_sync_with_out_of_range_or_unordered_times_is_422_and_stores_nothing(
    client: TestClient, body: dict[str, float], fields: list[str]
) -> None:
    before = _sources(client)
    response = client.post("/sources/r1/sync", json=body)
    assert response.status_code == 422, response.text
    assert [item["loc"] for item in response.json()["detail"]] == [["body", f] for f in fields]
    assert _sources(client) == before
    # the source still works: its detections are taken and a good exchange syncs it
    assert client.post("/detections", json={"time": 1.0, "class": "Cup", "position": [1.0, 2.0],
                                            "source": "r1"}).status_code == 200  # fmt: skip
    good = {"sent": 5.0, "received": 100.0, "replied": 100.0, "returned": 5.2}
    assert client.post("/sources/r1/sync", json=good).status_code == 200
    (r1,) = [s for s in _sources(client) if s["name"] == "r1"]
    assert r1["synced"] and r1["exchanges"] == 1


def test_a_sync_within_the_bounds_gives_finite_numbers_at_the_extremes(
    client: TestClient, service: WorldService
) -> None:
    body = {"sent": -MAX_CLOCK, "received": MAX_CLOCK, "replied": MAX_CLOCK,
            "returned": MAX_CLOCK}  # fmt: skip
    response = client.post("/sources/r1/sync", json=body)
    assert response.status_code == 200, response.text
    reply = response.json()
    assert reply["delay"] == pytest.approx(2 * MAX_CLOCK)
    assert reply["offset_std"] == pytest.approx(2 * MAX_CLOCK / 12**0.5)
    assert _sources(client)[0]["name"] == "r1"


def _unchecked(sent: float, received: float, replied: float, returned: float) -> Exchange:
    """An exchange past its checks, as one stored before them could be."""
    exchange = object.__new__(Exchange)
    for name, value in zip(("sent", "received", "replied", "returned"),
                           (sent, received, replied, returned), strict=True):  # fmt: skip
        object.__setattr__(exchange, name, value)
    return exchange


def test_a_stored_clock_that_overflows_cannot_break_the_source() -> None:
    """A clock state that got in before the bounds still reports (its numbers null)."""
    registry = SourceRegistry()
    registry._record("r1").clock = ClockEstimate().add(_unchecked(-HUGE, HUGE, HUGE, HUGE))
    (status,) = registry.statuses()
    assert status.synced and status.clock_offset is None and status.offset_std is None
    assert status.to_dict()["delay"] is None


def test_the_registry_refuses_an_exchange_whose_estimate_overflows() -> None:
    registry = SourceRegistry()
    with pytest.raises(ExchangeError, match="received"):
        Exchange(0.0, HUGE, HUGE, HUGE)
    with pytest.raises(ExchangeError, match="overflow"):
        registry.sync("r1", _unchecked(-HUGE, HUGE, HUGE, HUGE))
    assert registry.statuses() == []
