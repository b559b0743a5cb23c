"""Clock offset of a source from sync exchanges (paper 003, section 3.3, as NTP does it).

One exchange between a source (a robot, its own clock) and the service (the
service clock) gives four times:

1. ``sent`` (t1): the source sends a sync request, by its clock;
2. ``received`` (t2): the service receives it, by the service clock;
3. ``replied`` (t3): the service answers, by the service clock;
4. ``returned`` (t4): the source receives the answer, by its clock.

``delay = (t4 - t1) - (t3 - t2)`` is the time on the wire both ways, and
``offset = ((t2 - t1) + (t3 - t4)) / 2`` is how far the service clock is ahead of
the source's, exact when both directions take equally long; otherwise it is off by
half the difference of the two directions, at most ``delay / 2``. A time ``s`` on
the source's clock is ``s + offset`` on the service clock.

Paper 003 computes the same offset (``local time - (remote time + latency / 2)``,
with ``t2 = t3``) and smooths it with a mean filter. A plain mean lets one delayed
exchange (a wireless retry: 0.5 s one way, 20 ms the other) pull the estimate by a
quarter of a second. We keep the paper's mean but over the exchanges that bound the
error best: of the last ``window`` exchanges, the ``best`` with the smallest delays
(until the window is full, the smaller-delay half of those kept)
(NTP's clock filter keeps the one smallest-delay sample of its last eight; averaging
a few of the smallest keeps the paper's smoothing). A sliding window follows a
drifting clock.

Pure: no clock is read here; the edges (``api/``, :mod:`semwm.client`) read clocks.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

MAX_CLOCK = 1e12
"""Largest absolute time of an exchange (s): :data:`semwm.detection.MAX_TIME`. Within it
every delay, offset and their squares are finite (issue 30: ``1.797e308`` made the
offset's uncertainty overflow, and every later status of the source failed)."""


class ExchangeError(ValueError):
    """An exchange whose times cannot come from one round trip; ``field`` names the time."""

    def __init__(self, field_name: str, message: str) -> None:
        self.field = field_name
        super().__init__(f"{field_name}: {message}")


@dataclass(frozen=True)
class Exchange:
    """One finished sync exchange (s): t1 ``sent`` and t4 ``returned`` by the source's
    clock, t2 ``received`` and t3 ``replied`` by the service's."""

    sent: float
    received: float
    replied: float
    returned: float

    def __post_init__(self) -> None:
        for name in ("sent", "received", "replied", "returned"):
            value = getattr(self, name)
            if not math.isfinite(value):
                raise ExchangeError(name, f"must be a finite number; got {value}")
            if abs(value) > MAX_CLOCK:
                raise ExchangeError(
                    name, f"must lie within ±{MAX_CLOCK:g} s (a clock reading); got {value:g}"
                )
        if self.replied < self.received:
            raise ExchangeError(
                "replied",
                f"the service replied ({self.replied}) before it received ({self.received})",
            )
        if self.returned < self.sent:
            raise ExchangeError(
                "returned",
                f"the answer returned ({self.returned}) before it was sent ({self.sent})",
            )
        if self.delay < 0.0:
            raise ExchangeError(
                "returned",
                f"the round trip ({self.returned - self.sent:g} s) is shorter than the service's "
                f"processing time ({self.replied - self.received:g} s)",
            )

    @property
    def delay(self) -> float:
        """Time on the wire, both ways (s): ``(t4 - t1) - (t3 - t2)``."""
        return (self.returned - self.sent) - (self.replied - self.received)

    @property
    def offset(self) -> float:
        """Service clock minus source clock (s): ``((t2 - t1) + (t3 - t4)) / 2``."""
        return ((self.received - self.sent) + (self.replied - self.returned)) / 2.0


@dataclass(frozen=True)
class ClockEstimate:
    """The smoothed offset of one source's clock (immutable: :meth:`add` returns a new one).

    Parameters
    ----------
    window
        How many of the latest exchanges are kept (a drifting clock is followed).
    best
        How many of the kept exchanges, those with the smallest delays, are averaged
        at most; until the window is full, the smaller-delay half of those kept.
    exchanges
        The kept exchanges, oldest first.
    count
        Exchanges seen in all (kept or not).
    """

    window: int = 32
    best: int = 16
    exchanges: tuple[Exchange, ...] = field(default=())
    count: int = 0

    def __post_init__(self) -> None:
        if self.window < 1 or not 1 <= self.best <= self.window:
            raise ValueError(
                f"need window >= 1 and 1 <= best <= window; got window={self.window}, "
                f"best={self.best}"
            )

    def add(self, exchange: Exchange) -> ClockEstimate:
        """The estimate after one more exchange."""
        kept = (*self.exchanges, exchange)[-self.window :]
        return ClockEstimate(self.window, self.best, kept, self.count + 1)

    def _selected(self) -> list[Exchange]:
        # until the window is full, the smaller-delay half of what is kept (at most
        # ``best``): with only a few exchanges one delayed exchange must not count
        kept = len(self.exchanges)
        count = self.best if kept >= self.window else min(self.best, max(1, (kept + 1) // 2))
        return sorted(self.exchanges, key=lambda e: e.delay)[:count]

    @property
    def synced(self) -> bool:
        return bool(self.exchanges)

    @property
    def offset(self) -> float | None:
        """Mean offset of the smallest-delay exchanges (s), ``None`` before the first."""
        selected = self._selected()
        if not selected:
            return None
        return math.fsum(e.offset for e in selected) / len(selected)

    @property
    def delay(self) -> float | None:
        """Smallest round-trip delay among the kept exchanges (s)."""
        return min((e.delay for e in self.exchanges), default=None)

    @property
    def offset_std(self) -> float | None:
        """Standard uncertainty of :attr:`offset` (s).

        Each selected offset is off by an unknown asymmetry within ``±delay / 2``,
        taken as uniform (variance ``delay² / 12``); with the spread of the selected
        offsets around their mean: ``sqrt(var(offsets) + mean(delay)² / 12)``.
        """
        selected = self._selected()
        if not selected:
            return None
        mean = math.fsum(e.offset for e in selected) / len(selected)
        spread = math.fsum((e.offset - mean) ** 2 for e in selected) / len(selected)
        mean_delay = math.fsum(e.delay for e in selected) / len(selected)
        # hypot: sqrt(a² + b²) without overflow in the squares
        return math.hypot(math.sqrt(spread), mean_delay / math.sqrt(12.0))

    @property
    def finite(self) -> bool:
        """Whether the offset and its uncertainty are finite numbers (or not yet known)."""
        try:
            values = (self.offset, self.offset_std, self.delay)
        except (ArithmeticError, ValueError):
            return False
        return all(v is None or math.isfinite(v) for v in values)

    def to_service(self, stamp: float) -> float:
        """A time on the source's clock placed on the service clock (unchanged if unsynced)."""
        offset = self.offset
        return stamp if offset is None else stamp + offset
