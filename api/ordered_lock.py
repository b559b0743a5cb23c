"""The world's lock, handed to waiting scans in time order (paper 003's ordered fusion).

Many robots post at once; their requests wait on the one world lock. A plain
``threading.Lock`` lets them in in no particular order, so a scan often enters after
a newer one and the world replays it (``WorldModel`` processes scans in time order).
Here the waiter with the earliest key (its scan's time on the service clock) enters
next, so scans that queue up are processed in time order and cost no replay. Others
(reads, edits, resets) wait with key ``-inf``: they enter before queued scans.

Entry order changes nothing but the cost: every request is still applied whole, one
at a time, and the model processes scans in time order whatever order they come in.
"""

from __future__ import annotations

import heapq
import itertools
import math
import threading
from types import TracebackType


class TimeOrderedLock:
    """A mutex whose waiters enter by smallest key first (ties: first come)."""

    def __init__(self) -> None:
        self._guard = threading.Lock()
        self._held = False
        self._waiting: list[tuple[float, int, threading.Lock]] = []
        self._arrival = itertools.count()

    def ordered(self, key: float = -math.inf) -> _Held:
        """``with lock.ordered(key):`` hold the lock; if it is taken, wait behind every
        waiter with a smaller key."""
        return _Held(self, key)

    def acquire(self, key: float = -math.inf) -> None:
        with self._guard:
            if not self._held:
                self._held = True
                return
            baton = threading.Lock()
            baton.acquire()
            entry = (key, next(self._arrival), baton)
            heapq.heappush(self._waiting, entry)
        try:
            baton.acquire()  # released by release(): the lock is handed over, still held
        except BaseException:  # interrupted while waiting (a signal in the main thread)
            with self._guard:
                if entry in self._waiting:  # not handed over: leave the queue
                    self._waiting.remove(entry)
                    heapq.heapify(self._waiting)
                    raise
            self.release()  # handed over meanwhile: pass it on
            raise

    def try_acquire(self) -> bool:
        """Take the lock if nobody holds it (then nobody waits for it either); never wait."""
        with self._guard:
            if self._held:
                return False
            self._held = True
            return True

    def release(self) -> None:
        with self._guard:
            if not self._held:
                raise RuntimeError("release of an unlocked TimeOrderedLock")
            if self._waiting:
                _, _, baton = heapq.heappop(self._waiting)
                baton.release()  # hand over: _held stays True
            else:
                self._held = False

    def locked(self) -> bool:
        return self._held

    @property
    def waiting(self) -> int:
        """How many are waiting for the lock."""
        with self._guard:
            return len(self._waiting)


class _Held:
    """The context of :meth:`TimeOrderedLock.ordered` (a class: no generator per use)."""

    __slots__ = ("key", "lock")

    def __init__(self, lock: TimeOrderedLock, key: float) -> None:
        self.lock, self.key = lock, key

    def __enter__(self) -> None:
        self.lock.acquire(self.key)

    def __exit__(
        self,
        kind: type[BaseException] | None,
        error: BaseException | None,
        trace: TracebackType | None,
    ) -> None:
        self.lock.release()
