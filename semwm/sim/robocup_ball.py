"""The RoboCup scenario with a ball and limited fields of view (paper 004).

Peers (start-stop robots, paper 000) each carry a camera with a limited opening
angle that turns steadily (a head scanning the field) instead of omnivision.
A passive ball rests until the nearest peer kicks it (every few seconds, a
random direction and speed), then rolls out at a constant deceleration. Every
camera frame is a scan with the camera's pose: its own position (self
localisation, labelled), and the robots and ball in its view.

The same detections are run twice through the same knowledge
(``knowledge/robocup.yaml`` with the camera's ``field_of_view`` and the
rate-based missed-detection term off, since a camera sees only its view): once
with the scans' sensor poses (negative information: an estimate in view that the
camera does not report loses existence) and once without. GOSPA tells what the
negative information is worth.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass
from itertools import groupby
from typing import Any

import numpy as np

from semwm.detection import Detection
from semwm.knowledge.model import Knowledge, KnowledgeDocument
from semwm.knowledge.resolve import resolve
from semwm.sim.metrics import Metrics, Point, compute_metrics
from semwm.sim.runner import taxonomy_of
from semwm.sim.scenarios import ROBOCUP_REGION, _start_stop_paths
from semwm.world import WorldModel

FIELD_OF_VIEW = 90.0  # degrees
CAMERA_RANGE = 5.0  # m
TURN_RATE = math.radians(90.0)  # rad/s: the head sweeps the field


@dataclass(frozen=True)
class BallScenario:
    """Detections (sorted), each scan's camera pose, and truth frames."""

    detections: list[Detection]
    poses: dict[tuple[float, str], tuple[float, float, float]]
    truth: list[tuple[float, list[Point]]]


def ball_knowledge(document: KnowledgeDocument) -> Knowledge:
    """``robocup.yaml`` with a camera of limited view: omnivision gets ``field_of_view``,
    and the rate-based missed-detection term is off (only the views say where it saw)."""
    world = document.world.model_copy(update={"missed_detection_term": False})
    detectors = tuple(
        d.model_copy(update={"field_of_view": FIELD_OF_VIEW, "range": CAMERA_RANGE})
        if d.name == "omnivision"
        else d
        for d in document.detectors
    )
    classes = tuple(
        c.model_copy(update={"max_time_without_update": 3.0})
        if c.max_time_without_update is not None
        else c
        for c in document.classes
    )
    return resolve(
        document.model_copy(update={"world": world, "detectors": detectors, "classes": classes}),
        source="robocup.yaml (camera view)",
    )


def make_ball_scenario(
    rng: np.random.Generator,
    *,
    n_peers: int = 4,
    n_opponents: int = 3,
    duration: float = 10.0,
    rate: float = 10.0,
    noise: float = 0.3,
    ball_noise: float = 0.1,
    self_noise: float = 0.1,
    alpha: float = 0.3,
    kick_every: tuple[float, float] = (1.5, 3.0),
) -> BallScenario:
    dt = 1.0 / rate
    steps = round(duration * rate) + 1
    n = n_peers + n_opponents
    positions, _ = _start_stop_paths(rng, n, steps, dt, 3.0)
    ids = [f"peer{i + 1}" for i in range(n_peers)] + [f"opp{i + 1}" for i in range(n_opponents)]
    classes = ["Peer"] * n_peers + ["Opponent"] * n_opponents
    phase = rng.uniform(0.0, 2.0 * math.pi, n_peers)
    ball = np.zeros(2)
    velocity = np.zeros(2)
    next_kick = float(rng.uniform(*kick_every))
    low = np.array([r[0] for r in ROBOCUP_REGION]) + 0.2
    high = np.array([r[1] for r in ROBOCUP_REGION]) - 0.2
    detections: list[Detection] = []
    poses: dict[tuple[float, str], tuple[float, float, float]] = {}
    truth: list[tuple[float, list[Point]]] = []
    for k in range(steps):
        t = round(k * dt, 9)
        here = positions[k]
        if t >= next_kick:
            angle = rng.uniform(0.0, 2.0 * math.pi)
            velocity = rng.uniform(1.5, 3.5) * np.array([math.cos(angle), math.sin(angle)])
            next_kick = t + float(rng.uniform(*kick_every))
        speed = float(np.linalg.norm(velocity))
        if speed > 0.0:
            tau = min(dt, speed / alpha)
            ball = ball + velocity / speed * (speed * tau - alpha * tau**2 / 2.0)
            velocity = velocity / speed * max(0.0, speed - alpha * dt)
            outside = (ball < low) | (ball > high)
            velocity[outside] *= -1.0  # the field's boundary bounces it back
            ball = np.clip(ball, low, high)
        points = [Point(ids[i], classes[i], tuple(here[i])) for i in range(n)]
        truth.append((t, [*points, Point("ball", "Ball", tuple(ball))]))
        for p in range(n_peers):
            heading = float((phase[p] + TURN_RATE * t + math.pi) % (2 * math.pi) - math.pi)
            poses[(t, ids[p])] = (float(here[p, 0]), float(here[p, 1]), heading)
            sensor = tuple(float(v) for v in here[p])
            detections.append(
                Detection(
                    time=t,
                    cls="Peer",
                    position=tuple(here[p] + rng.normal(0.0, self_noise, 2)),
                    source=ids[p],
                    detector="self_localization",
                    label=ids[p],
                    sensor_position=sensor,
                )
            )
            targets = [(here[j], "Robot", noise) for j in range(n) if j != p]
            for target, cls, sigma in [*targets, (ball, "Ball", ball_noise)]:
                if not _in_view(target - here[p], heading) or rng.random() < 0.1:
                    continue
                detections.append(
                    Detection(
                        time=t,
                        cls=cls,
                        position=tuple(target + rng.normal(0.0, sigma, 2)),
                        source=ids[p],
                        detector="omnivision",
                        sensor_position=sensor,
                    )
                )
    return BallScenario(detections, poses, truth)


