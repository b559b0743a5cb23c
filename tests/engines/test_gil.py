"""A scan in the core releases Python's interpreter lock: other threads of the process
(the service's `/health`, reads of the last published world) run while it does
(docs/engines.md, "Safety at the boundary")."""

from __future__ import annotations

import threading
import time

import numpy as np
import pytest

from semwm.knowledge.loader import load_knowledge
from semwm.knowledge.shipped import shipped_knowledge_path
from semwm.world import WorldModel

from . import needs_rust

pytestmark = needs_rust


@pytest.mark.parametrize("call", ["process_measurements", "process_and_publish"])
def test_other_threads_run_while_the_core_scans(call: str) -> None:
    """``process_and_publish``: a scan, its confidences and its publishing in one call
    (``WorldModel._ingest_scan``)."""
    knowledge = load_knowledge(shipped_knowledge_path("grid.yaml"))
    side = 150  # 22,500 new objects in one scan (30-60 ms): long enough to see threads interleave
    region = knowledge.world.region
    assert region is not None
    (x0, x1), (y0, y1) = region[0], region[1]
    xs = np.linspace(x0 + 0.1, x1 - 0.1, side)
    ys = np.linspace(y0 + 0.1, y1 - 0.1, side)
    batch = [
        {"time": 0.0, "class": "Thing", "position": [float(x), float(y)], "source": "cam"}
        for x in xs
        for y in ys
    ]
    model = WorldModel(knowledge, engine="rust")
    mhf = model._mhf
    core = mhf._core
    assert core is not None
    measurements = model.validate(batch)
    state = core.to_core(model._state)
    ticks: list[float] = []
    done = threading.Event()

    def count() -> None:
        while not done.is_set():
            ticks.append(time.perf_counter())
            time.sleep(0)

    counter = threading.Thread(target=count)
    counter.start()
    try:
        time.sleep(0.05)
        start = time.perf_counter()
        if call == "process_measurements":
            core.engine.process_measurements(state, list(measurements))
        else:
            core.engine.process_and_publish(
                state,
                core.core_book(model._book),
                list(measurements),
                {},
                {},
                False,
                1,
                [],
                core.state_of,
            )
        end = time.perf_counter()
    finally:
        done.set()
        counter.join()
    # the middle half of the call is the core's scan (reading the measurements is
    # before it): the other thread ran there
    middle = [t for t in ticks if start + 0.25 * (end - start) < t < start + 0.75 * (end - start)]
    assert end - start > 0.01, "the scan was too short to tell"
    assert middle, f"no other thread ran during {1e3 * (end - start):.0f} ms in the core"
