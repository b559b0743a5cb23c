"""The world's lock hands itself to queued scans in time order (api.ordered_lock)."""

from __future__ import annotations

import threading
import time
from pathlib import Path

import pytest

from api.ordered_lock import TimeOrderedLock
from api.service import WorldService

ROOT = Path(__file__).resolve().parents[2]


def _wait_for(condition, timeout: float = 10.0) -> None:  # type: ignore[no-untyped-def]
    deadline = time.monotonic() + timeout
    while not condition():
        if time.monotonic() > deadline:
            raise AssertionError("timed out")
        time.sleep(0.001)


def _queue(
    lock: TimeOrderedLock, keys: list[tuple[str, float]], entered: list[str]
) -> list[threading.Thread]:
    """Start one thread per (name, key), each waiting (in this order) for the held ``lock``."""
    threads = []
    for count, (name, key) in enumerate(keys, start=1):

        def enter(name: str = name, key: float = key) -> None:
            with lock.ordered(key):
                entered.append(name)

        thread = threading.Thread(target=enter)
        thread.start()
        threads.append(thread)
        _wait_for(lambda count=count: lock.waiting == count)
    return threads


def test_waiters_enter_by_smallest_key_not_by_arrival() -> None:
    lock = TimeOrderedLock()
    entered: list[str] = []
    with lock.ordered(0.0):
        threads = _queue(lock, [("a", 5.0), ("b", 1.0), ("c", 3.0), ("d", 2.0)], entered)
    for thread in threads:
        thread.join(10)
    assert entered == ["b", "d", "c", "a"]
    assert not lock.locked() and lock.waiting == 0


def test_equal_keys_enter_first_come_and_plain_users_go_first() -> None:
    lock = TimeOrderedLock()
    entered: list[str] = []
    with lock.ordered():
        threads = _queue(lock, [("first", 1.0), ("second", 1.0)], entered)

        def plain() -> None:
            with lock.ordered():
                entered.append("plain")

        reader = threading.Thread(target=plain)
        reader.start()
        _wait_for(lambda: lock.waiting == 3)
    for thread in [reader, *threads]:
        thread.join(10)
    assert entered == ["plain", "first", "second"]


def test_the_lock_excludes_and_an_error_inside_releases_it() -> None:
    lock = TimeOrderedLock()
    inside = 0
    most = 0

    def work(seed: int) -> None:
        nonlocal inside, most
        for step in range(200):
            with lock.ordered(float((seed * 7 + step) % 13)):
                inside += 1
                most = max(most, inside)
                inside -= 1

    threads = [threading.Thread(target=work, args=(i,)) for i in range(6)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join(30)
    assert most == 1
    with pytest.raises(ValueError), lock.ordered(1.0):
        raise ValueError("inside")
    assert not lock.locked()
    with pytest.raises(RuntimeError, match="unlocked"):
        lock.release()


def test_scans_queued_behind_the_world_lock_are_applied_in_time_order_without_replay() -> None:
    service = WorldService.from_file(ROOT / "knowledge" / "sim1.yaml", reorder_window=1.0)
    service.ingest([{"time": 10.0, "class": "Cup", "position": [1.0, 1.0], "source": "r0"}], True)
    results: dict[str, int] = {}

    def post(source: str, stamp: float) -> None:
        detection = {"time": stamp, "class": "Cup", "position": [1.0, 1.02], "source": source}
        results[source] = service.ingest([detection], True).value.applied

    with service._lock.ordered():  # the world is busy: these queue up, newest first
        threads = []
        for count, (source, stamp) in enumerate([("r3", 10.3), ("r2", 10.2), ("r1", 10.1)], 1):
            thread = threading.Thread(target=post, args=(source, stamp))
            thread.start()
            threads.append(thread)
            _wait_for(lambda count=count: service._lock.waiting == count)
    for thread in threads:
        thread.join(30)
    assert results == {"r1": 1, "r2": 1, "r3": 1}
    assert service.model.replayed_scans == 0
    assert service.model.latest_time == pytest.approx(10.3)


def test_a_waiter_interrupted_while_waiting_leaves_the_queue(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """A signal (KeyboardInterrupt) in a waiting thread must not leave a dead entry that
    the lock would later be handed to."""
    lock = TimeOrderedLock()
    lock.acquire(0.0)
    real_lock = threading.Lock

    class Interrupted:  # a baton whose second acquire (the wait) is interrupted
        def __init__(self) -> None:
            self.inner = real_lock()
            self.calls = 0

        def acquire(self) -> bool:
            self.calls += 1
            if self.calls == 2:
                raise KeyboardInterrupt
            return self.inner.acquire()

        def release(self) -> None:
            self.inner.release()

        def __lt__(self, other: object) -> bool:
            return False

    monkeypatch.setattr("api.ordered_lock.threading.Lock", Interrupted)
    with pytest.raises(KeyboardInterrupt):
        lock.acquire(1.0)
    monkeypatch.undo()
    assert lock.waiting == 0  # left the queue
    lock.release()
    assert not lock.locked()  # not handed to the dead waiter
    with lock.ordered(2.0):
        assert lock.locked()


def test_try_acquire_takes_a_free_lock_and_never_waits() -> None:
    lock = TimeOrderedLock()
    assert lock.try_acquire() and lock.locked()
    started = time.monotonic()
    assert not lock.try_acquire()  # taken: refused at once, not queued
    assert time.monotonic() - started < 0.1 and lock.waiting == 0
    lock.release()
    assert not lock.locked()
    with lock.ordered():
        assert not lock.try_acquire()
    assert lock.try_acquire()
    lock.release()
