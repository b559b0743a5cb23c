"""Both engines give the same worlds, frame by frame, on the shipped scenarios.

After every scan: the same published objects (ids, classes, labels, counts,
confidence states) with positions, velocities, covariances, existence, mode and class
probabilities and confidences within 1e-9, and the same hypotheses (count, and the 20 most probable within 1e-9). The Python
engine is the specification (docs/engines.md)."""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path
from typing import Any

import pytest

from semwm.knowledge.loader import load_knowledge
from semwm.knowledge.model import Knowledge
from semwm.knowledge.shipped import shipped_knowledge_path
from semwm.sim.leftbehind import SensorViews
from semwm.sim.runner import scans
from semwm.sim.scenarios import make_scenario
from semwm.world import WorldModel
from semwm.world_types import WorldObject

from . import needs_rust

pytestmark = needs_rust

TOL = 1e-9
BENCHMARK_KNOWLEDGE = Path(__file__).resolve().parents[2] / "benchmarks" / "knowledge"


def _knowledge(name: str) -> Knowledge:
    """A shipped knowledge file, or a benchmark's (datasheet, leftbehind)."""
    if (BENCHMARK_KNOWLEDGE / name).is_file():
        return load_knowledge(BENCHMARK_KNOWLEDGE / name)
    return load_knowledge(shipped_knowledge_path(name))


SCENARIOS = [
    ("sim1", {}),
    ("sim2", {}),
    ("robocup", {"duration": 2.0}),
    # learnt coverage (the convex hull of a scan's detections) at a datasheet's rates;
    # leftbehind (range coverage, sensor views): test_same_world_leaving_things_behind
    ("datasheet", {"duration": 20.0}),
]


def _numbers(obj: WorldObject) -> list[float]:
    values = [*obj.position, *(obj.velocity or ()), *sum(obj.covariance, ()), obj.existence]
    values += [*(obj.mode_probabilities or {}).values()]
    values += [*(obj.class_probabilities or {}).values()]
    values += [] if obj.confidence is None else [obj.confidence.value]
    return values


def _keys(obj: WorldObject) -> tuple[Any, ...]:
    return (
        obj.id,
        obj.cls,
        obj.label,
        tuple(obj.mode_probabilities or ()),
        tuple(obj.class_probabilities or ()),
        None if obj.confidence is None else obj.confidence.state,
    )


def _largest_difference(a: list[float], b: list[float]) -> float:
    assert len(a) == len(b)
    return max((abs(x - y) for x, y in zip(a, b, strict=True)), default=0.0)


def _assert_same_frame(python: WorldModel, rust: WorldModel, frame: int) -> int:
    """The two worlds agree now; returns the number of objects."""
    expected = python.world(min_existence=1e-6).objects
    got = rust.world(min_existence=1e-6).objects
    assert [_keys(o) for o in got] == [_keys(o) for o in expected], f"frame {frame}"
    for g, e in zip(got, expected, strict=True):
        assert _largest_difference(_numbers(g), _numbers(e)) <= TOL, (frame, g.id)
    p_hyp = sorted(h.probability for h in python.hypotheses(20))
    r_hyp = sorted(h.probability for h in rust.hypotheses(20))
    assert len(r_hyp) == len(p_hyp) and _largest_difference(r_hyp, p_hyp) <= TOL
    assert rust.hypothesis_count == python.hypothesis_count
    return len(expected)


def _same_worlds(knowledge: Knowledge, detections: Any) -> tuple[int, int, WorldModel]:
    """Both engines through the scans of ``detections``, every frame compared: the
    number of frames, of objects over them, and the Rust engine's world model."""
    python = WorldModel(knowledge, engine="python")
    rust = WorldModel(knowledge, engine="rust")
    frames = objects = 0
    for scan in scans(detections):
        python.ingest(scan)
        rust.ingest(scan)
        objects += _assert_same_frame(python, rust, frames)
        frames += 1
    return frames, objects, rust


