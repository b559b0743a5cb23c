"""``WorldModel._placed`` decides the common case (the class's noise, within range,
inside the region's bounds) without calling ``_ignored``: it must use and refuse
exactly what ``_ignored`` alone would, detection by detection, with the same words."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from semwm.knowledge.loader import load_knowledge
from semwm.knowledge.shipped import shipped_knowledge_path
from semwm.validation import check, parse
from semwm.world import WorldModel


def _batch(rng: np.random.Generator, knowledge_file: str, n: int) -> list[dict[str, Any]]:
    """Detections around the region's edges and the detectors' ranges: some with a
    sensor position, some with their own noise, some detectors with a range."""
    model = WorldModel(load_knowledge(shipped_knowledge_path(knowledge_file)))
    knowledge = model.knowledge
    region = knowledge.world.region
    assert region is not None
    classes = list(knowledge.classes)
    detectors = list(knowledge.detectors)
    batch = []
    for _ in range(n):
        (x0, x1), (y0, y1) = region
        # near an edge: within a few noise widths either side of it, or anywhere
        x = rng.choice([x0, x1, rng.uniform(x0, x1)]) + rng.normal(0.0, 0.3)
        y = rng.choice([y0, y1, rng.uniform(y0, y1)]) + rng.normal(0.0, 0.3)
        detection: dict[str, Any] = {
            "time": 0.0,
            "class": str(rng.choice(classes)),
            "position": [float(x), float(y)],
            "detector": str(rng.choice(detectors)),
            "source": "r1",
        }
        reach = knowledge.detectors[detection["detector"]].range
        if rng.random() < 0.6:  # a sensor near its range from the detection
            distance = (reach or 5.0) * rng.uniform(0.8, 2.0)
            angle = rng.uniform(0.0, 2.0 * np.pi)
            detection["sensor_position"] = [
                float(x + distance * np.cos(angle)),
                float(y + distance * np.sin(angle)),
            ]
        if rng.random() < 0.2:
            variance = float(rng.uniform(0.001, 0.2))
            detection["covariance"] = [[variance, 0.0], [0.0, variance]]
        batch.append(detection)
    return batch


@pytest.mark.parametrize("knowledge_file", ["robocup.yaml", "sim2.yaml"])
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_placed_uses_and_refuses_what_ignored_alone_would(knowledge_file: str, seed: int) -> None:
    rng = np.random.default_rng(seed)
    model = WorldModel(load_knowledge(shipped_knowledge_path(knowledge_file)))
    parsed = parse(_batch(rng, knowledge_file, 600))  # type: ignore[arg-type]
    measurements = check(parsed, model.knowledge, model._mhf.factory, 0)
    used, skipped = model._placed(parsed, measurements)
    expected_used, expected_skipped = [], []
    for index, (m, d) in enumerate(zip(measurements, parsed, strict=True)):
        why = model._ignored(d, m, index, {})
        (expected_used if why is None else expected_skipped).append(m if why is None else why)
    assert [m.seq for m in used] == [m.seq for m in expected_used]
    assert skipped == expected_skipped
    reasons = {why.reason for why in skipped}
    assert len(used) > 100 and len(skipped) > 20  # both sides of every edge are tried
    if knowledge_file == "robocup.yaml":
        assert reasons == {"out_of_range", "outside_region"}
