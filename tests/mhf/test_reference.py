"""The real MHF against the brute-force reference (tests/mhf/reference.py) on random
small scenarios: the same hypotheses with the same probabilities, to 1e-9."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from semwm.knowledge.model import AppearanceRelation, KnownObject
from semwm.world import WorldModel

from .compare import (
    assert_same_hypotheses,
    lineage_existence,
    map_objects,
    real_hypotheses,
    ref_hypotheses,
)
from .kb import knowledge, static_class
from .reference import RefDetection, run_reference

REGION = ((-1.0, 5.0), (-1.0, 5.0))


def kb_compatible(kb: Any, a: str, b: str) -> bool:
    from semwm.knowledge.taxonomy import Taxonomy

    taxonomy = Taxonomy({name: c.parents for name, c in kb.classes.items()})
    return taxonomy.compatible(a, b)


def _taxonomy(rng: np.random.Generator, p_max: float | None) -> tuple[list, dict[str, list[str]]]:
    """Classes and, per leaf class, the classes a detection of it may carry."""

    def cls(name: str, **kw: Any):
        return static_class(
            name,
            f_existing=float(rng.uniform(0.3, 2.0)),
            f_new=float(rng.uniform(0.05, 0.5)),
            r=float(rng.uniform(0.02, 0.2)),
            p0=float(rng.uniform(0.02, 0.3)),
            qc=float(rng.uniform(0.001, 0.2)),
            p_max=p_max,
            **kw,
        )

    choice = int(rng.integers(4))
    if choice == 0:
        return [cls("Cup")], {"Cup": ["Cup"]}
    if choice == 1:
        return [cls("Can"), cls("CokeCan", is_a=["Can"])], {"CokeCan": ["CokeCan", "Can"]}
    if choice == 2:
        return [cls("Cup"), cls("Plate")], {"Cup": ["Cup"], "Plate": ["Plate"]}
    return (
        [cls("Can"), cls("CokeCan", is_a=["Can"]), cls("Cup")],
        {"CokeCan": ["CokeCan", "Can"], "Cup": ["Cup"]},
    )


def _scenario(seed: int, model: str):
    rng = np.random.default_rng(seed)
    p_max = float(rng.uniform(0.1, 0.4)) if rng.random() < 0.4 else None
    classes, seen_as = _taxonomy(rng, p_max)
    kb = knowledge(
        classes,
        f_clutter=float(rng.uniform(0.05, 1.0)),
        model=model,
        region=REGION if model == "mht" else None,
    )
    leaves = list(seen_as)
    truth = [
        (leaves[int(rng.integers(len(leaves)))], rng.uniform(0.0, 3.0, size=2))
        for _ in range(int(rng.integers(1, 4)))
    ]
    n_det = int(rng.integers(2, 7))
    scans = []
    t = 0.0
    seq = 0
    while seq < n_det:
        size = min(int(rng.integers(1, 3)), n_det - seq)
        source = str(rng.choice(["a", "b"]))
        scan = []
        for _ in range(size):
            if rng.random() < 0.2:
                c = leaves[int(rng.integers(len(leaves)))]
                z = rng.uniform(-1.0, 5.0, size=2)
            else:
                c, pos = truth[int(rng.integers(len(truth)))]
                c = seen_as[c][int(rng.integers(len(seen_as[c])))]
                z = pos + rng.normal(0.0, 0.2, size=2)
            scan.append(RefDetection(seq, t, c, z, source=source))
            seq += 1
        scans.append(scan)
        t += float(rng.choice([0.0, 0.3, 1.0, 2.5]))
    return kb, scans


def _ingest_all(kb, scans, engine: str = "python") -> WorldModel:
    wm = WorldModel(kb, engine=engine)
    for scan in scans:
        wm.ingest(
            [
                {"time": d.time, "class": d.cls, "position": list(d.z), "source": d.source}
                for d in scan
            ]
        )
    return wm


@pytest.mark.parametrize("model", ["paper", "mht"])
@pytest.mark.parametrize("seed", range(40))
def test_same_hypotheses_as_reference(seed: int, model: str, engine: str) -> None:
    kb, scans = _scenario(seed, model)
    wm = _ingest_all(kb, scans, engine)
    ref = run_reference(kb, scans)
    real, expected = real_hypotheses(wm), ref_hypotheses(ref)
    assert_same_hypotheses(real, expected)
    if model == "mht":  # the world: objects likely to exist over the whole hypothesis set
        floor = kb.world.min_existence
        lineages = lineage_existence(ref)
        world = wm.world(min_existence=floor).objects
        # every object the reference finds at least `floor` likely is in the world, at
        # least as likely (lineages that are one object in different hypotheses add up)
        for cls, existence in lineages.values():
            if existence >= floor:
                assert any(
                    kb_compatible(kb, o.cls, cls) and o.existence >= existence - 1e-9 for o in world
                ), (cls, existence, world)
        # and every world object is some lineage of the reference, no less likely
        for o in world:
            assert o.existence >= floor
            assert any(
                kb_compatible(kb, o.cls, cls) and existence <= o.existence + 1e-9
                for cls, existence in lineages.values()
            )
        return
    best = map_objects(expected)
    if best is not None:
        assert sorted((o.id is not None, o.cls) for o in wm.world().objects) == sorted(
            (True, c) for _, c in best
        )
        assert map_objects(real) == best


def _door_scenario(seed: int, model: str):
    """Doors and Persons (Person appears near a Door, eq. 4), a known map door, labels;
    one detection per scan."""
    rng = np.random.default_rng(1000 + seed)
    relation = AppearanceRelation(
        target="Door",
        max_distance=float(rng.uniform(0.5, 1.5)),
        frequency=float(rng.uniform(0.5, 3.0)),
    )
    classes = [
        static_class(
            "Door", f_existing=float(rng.uniform(0.2, 1.0)), f_new=0.1, r=0.05, p0=0.05, qc=0.001
        ),
        static_class(
            "Person",
            f_existing=float(rng.uniform(0.5, 2.0)),
            f_new=0.2,
            r=0.1,
            p0=0.1,
            qc=0.1,
            appearance=[relation],
        ),
    ]
    known = [KnownObject(cls="Door", position=(4.0, 4.0))] if rng.random() < 0.5 else []
    kb = knowledge(
        classes,
        f_clutter=float(rng.uniform(0.1, 0.6)),
        model=model,
        region=REGION if model == "mht" else None,
        known=known,
    )
    scans, t = [], 0.0
    for seq in range(int(rng.integers(2, 7))):
        cls = "Door" if rng.random() < 0.4 else "Person"
        centre = np.array([1.0, 1.0]) if rng.random() < 0.6 else np.array([4.0, 4.0])
        z = centre + rng.normal(0.0, 0.4, size=2)
        label = str(rng.choice(["p1", "p2"])) if cls == "Person" and rng.random() < 0.5 else None
        scans.append([RefDetection(seq, t, cls, z, label=label)])
        t += float(rng.choice([0.0, 0.5, 1.0]))
    return kb, scans


@pytest.mark.parametrize("model", ["paper", "mht"])
@pytest.mark.parametrize("seed", range(25))
def test_appearance_and_labels_as_reference(seed: int, model: str, engine: str) -> None:
    kb, scans = _door_scenario(seed, model)
    wm = WorldModel(kb, engine=engine)
    for scan in scans:
        wm.ingest(
            [
                {"time": d.time, "class": d.cls, "position": list(d.z), "label": d.label}
                for d in scan
            ]
        )
    assert_same_hypotheses(real_hypotheses(wm), ref_hypotheses(run_reference(kb, scans)))