@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize(("name", "sizes"), SCENARIOS, ids=[s[0] for s in SCENARIOS])
def test_same_world_every_frame(name: str, sizes: dict[str, float], seed: int) -> None:
    scenario = make_scenario(name, seed, **sizes)
    frames, objects, rust = _same_worlds(_knowledge(scenario.knowledge_file), scenario.detections)
    assert frames > 10 and objects > frames  # a real run, not an empty one
    assert math.isfinite(rust.latest_time or 0.0)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_same_world_of_a_rolling_ball(seed: int) -> None:
    """robocup_kick.yaml's passive ball, whose speed decays (paper 004 IV-B), rolled
    through the camera's view and seen at 10 Hz with misses: the same frames."""
    import numpy as np

    rng = np.random.default_rng(seed)
    knowledge = load_knowledge(shipped_knowledge_path("robocup_kick.yaml"))
    python = WorldModel(knowledge, engine="python")
    rust = WorldModel(knowledge, engine="rust")
    position, velocity = np.array([0.5, -1.0]), rng.uniform([0.6, 0.5], [1.2, 1.0])
    frames = 0
    for step in range(60):
        t = round(0.1 * step, 9)
        speed = float(np.linalg.norm(velocity))
        if speed > 0.0:
            new_speed = max(0.0, speed - 0.4 * 0.1)
            position = position + velocity * 0.1
            velocity = velocity * (new_speed / speed)
        if rng.random() < 0.8:
            z = position + rng.normal(0.0, 0.05, size=2)
            scan = [
                {"time": t, "class": "Ball", "position": z.tolist(), "source": "A",
                 "detector": "camera"}
            ]  # fmt: skip
            python.ingest(scan)
            rust.ingest(scan)
            _assert_same_frame(python, rust, frames)
            frames += 1
    moving = python.world(min_existence=1e-6).objects
    assert frames > 30 and moving and moving[0].velocity is not None


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_same_kick_trials(seed: int, monkeypatch: pytest.MonkeyPatch) -> None:
    """The kick scenario (robocup_kick.yaml: the passive ball whose speed decays, a
    sensor view, a known action) with each engine: the same trials, the same confidence
    trace within 1e-9. Its world models are made inside run_kick: $SEMWM_ENGINE picks."""
    from semwm.sim.kick import run_kick

    knowledge = load_knowledge(shipped_knowledge_path("robocup_kick.yaml"))
    results = {}
    for engine in ("python", "rust"):
        monkeypatch.setenv("SEMWM_ENGINE", engine)
        results[engine] = run_kick(knowledge, seed, trials=3)
    python, rust = results["python"].trials, results["rust"].trials
    assert sorted(rust) == sorted(python)
    for model, expected_trials in python.items():
        for got, expected in zip(rust[model], expected_trials, strict=True):
            assert (got.model, got.times, got.states, got.scanning) == (
                expected.model,
                expected.times,
                expected.states,
                expected.scanning,
            )
            assert (got.time_to_see is None) == (expected.time_to_see is None)
            assert (
                _largest_difference([got.time_to_see or 0.0], [expected.time_to_see or 0.0]) <= TOL
            )
            assert _largest_difference(got.confidence, expected.confidence) <= TOL


@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize(
    ("poses", "views"),
    [(False, False), (True, False), (True, True)],
    ids=["hull", "poses", "views"],
)
def test_same_world_leaving_things_behind(seed: int, poses: bool, views: bool) -> None:
    """``leftbehind`` (the first 60 s: about one lap): without poses (learnt coverage,
    the convex hull of each scan's detections), with the sensor's pose in its detections
    (range coverage), or with poses as sensor views (``looked_at``: the view's
    Gauss-Hermite probability and the missed update, and empty scans)."""
    scenario = make_scenario("leftbehind", seed, poses=poses)
    scenario = replace(scenario, detections=[d for d in scenario.detections if d.time < 60.0])
    knowledge = _knowledge(scenario.knowledge_file)
    worlds: dict[str, Any] = {}
    for engine in ("python", "rust"):
        world = WorldModel(knowledge, reorder_window=0.0, engine=engine)
        worlds[engine] = SensorViews(world, scenario) if views else world
    frames = objects = 0
    for scan in scans(scenario.detections):
        worlds["python"].ingest(scan)
        worlds["rust"].ingest(scan)
        python, rust = (getattr(w, "inner", w) for w in (worlds["python"], worlds["rust"]))
        objects += _assert_same_frame(python, rust, frames)
        frames += 1
    assert frames > 100 and objects > frames


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_same_world_of_a_static_grid(seed: int) -> None:
    """The benchmark grid (N = 30, with its region): the region's inside probability,
    and the convex hull of each scan's detections computed in Rust on every scan (every
    object is detected in every frame, so the hull decides nothing here; the ``hull``
    case of :func:`test_same_world_leaving_things_behind` is where it does)."""
    scenario = make_scenario("grid", seed, n_objects=30, duration=3.0)
    knowledge = _knowledge(scenario.knowledge_file)
    region = tuple(tuple(r) for r in scenario.region)
    knowledge = knowledge.model_copy(
        update={"world": knowledge.world.model_copy(update={"region": region})}
    )
    frames, objects, _ = _same_worlds(knowledge, scenario.detections)
    assert frames > 20 and objects > 20 * frames


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_same_world_under_the_paper_model(seed: int) -> None:
    """robocup (2 s: robots reporting their own labelled positions) under the ``paper``
    association model (paper 002 eqs. 5-8: one global cluster, F per parent): the
    expansion's other model, with labels, frame by frame. (The shipped knowledge under
    ``paper`` keeps sim1's and sim2's worlds empty: tests/sim/test_paper_claims.py.)"""
    scenario = make_scenario("robocup", seed, duration=2.0)
    knowledge = _knowledge(scenario.knowledge_file)
    world = knowledge.world.model_copy(update={"association_model": "paper"})
    knowledge = knowledge.model_copy(update={"world": world})
    frames, objects, rust = _same_worlds(knowledge, scenario.detections)
    assert frames > 100 and objects > 3 * frames
    assert rust.hypothesis_count > 1  # hypotheses, not one certain world
