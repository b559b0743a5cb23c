"""What a robot runs to keep its clock synced with a semwm service (paper 003, 3.3).

>>> sync = ClockSync("http://127.0.0.1:8000", "robot1")       # doctest: +SKIP
>>> sync.exchange()          # one round trip; the service updates its estimate
>>> sync.run(every=3.0)      # a background thread, every third second as in paper 003

The robot keeps stamping its detections with its own clock; the service places
them at ``stamp + offset``. Only the standard library is used (``urllib``).
"""

from __future__ import annotations

import contextlib
import json
import threading
import time
import urllib.parse
import urllib.request
from collections.abc import Callable
from typing import Any

Transport = Callable[[str, dict[str, Any]], dict[str, Any]]


def http_transport(base_url: str, timeout: float = 5.0) -> Transport:
    """POST JSON to ``base_url + path`` and return the JSON answer."""

    def post(path: str, payload: dict[str, Any]) -> dict[str, Any]:
        request = urllib.request.Request(
            base_url.rstrip("/") + path,
            data=json.dumps(payload).encode(),
            headers={"content-type": "application/json"},
            method="POST",
        )
        with urllib.request.urlopen(request, timeout=timeout) as response:
            answer: dict[str, Any] = json.loads(response.read())
            return answer

    return post


class ClockSync:
    """Sync exchanges of one source with the service.

    Parameters
    ----------
    base_url
        The service, e.g. ``http://127.0.0.1:8000``.
    source
        The source name its detections carry (``"source": "robot1"``).
    clock
        The robot's clock, the one its detection stamps come from (s).
    transport
        How a JSON body is posted (tests wrap :func:`http_transport`).
    """

    def __init__(
        self,
        base_url: str,
        source: str,
        *,
        clock: Callable[[], float] = time.time,
        transport: Transport | None = None,
    ) -> None:
        self.source = source
        self.clock = clock
        self._post = transport or http_transport(base_url)
        self._path = f"/sources/{urllib.parse.quote(source, safe='')}/sync"
        self.last: dict[str, Any] | None = None
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def exchange(self) -> dict[str, Any]:
        """One round trip, then report it; returns the service's view of this source."""
        sent = self.clock()
        reply = self._post(self._path, {"sent": sent})
        returned = self.clock()
        finished = {
            "sent": sent,
            "received": reply["received"],
            "replied": reply["replied"],
            "returned": returned,
        }
        self.last = self._post(self._path, finished)
        return self.last

    def sync(self, count: int = 5, interval: float = 0.0) -> dict[str, Any]:
        """``count`` exchanges ``interval`` s apart; returns the last answer."""
        if count < 1:
            raise ValueError(f"count must be at least 1; got {count}")
        answer: dict[str, Any] = {}
        for i in range(count):
            if i and interval > 0:
                time.sleep(interval)
            answer = self.exchange()
        return answer

    @property
    def offset(self) -> float | None:
        """Service clock minus this robot's clock, as the service last estimated it (s)."""
        if self.last is None:
            return None
        offset = self.last.get("clock_offset")
        return float(offset) if offset is not None else None

    def run(self, every: float = 3.0) -> None:
        """Exchange every ``every`` s in a daemon thread until :meth:`stop`; errors
        (service away) are retried at the next tick."""
        if self._thread is not None:
            raise RuntimeError("already running")
        self._stop.clear()

        def loop() -> None:
            while not self._stop.is_set():
                with contextlib.suppress(OSError):  # service away: retry at the next tick
                    self.exchange()
                self._stop.wait(every)

        self._thread = threading.Thread(target=loop, name=f"clock-sync-{self.source}", daemon=True)
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join()
            self._thread = None
