"""Paper 002's simulation claims as assertions on short seeded runs.

Run with the shipped knowledge (``paper`` association model, eqs. (5)-(8)) and,
for comparison, the same knowledge with ``association_model: mht``. Claims that
do not hold are marked ``xfail(strict=True)`` with the measured numbers: they
are findings about the MHF or the knowledge, not about these tests.
"""

from __future__ import annotations

from functools import cache

import numpy as np
import pytest

from semwm.knowledge.loader import load_document
from semwm.knowledge.resolve import resolve
from semwm.knowledge.shipped import shipped_knowledge_path
from semwm.sim.ablations import without_appearance_relations
from semwm.sim.runner import RunResult, run_scenario
from semwm.sim.scenarios import Scenario, make_scenario
from semwm.world_types import WorldObject

PAPER_EMPTY = (
    "paper model, shipped knowledge: the world stays empty (seed 0: sim1 0 of 5 objects, "
    "sim2 no person track). With F = f_clutter + f_new + sum f_existing over the "
    "hypothesis's objects and an unnormalised likelihood exp(-d^2/2) <= 1, the all-clutter "
    "hypothesis gains f_c/(f_c+f_n) = 0.91 per detection and a one-object one at most "
    "f_e/(f_c+f_n+f_e) = 0.78 (sim1), so no object is ever kept"
)


@cache
def scenario(name: str) -> Scenario:
    return make_scenario(name, 0)


@cache
def run(name: str, model: str, ablation: str = "") -> RunResult:
    """Run a scenario with the shipped knowledge under ``model``: ``paper``, ``mht``, or
    ``mht-no-missed`` (mht without the missed-detection term, paper 002's behaviour)."""
    s = scenario(name)
    document = load_document(shipped_knowledge_path(s.knowledge_file))
    world = document.world.model_copy(
        update={
            "association_model": model.removesuffix("-no-missed"),
            "missed_detection_term": not model.endswith("-no-missed"),
        }
    )
    document = document.model_copy(update={"world": world})
    if ablation == "door-relation":
        document = without_appearance_relations(document)
    return run_scenario(s, resolve(document), progress=False)


def at(result: RunResult, time: float) -> tuple[WorldObject, ...]:
    times = np.asarray([f.time for f in result.scenario.truth])
    return result.worlds[int(np.argmin(np.abs(times - time)))].objects


def person_id(result: RunResult, time: float) -> int | None:
    """World id of the object nearest the true person (within 1.5 m) at ``time``."""
    frames = result.scenario.truth
    k = int(np.argmin(np.abs(np.asarray([f.time for f in frames]) - time)))
    truth = np.asarray(frames[k].objects[0].position)
    best = min(
        result.worlds[k].objects,
        key=lambda o: float(np.linalg.norm(np.asarray(o.position) - truth)),
        default=None,
    )
    if best is None or np.linalg.norm(np.asarray(best.position) - truth) > 1.5:
        return None
    return best.id


def moments() -> dict[str, float]:
    m = scenario("sim2").metadata["moments"]
    assert isinstance(m, dict)
    return m


xfail_paper = pytest.mark.xfail(strict=True, reason=PAPER_EMPTY)


@pytest.mark.parametrize(
    "model",
    [
        pytest.param("paper", marks=xfail_paper),
        "mht",
    ],
)
def test_sim1_one_object_per_real_object_with_taxonomy_resolved_classes(model: str) -> None:
    result = run("sim1", model)
    final = result.worlds[-1].objects
    truth = result.scenario.truth[-1].objects
    assert len(final) == len(truth), [(o.cls, o.position) for o in final]
    for real in truth:
        near = [o for o in final if np.linalg.norm(np.subtract(o.position, real.position)) < 0.2]
        assert len(near) == 1, (real.id, near)
        # a CokeCan sometimes seen as Can is reported CokeCan (taxonomy, eq. 8)
        assert near[0].cls == real.cls


@pytest.mark.parametrize("model", [pytest.param("paper", marks=xfail_paper), "mht"])
def test_sim1_metrics_class_accuracy_is_exact_once_resolved(model: str) -> None:
    metrics = run("sim1", model).metrics
    assert metrics.class_accuracy.n_assigned > 0.8 * 5 * metrics.n_frames
    assert metrics.class_accuracy.compatible == 1.0


