"""The hold (``WorldModel(hold=...)``): scans are kept pending for ``hold`` s and
processed in time order, so arrivals out of order within the hold cost no replay."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest
from categories.test_kick import KNOWLEDGE as KICK_KNOWLEDGE

from semwm import load_knowledge
from semwm.detection import DetectionError, OutOfOrderError
from semwm.knowledge.loader import knowledge_from_text
from semwm.knowledge.model import Knowledge
from semwm.knowledge.shipped import shipped_knowledge_path
from semwm.persistence import DurableWorld, model_digest
from semwm.persistence.replay import world_digest
from semwm.world import WorldModel

Batch = list[dict[str, Any]]
RATE_HZ = 30.0
GRID = [("Cup" if (i + j) % 2 else "CokeCan", (0.6 + 0.7 * i, 0.45 + 0.7 * j))
        for i in range(3) for j in range(3)]  # fmt: skip


@pytest.fixture(scope="module")
def sim1() -> Knowledge:
    return load_knowledge(shipped_knowledge_path("sim1.yaml"))


def team_stream(seconds: float, robots: int = 3, seed: int = 0) -> list[tuple[float, Batch]]:
    """``bench_teamload``'s layout, smaller: each robot sees 5 of 9 static objects at
    30 Hz (5 cm noise), one batch per robot and frame, in time order."""
    rng = np.random.default_rng(seed)
    stream = []
    for tick in range(int(seconds * RATE_HZ)):
        for r in range(robots):
            t = tick / RATE_HZ + r * 1e-3
            seen = [GRID[(2 * r + k) % len(GRID)] for k in range(5)]
            noise = rng.normal(0.0, 0.05, size=(len(seen), 2))
            batch = [
                {"time": t, "class": cls, "source": f"r{r}",
                 "position": [x + noise[k, 0], y + noise[k, 1]]}
                for k, (cls, (x, y)) in enumerate(seen)
            ]  # fmt: skip
            stream.append((t, batch))
    return stream


def arrivals(stream: list[tuple[float, Batch]], jitter: float, seed: int = 1) -> list[Batch]:
    """The batches in order of arrival, each delayed by ``±jitter`` s (uniform)."""
    rng = np.random.default_rng(seed)
    arrived = [(t + rng.uniform(-jitter, jitter), i, b) for i, (t, b) in enumerate(stream)]
    return [b for _, _, b in sorted(arrived, key=lambda a: (a[0], a[1]))]


def held_scans(wm: WorldModel) -> list[tuple[Any, ...]]:
    """The pending scans as plain values: key, then each detection's number, time, class,
    position, noise and source, and whether the scan has a sensor view."""
    return [
        (key, [(m.seq, m.time, m.cls, m.z.tolist(), m.R.tolist(), m.source)
               for m in held.measurements], held.view is None)
        for key, held in sorted(wm._pending.items())
    ]  # fmt: skip


def test_hold_0_is_todays_model_every_scan_at_once(sim1: Knowledge) -> None:
    """``hold=0`` takes the immediate path: nothing pending, replays as before, the same
    worlds and ingest results as a model built without the option (checked against
    the code before the hold on the robocup and team streams when it was added)."""
    batches = arrivals(team_stream(1.0), jitter=0.02)
    default = WorldModel(sim1, reorder_window=0.3)
    zero = WorldModel(sim1, reorder_window=0.3, hold=0.0)
    for i, batch in enumerate(batches):
        assert default.ingest(batch) == zero.ingest(batch)
        assert zero.pending_scans == 0 and zero.latest_time == zero.processed_time
        if i % 10 == 0:
            assert world_digest(default.world()) == world_digest(zero.world())
    assert world_digest(default.world()) == world_digest(zero.world())
    assert zero.replayed_scans == default.replayed_scans > 0  # the jitter costs replays


@pytest.mark.parametrize("hold", [0.041, 0.15])
def test_a_stream_shuffled_within_the_hold_gives_the_in_order_world_without_replay(
    sim1: Knowledge, hold: float
) -> None:
    stream = team_stream(1.0)
    in_order = WorldModel(sim1, reorder_window=0.3)
    for _, batch in stream:
        in_order.ingest(batch)
    held = WorldModel(sim1, reorder_window=0.3, hold=hold)
    asked = WorldModel(sim1, reorder_window=0.3, hold=hold)  # queried after every batch
    for batch in arrivals(stream, jitter=0.02):  # out of order by up to 40 ms
        held.ingest(batch)
        asked.ingest(batch)
        asked.world()
    assert held.replayed_scans == 0 == asked.replayed_scans
    assert world_digest(asked.world()) == world_digest(held.world())
    assert held_scans(asked) == held_scans(held)
    assert asked._state.time == held._state.time
    assert held.pending_scans > 0
    assert world_digest(held.world()) == world_digest(in_order.world())
    assert [h.probability for h in held.hypotheses(5)] == [
        h.probability for h in in_order.hypotheses(5)
    ]
    held.set_hold(0.0)  # processes what is pending: the same world, committed
    assert held.pending_scans == 0
    assert world_digest(held.world()) == world_digest(in_order.world())


def test_queries_include_pending_detections_and_commit_nothing(sim1: Knowledge) -> None:
    held = WorldModel(sim1, hold=1.0)
    now = WorldModel(sim1)
    for t in (0.0, 0.1, 0.2):
        for wm in (held, now):
            wm.ingest({"time": t, "class": "Cup", "position": [1.0 + t, 2.0]})
    assert held.pending_scans == 3 and held.processed_time is None
    assert held.latest_time == pytest.approx(0.2)
    state = held._state
    for _ in range(2):  # the second answer comes from the cache
        assert world_digest(held.world()) == world_digest(now.world())
        assert held.object(1) == now.object(1)
        assert [h.probability for h in held.hypotheses()] == [
            h.probability for h in now.hypotheses()
        ]
    assert held._state is state and held.pending_scans == 3  # nothing committed
    held.ingest({"time": 1.5, "class": "Cup", "position": [1.5, 2.0]})  # releases 0.0-0.2
    now.ingest({"time": 1.5, "class": "Cup", "position": [1.5, 2.0]})
    assert held.pending_scans == 1 and held.processed_time == pytest.approx(0.2)
    assert world_digest(held.world()) == world_digest(now.world())


def test_refusals_happen_at_ingest_and_change_nothing(sim1: Knowledge) -> None:
    wm = WorldModel(sim1, reorder_window=0.1, hold=0.2)
    for t in (1.0, 1.1, 1.2, 1.3, 1.4, 1.5):
        wm.ingest({"time": t, "class": "Cup", "position": [1.0, 2.0]})
    before = (world_digest(wm.world()), wm.pending_scans, wm.processed_time)
    with pytest.raises(DetectionError):  # validated whole at ingest, even when it would be held
        wm.ingest([{"time": 1.45, "class": "Cup", "position": [1.0, 2.0]},
                   {"time": 1.45, "class": "Nope", "position": [1.0, 2.0]}])  # fmt: skip
    with pytest.raises(OutOfOrderError):  # processed up to 1.3: 1.1 is before 1.3 - 0.1
        wm.ingest({"time": 1.1, "class": "Cup", "position": [1.0, 2.0]})
    assert (world_digest(wm.world()), wm.pending_scans, wm.processed_time) == before
    wm.ingest({"time": 1.25, "class": "Cup", "position": [1.0, 2.0], "source": "late"})
    assert wm.replayed_scans == 1  # later than the hold, within the window: replayed


def test_an_action_and_a_knowledge_change_process_the_held_scans_first(sim1: Knowledge) -> None:
    wm = WorldModel(sim1, hold=0.5)
    wm.ingest({"time": 0.0, "class": "Cup", "position": [1.0, 2.0]})
    wm.ingest({"time": 0.1, "class": "Cup", "position": [1.0, 2.0]})
    wm.replace_knowledge(sim1)
    assert wm.pending_scans == 0 and wm.processed_time == pytest.approx(0.1)


def test_a_restart_replays_the_journal_to_the_same_held_scans(
    sim1: Knowledge, tmp_path: Path
) -> None:
    batches = arrivals(team_stream(1.0), jitter=0.02)
    half = len(batches) // 2
    live = DurableWorld.open(tmp_path / "a", sim1, reorder_window=0.3, hold=0.1)
    for batch in batches[:half]:
        live.ingest(batch)
    pending = held_scans(live.model)
    assert pending
    digest = model_digest(live.model)
    live.close()
    for snapshot_every in (10_000, 7):  # from the journal alone; from a snapshot + tail
        data = tmp_path / f"b{snapshot_every}"
        first = DurableWorld.open(data, sim1, reorder_window=0.3, hold=0.1,
                                  snapshot_every=snapshot_every)  # fmt: skip
        for batch in batches[:half]:
            first.ingest(batch)
        first.close()
        again = DurableWorld.open(data, sim1, reorder_window=0.3, hold=0.1)
        assert again.model.hold == 0.1
        assert held_scans(again.model) == pending  # the same scans, detections numbered alike
        assert model_digest(again.model) == digest
        for batch in batches[half:]:
            again.ingest(batch)
        uninterrupted = WorldModel(sim1, reorder_window=0.3, hold=0.1)
        for batch in batches:
            uninterrupted.ingest(batch)
        assert model_digest(again.model) == model_digest(uninterrupted)
        again.close()


def test_a_new_hold_on_restart_is_a_journaled_change(sim1: Knowledge, tmp_path: Path) -> None:
    first = DurableWorld.open(tmp_path, sim1, hold=1.0)
    for t in (0.0, 0.1, 0.2):
        first.ingest([{"time": t, "class": "Cup", "position": [1.0, 2.0]}])
    first.close()
    second = DurableWorld.open(tmp_path, sim1, hold=0.0)  # processes the held scans
    assert second.model.pending_scans == 0
    digest = model_digest(second.model)
    second.close()
    third = DurableWorld.open(tmp_path, sim1, hold=0.0)
    assert third.model.pending_scans == 0 and model_digest(third.model) == digest
    third.close()


def test_hold_must_be_a_finite_number_not_below_0(sim1: Knowledge) -> None:
    for bad in (-0.1, float("nan"), float("inf")):
        with pytest.raises(ValueError, match="hold"):
            WorldModel(sim1, hold=bad)


KICKABLE = KICK_KNOWLEDGE  # a ball to kick and a post (tests/categories/test_kick.py)
KICK = {"time": 1.0, "type": "kick", "source": "me", "near": [0.1, 0.0], "direction": [0, 3],
        "speed": 2.0}  # fmt: skip


def test_an_action_sees_and_then_processes_the_held_scans() -> None:
    knowledge = knowledge_from_text(KICKABLE, "yaml")
    worlds = []
    for hold in (0.0, 0.5):
        wm = WorldModel(knowledge, hold=hold)
        for t in np.arange(0.0, 1.0 + 1e-9, 0.1):
            wm.ingest([{"time": float(t), "class": "Ball", "position": [0.0, 0.0]},
                       {"time": float(t), "class": "Post", "position": [3.0, 0.0]}])  # fmt: skip
        assert wm.pending_scans == (5 if hold else 0)  # 0.6-1.0 held
        moved = wm.act(KICK)  # found among the held scans' objects
        assert wm.pending_scans == 0 and moved
        wm.ingest({"time": 1.5, "class": "Ball", "position": [0.0, 1.2]})
        worlds.append(world_digest(wm.world(2.0)))
    assert worlds[0] == worlds[1]
