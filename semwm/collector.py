"""Python's cyclic garbage collector, paused while the world model processes a batch.

Processing a scan allocates thousands of container objects (object versions,
hypotheses, sets of keys, per-detection options) that are garbage a few scans later
and hold no reference cycles. Each 700 allocations start a collection of the
youngest generation, and every hundredth one a full collection that walks every
live object of the process (numpy's and scipy's included): on a static grid of
100 objects that is about 20 % of the CPU per frame. Paused during
:meth:`semwm.WorldModel.ingest`, the collector runs its collections between batches
instead, as allocations continue after it; reference counting frees everything
that is not a cycle at once either way, so memory use is the same.

The collector is process-wide: the pause is counted, so that concurrent ingests
(several models, several threads) resume it only when the last one ends, and only
if it was enabled when the first one began.
"""

from __future__ import annotations

import gc
import threading
from collections.abc import Iterator
from contextlib import contextmanager

_lock = threading.Lock()
_depth = 0
_resume = False


@contextmanager
def collector_paused() -> Iterator[None]:
    """Within: the cyclic garbage collector is disabled (see the module docstring)."""
    global _depth, _resume
    with _lock:
        if _depth == 0:
            _resume = gc.isenabled()
            gc.disable()
        _depth += 1
    try:
        yield
    finally:
        with _lock:
            _depth -= 1
            if _depth == 0 and _resume:
                gc.enable()