def _in_view(offset: np.ndarray, heading: float) -> bool:
    if float(np.linalg.norm(offset)) > CAMERA_RANGE:
        return False
    bearing = (math.atan2(offset[1], offset[0]) - heading + math.pi) % (2 * math.pi) - math.pi
    return abs(bearing) <= math.radians(FIELD_OF_VIEW) / 2.0


def _scans(scenario: BallScenario) -> Iterator[tuple[tuple[float, str], list[Detection]]]:
    for key, group in groupby(scenario.detections, key=lambda d: (d.time, d.source or "")):
        yield key, list(group)


def run_ball(knowledge: Knowledge, scenario: BallScenario, negative_information: bool) -> Metrics:
    """GOSPA and the other metrics of one run, with or without the scans' poses."""
    model = WorldModel(knowledge)
    estimates: list[list[Point]] = []
    scans = list(_scans(scenario))
    index = 0
    for t, _ in scenario.truth:
        while index < len(scans) and scans[index][0][0] <= t:
            key, scan = scans[index]
            x, y, heading = scenario.poses[key]
            sensor = (
                {"pose": [x, y, heading], "detector": "omnivision"}
                if negative_information
                else None
            )
            model.ingest(scan, sensor=sensor)
            index += 1
        estimates.append([Point(o.id, o.cls, o.position) for o in model.world(time=t).objects])
    return compute_metrics(
        [points for _, points in scenario.truth],
        estimates,
        c=2.0,
        compatible=taxonomy_of(knowledge).compatible,
    )


def compare(
    document: KnowledgeDocument, seeds: list[int], duration: float = 10.0
) -> dict[str, Any]:
    """GOSPA (c = 2 m, p = 1) with and without negative information, per seed."""
    knowledge = ball_knowledge(document)
    rows = []
    for seed in seeds:
        scenario = make_ball_scenario(np.random.default_rng(seed), duration=duration)
        with_views = run_ball(knowledge, scenario, True)
        without = run_ball(knowledge, scenario, False)
        rows.append(
            {
                "seed": seed,
                "with": with_views.gospa.total,
                "without": without.gospa.total,
                "with_false": with_views.gospa.false,
                "without_false": without.gospa.false,
            }
        )
    return {
        "gospa_with_negative_information": float(np.mean([r["with"] for r in rows])),
        "gospa_without_negative_information": float(np.mean([r["without"] for r in rows])),
        "runs": rows,
    }


if __name__ == "__main__":  # python -m semwm.sim.robocup_ball [SEED...]
    import json
    import sys

    from semwm.knowledge.loader import load_document
    from semwm.knowledge.shipped import shipped_knowledge_path

    chosen = [int(a) for a in sys.argv[1:]] or [0, 1, 2]
    print(
        json.dumps(compare(load_document(shipped_knowledge_path("robocup.yaml")), chosen), indent=2)
    )
