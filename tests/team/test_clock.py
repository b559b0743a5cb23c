"""The clock estimator (paper 003 3.3, NTP-style) and the source registry's time guards."""

from __future__ import annotations

import math

import numpy as np
import pytest

from semwm.clock import ClockEstimate, Exchange, ExchangeError
from semwm.sources import SourceRegistry, TimeGuard, TimeGuardError


def exchange(t1: float, offset: float, out: float, back: float, work: float = 0.001) -> Exchange:
    """A round trip from a source whose clock is ``offset`` s behind the service's:
    ``out`` s to the service, ``work`` s there, ``back`` s to the source."""
    t2 = t1 + offset + out
    t3 = t2 + work
    return Exchange(t1, t2, t3, t3 - offset + back)


def test_delay_and_offset_are_the_ntp_formulas() -> None:
    e = Exchange(sent=10.0, received=113.0, replied=113.5, returned=11.5)
    assert e.delay == pytest.approx((11.5 - 10.0) - (113.5 - 113.0))
    assert e.offset == pytest.approx(((113.0 - 10.0) + (113.5 - 11.5)) / 2)


def test_symmetric_latency_gives_the_exact_offset_and_asymmetry_half_the_difference() -> None:
    assert exchange(5.0, 2.5, 0.05, 0.05).offset == pytest.approx(2.5)
    # 30 ms out, 90 ms back: the estimate is off by (out - back) / 2 = -30 ms
    assert exchange(5.0, 2.5, 0.03, 0.09).offset == pytest.approx(2.5 + (0.03 - 0.09) / 2)


@pytest.mark.parametrize(
    ("times", "field"),
    [
        ((0.0, 1.0, 0.5, 2.0), "replied"),  # replied before received
        ((1.0, 1.0, 1.0, 0.5), "returned"),  # returned before sent
        ((0.0, 0.0, 5.0, 1.0), "returned"),  # round trip shorter than the processing
        ((math.nan, 0.0, 0.0, 1.0), "sent"),
    ],
)
def test_impossible_exchanges_name_the_time(times: tuple[float, ...], field: str) -> None:
    with pytest.raises(ExchangeError) as error:
        Exchange(*times)
    assert error.value.field == field


def test_one_delayed_exchange_does_not_move_the_estimate_a_plain_mean_would() -> None:
    truth = -3.0
    good = [
        exchange(t, truth, 0.02 + 0.01 * (t % 3), 0.02 + 0.01 * ((t + 1) % 3)) for t in range(5)
    ]
    delayed = exchange(10.0, truth, 0.5, 0.02)  # a retry: 0.5 s out, 20 ms back
    estimate = ClockEstimate(window=8, best=3)
    for e in [*good[:2], delayed, *good[2:]]:
        estimate = estimate.add(e)
    plain_mean = sum(e.offset for e in [*good, delayed]) / 6
    selected = sorted(good, key=lambda e: e.delay)[:3]
    assert estimate.offset == pytest.approx(sum(e.offset for e in selected) / 3)
    assert abs(estimate.offset - truth) < 0.02 < abs(plain_mean - truth)
    assert estimate.count == 6 and estimate.delay == pytest.approx(min(e.delay for e in good))


def test_the_window_follows_a_clock_that_changed() -> None:
    estimate = ClockEstimate(window=4, best=2)
    for t in range(4):
        estimate = estimate.add(exchange(t, 1.0, 0.02, 0.02))
    for t in range(4, 8):
        estimate = estimate.add(exchange(t, 1.5, 0.02, 0.02))
    assert estimate.offset == pytest.approx(1.5)
    assert estimate.count == 8 and len(estimate.exchanges) == 4


def test_offset_std_is_spread_plus_the_asymmetry_bound() -> None:
    e1, e2 = exchange(0.0, 1.0, 0.01, 0.01), exchange(1.0, 1.1, 0.01, 0.01)
    estimate = ClockEstimate(window=2, best=2).add(e1).add(e2)
    delay = (e1.delay + e2.delay) / 2
    assert estimate.offset_std == pytest.approx(math.sqrt(0.05**2 + delay**2 / 12))


def test_synced_detections_are_placed_on_the_service_clock() -> None:
    registry = SourceRegistry()
    registry.sync("r1", exchange(5.0, 100.0, 0.02, 0.02))
    placement = registry.place(
        [{"time": 6.0, "class": "Cup", "position": [0, 0], "source": "r1"},
         {"time": 6.0, "class": "Cup", "position": [0, 0], "source": "r2"}],
        now=106.5,
    )  # fmt: skip
    assert [d["time"] for d in placement.detections] == [pytest.approx(106.0), 6.0]  # type: ignore[index]


