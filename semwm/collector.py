"""Python's cyclic garbage collector, paused while the world model processes a batch.

Processing a scan allocates thousands of container objects (object versions,
hypotheses, sets of keys, per-detection options) that are garbage a few scans later
and hold no reference cycles. Each 700 allocations start a collection of the
youngest generation, and every hundredth one a full collection that walks every
live object of the process (numpy's and scipy's included): on a static grid of
100 objects that is about 20 % of the CPU per frame. Paused during
:meth:`semwm.WorldModel.ingest`, the collector runs its collections between batches
instead, as allocations continue after it; reference counting frees everything
that is not a cycle at once either way, so memory use is the same. A small batch the
Rust engine takes in one call is not paused: it makes a few dozen Python objects, and
the pause (about a microsecond) would cost more than the collections it defers.

A query (:meth:`semwm.WorldModel.world`) of more than 64 objects makes their Python
values with the collector paused too: each object is several containers, none in a
cycle, and a query of 1,000 objects made without the pause set off collections that
took half its time and, now and then, a full one of tens of milliseconds. With the
Rust engine that includes the core's rows (``Engine.world_at``: a row of Python values
per object), for a state of more than 64 object versions. The client
(:func:`semwm.client.decode_json`) reads an answer of more than 64 KiB paused as well.

The collector is process-wide: the pause is counted, so that concurrent ingests
(several models, several threads) resume it only when the last one ends, and only
if it was enabled when the first one began.
"""

from __future__ import annotations

import gc
import threading
from contextlib import AbstractContextManager


class _Paused:
    """The context manager :func:`collector_paused` returns (a class, not a generator:
    it is entered once per batch, and a generator-based one costs about a microsecond)."""

    __slots__ = ()
    _lock = threading.Lock()
    _depth = 0
    _resume = False

    def __enter__(self) -> None:
        cls = _Paused
        with cls._lock:
            if cls._depth == 0:
                cls._resume = gc.isenabled()
                gc.disable()
            cls._depth += 1

    def __exit__(self, *exc: object) -> None:
        cls = _Paused
        with cls._lock:
            cls._depth -= 1
            if cls._depth == 0 and cls._resume:
                gc.enable()


_PAUSED = _Paused()


def collector_paused() -> AbstractContextManager[None]:
    """Within: the cyclic garbage collector is disabled (see the module docstring)."""
    return _PAUSED