@pytest.mark.parametrize(
    "model",
    [
        pytest.param("paper", marks=xfail_paper),
        "mht",
    ],
)
def test_sim2_person_keeps_one_id_through_both_occlusions(model: str) -> None:
    result = run("sim2", model)
    m = moments()
    ids = {
        person_id(result, t)
        for t in (m["A"] - 0.5, m["A"] + 0.7, m["B"] + 1.0, m["C"] - 0.5, m["D"] + 1.0)
    }
    assert len(ids) == 1 and None not in ids, ids
    assert result.metrics.id_switches == 0


def _near_false_pair(objects: tuple[WorldObject, ...], radius: float) -> list[WorldObject]:
    x, y, _ = scenario("sim2").metadata["false_pair"][0]  # type: ignore[index]
    return [o for o in objects if np.hypot(o.position[0] - x, o.position[1] - y) < radius]


def test_sim2_false_pair_at_e_fades_within_two_seconds() -> None:
    """With the missed-detection term (shipped default) the two close false positives at
    E (0.14 m and 0.3 s apart: under the knowledge's clutter density very unlikely to be
    clutter) make a track, which then goes unseen where the detector would see a person
    at 5 Hz: its existence falls below min_existence and it leaves the world within 2 s
    of the second false detection, long before P_max would remove it (paper 002: F)."""
    result = run("sim2", "mht")
    m = moments()
    last_false = max(t for _, _, t in scenario("sim2").metadata["false_pair"])  # type: ignore[misc]
    assert not _near_false_pair(at(result, last_false + 2.0), 1.0)
    for dt in (2.0, 3.0, m["F"] - last_false):
        assert not _near_false_pair(at(result, last_false + dt), 1.5), dt


@pytest.mark.parametrize("model", [pytest.param("paper", marks=xfail_paper), "mht-no-missed"])
def test_sim2_false_track_at_e_is_removed_by_the_uncertainty_threshold(model: str) -> None:
    """Paper 002 Fig. 2, E to F: without a missed-detection term the false pair makes a
    track that nothing denies; it goes only when it becomes too uncertain (P_max) or its
    prediction runs out of the room (the region), and is gone by F."""
    result = run("sim2", model)
    m = moments()
    born = _near_false_pair(at(result, m["E"] + 0.5), 1.0)
    assert born, "no false track shortly after E"
    later = {o.id for o in at(result, m["F"])}
    assert born[0].id not in later
    p_max = result.knowledge.classes["Person"].max_position_variance
    assert p_max is not None
    track = [o for w in result.worlds for o in w.objects if o.id == born[0].id]
    region = result.knowledge.world.region
    assert region is not None
    last = track[-1]
    uncertain = max(np.linalg.eigvalsh(np.asarray(last.covariance))) > 0.5 * p_max
    leaving = any(
        min(v - lo, hi - v) < 3.0 * np.sqrt(last.covariance[i][i])
        for i, (v, (lo, hi)) in enumerate(zip(last.position, region, strict=True))
    )
    assert uncertain or leaving
    assert len(track) >= 10  # it lived for seconds: nothing denied it


def _first_person_time(result: RunResult) -> float:
    enter = float(result.scenario.metadata["enter_time"])  # type: ignore[arg-type]
    for frame in result.scenario.truth:
        if frame.time >= enter and person_id(result, frame.time) is not None:
            return frame.time
    return float("inf")


@pytest.mark.parametrize("model", [pytest.param("paper", marks=xfail_paper), "mht"])
def test_sim2_without_the_door_relation_the_person_is_found_later_or_false_tracks_grow(
    model: str,
) -> None:
    with_door = run("sim2", model)
    without = run("sim2", model, "door-relation")
    assert _first_person_time(with_door) < float("inf")
    later = _first_person_time(without) > _first_person_time(with_door)
    more_false = without.metrics.false_objects.total > with_door.metrics.false_objects.total
    assert later or more_false, (
        _first_person_time(with_door),
        _first_person_time(without),
        with_door.metrics.false_objects.total,
        without.metrics.false_objects.total,
    )