def test_guards_refuse_far_future_and_jumps_and_count_them() -> None:
    registry = SourceRegistry(TimeGuard(max_ahead=10.0, max_jump=60.0))
    ok = registry.place([{"time": 100.0, "source": "r1"}], now=1000.0)
    registry.accepted(ok, now=1000.0)
    with pytest.raises(TimeGuardError) as ahead:
        registry.place([{"time": 1e15, "source": "r1"}], now=1001.0)
    assert ahead.value.problems[0].kind == "ahead" and "max_ahead = 10 s" in str(ahead.value)
    # 100 -> 300 s while the service clock moved 5 s: a jump of 200 - 5 > 60 s
    with pytest.raises(TimeGuardError) as jump:
        registry.place([{"time": 300.0, "source": "r1"}], now=1005.0)
    assert jump.value.problems[0].kind == "jump" and "max_jump = 60 s" in str(jump.value)
    # 100 -> 300 s after 150 s of service time: 50 s faster than the service, allowed
    registry.place([{"time": 300.0, "source": "r1"}], now=1150.0)
    status = registry.status("r1")
    assert status is not None and status.refused == 2 and status.detections == 1
    assert status.problem is not None and "max_jump" in status.problem


def test_a_sync_restarts_the_jump_reference() -> None:
    registry = SourceRegistry(TimeGuard(max_ahead=None, max_jump=1.0))
    registry.accepted(registry.place([{"time": 5.0, "source": "r1"}]))
    with pytest.raises(TimeGuardError):
        registry.place([{"time": 50.0, "source": "r1"}])
    registry.sync("r1", exchange(10.0, 0.0, 0.01, 0.01))
    registry.place([{"time": 50.0, "source": "r1"}])


def test_a_synced_detection_carries_the_offsets_uncertainty_as_time_std() -> None:
    registry = SourceRegistry()
    registry.sync("r1", exchange(5.0, 100.0, 0.02, 0.08))  # asymmetric: uncertain offset
    std = registry.clock("r1").offset_std  # type: ignore[union-attr]
    assert std is not None and std > 0.0
    placement = registry.place(
        [{"time": 6.0, "class": "Cup", "position": [0, 0], "source": "r1"},
         {"time": 6.0, "class": "Cup", "position": [0, 0], "source": "r1", "time_std": 0.03},
         {"time": 6.0, "class": "Cup", "position": [0, 0], "source": "r2"}],
    )  # fmt: skip
    placed = [dict(d) for d in placement.detections]  # type: ignore[call-overload]
    assert placed[0]["time_std"] == pytest.approx(std)
    assert placed[1]["time_std"] == pytest.approx(math.hypot(0.03, std))
    assert "time_std" not in placed[2]  # unsynced: as sent


def test_a_delayed_exchange_among_a_few_does_not_count() -> None:
    # five exchanges, true offset 0: asymmetric delays, one delayed 0.4 s one way
    # (paper 003's mean of all five would be 39 ms off)
    delays = [(0.02, 0.06), (0.15, 0.03), (0.4, 0.02), (0.05, 0.05), (0.03, 0.1)]
    estimate = ClockEstimate()
    for k, (out, back) in enumerate(delays):
        estimate = estimate.add(exchange(float(k), 0.0, out, back))
    assert estimate.offset is not None and abs(estimate.offset) < 0.02


def test_batches_placed_per_source_match_one_by_one_placement() -> None:
    """The per-source shortcut for plain batches gives what placing each detection does,
    refusals included (then it steps aside), on random batches of several sources."""
    rng = np.random.default_rng(3)
    for trial in range(200):
        registry = SourceRegistry(TimeGuard(max_ahead=10.0, max_jump=5.0))
        registry.accepted(registry.place([{"time": 100.0, "source": "a"}], 100.0), 100.0)
        if trial % 3 == 0:
            registry.sync("b", Exchange(0.0, 1.0, 1.0, 0.1))  # synced: no shortcut
        batch: list[dict[str, object]] = []
        for _ in range(int(rng.integers(1, 8))):
            time: object = float(100.0 + rng.uniform(-2.0, 12.0))
            if rng.random() < 0.1:
                time = int(time)
            if rng.random() < 0.05:
                time = rng.choice(["x", True, float("nan")])
            batch.append({"time": time, "source": rng.choice(["a", "b", None])})
        plain = registry._place_plain(batch, 100.5)
        try:
            each = registry._place_each(batch, 100.5)
        except TimeGuardError:
            assert plain is None
            continue
        if plain is not None:
            assert all(x is y for x, y in zip(plain[0], each[0], strict=True))
            assert plain[1:] == each[1:]
