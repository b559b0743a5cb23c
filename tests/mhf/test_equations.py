"""Paper 002 eqs. (1), (4)-(8) and the MHT alternative, each against values computed by hand.

2D, static classes with a zeroth-order Kalman filter (x- = x, P- = P + dt Qc),
gating off, no pruning.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from semwm.knowledge.model import AppearanceRelation, KnownObject
from semwm.world import WorldModel

from .kb import det, knowledge, static_class

FC, FN, FE = 0.5, 0.2, 1.5  # f_clutter, f_new (base), f_existing
P0, QC, R = 0.1, 0.05, 0.09
R_FULL = np.array([[0.09, 0.02], [0.02, 0.05]])  # a detection's own covariance


def _hyps(wm: WorldModel) -> dict[tuple, float]:
    """Hypotheses keyed by their objects: ((lineage, class, label, rounded position), ...)."""
    out: dict[tuple, float] = {}
    for h in wm.hypotheses(10**6):
        key = tuple(
            sorted(
                (o.track, o.cls, o.label, tuple(round(v, 9) for v in o.position)) for o in h.objects
            )
        )
        assert key not in out
        out[key] = h.probability
    return out


def _obj(lineage: int, cls: str, pos, label=None) -> tuple:
    return (lineage, cls, label, tuple(round(float(v), 9) for v in pos))


def _cup_world(model: str = "paper", **kw) -> WorldModel:
    region = ((0.0, 10.0), (0.0, 4.0)) if model == "mht" else None
    return WorldModel(
        knowledge(
            [static_class("Cup", f_existing=FE, f_new=FN, r=R, p0=P0, qc=QC)],
            f_clutter=FC,
            model=model,
            region=region,
            **kw,
        )
    )


def _kalman(x, P, z, Rm):
    """Hand Kalman update: posterior mean and covariance, innovation y and S."""
    S = P + Rm
    K = P @ np.linalg.inv(S)
    return x + K @ (z - x), (np.eye(2) - K) @ P, z - x, S


def test_first_detection_clutter_or_new() -> None:
    wm = _cup_world()
    wm.ingest(det(0.0, "Cup", 1.0, 2.0))
    hyps = _hyps(wm)
    assert hyps.keys() == {(), (_obj(0, "Cup", (1.0, 2.0)),)}
    assert hyps[()] == pytest.approx(FC / (FC + FN), abs=1e-12)
    assert hyps[(_obj(0, "Cup", (1.0, 2.0)),)] == pytest.approx(FN / (FC + FN), abs=1e-12)


def test_second_detection_five_hypotheses() -> None:
    """Paper 000 III-A: a second detection near the first gives five hypotheses (the
    paper model; mht: test_second_detection_mht)."""
    model = "paper"
    z1, z2, dt = np.array([1.0, 2.0]), np.array([1.2, 1.9]), 2.0
    wm = _cup_world(model)
    wm.ingest(det(0.0, "Cup", *z1))
    wm.ingest(det(dt, "Cup", *z2, covariance=R_FULL.tolist()))
    P_pred = P0 * np.eye(2) + dt * QC * np.eye(2)
    x_post, _, y, S = _kalman(z1, P_pred, z2, R_FULL)
    if model == "paper":
        delta = z2 - x_post
        lik = math.exp(-0.5 * delta @ np.linalg.inv(R_FULL) @ delta)
        p_new1, p_cl1 = FN / (FC + FN), FC / (FC + FN)
        F1, F0 = FC + FN + FE, FC + FN  # the parent with one object, the empty parent
        w = {
            "new,new": p_new1 * FN / F1,
            "new,same": p_new1 * FE / F1 * lik,
            "new,clutter": p_new1 * FC / F1,
            "clutter,new": p_cl1 * FN / F0,
            "clutter,clutter": p_cl1 * FC / F0,
        }
    total = sum(w.values())
    o1, o2 = _obj(0, "Cup", z1), _obj(1, "Cup", z2)
    expected = {
        (o1, o2): w["new,new"] / total,
        (_obj(0, "Cup", x_post),): w["new,same"] / total,
        (o1,): w["new,clutter"] / total,
        (o2,): w["clutter,new"] / total,
        (): w["clutter,clutter"] / total,
    }
    got = _hyps(wm)
    assert got.keys() == expected.keys()
    for key, p in expected.items():
        assert got[key] == pytest.approx(p, abs=1e-12), key


def _existence(wm: WorldModel) -> dict[tuple, tuple[float, dict[int, float]]]:
    """mht: hypotheses keyed by their objects -> (probability, lineage -> existence)."""
    out = {}
    for h in wm.hypotheses(10**6):
        key = tuple(
            sorted(
                (o.track, o.cls, o.label, tuple(round(v, 9) for v in o.position)) for o in h.objects
            )
        )
        out[key] = (h.probability, {o.track: o.existence for o in h.objects})
    return out


def test_first_detection_mht_is_one_object_of_existence_b_over_b_plus_c() -> None:
    """mht: one child "new or clutter": one hypothesis holding an object whose existence
    is lambda_b / (lambda_b + lambda_c); clutter and birth both spread by 1/V (cancels)."""
    wm = _cup_world("mht")
    wm.ingest(det(0.0, "Cup", 1.0, 2.0))
    got = _existence(wm)
    assert list(got) == [(_obj(0, "Cup", (1.0, 2.0)),)]
    p, existence = got[(_obj(0, "Cup", (1.0, 2.0)),)]
    assert p == pytest.approx(1.0)
    assert existence[0] == pytest.approx(FN / (FC + FN), abs=1e-12)


def test_second_detection_mht() -> None:
    """mht: the first object's existence decays over dt: it may leave (rate mu) and the
    source that reported it scans again without reporting it (rate FE while inside the
    region, semwm.mhf.existence), then the second detection either updates it (weight r
    FE N(z; x, S)) or is new-or-clutter (weight (FC + FN) / V, a second object)."""
    from scipy.special import chdtri, ndtr

    z1, z2, dt, V = np.array([1.0, 2.0]), np.array([1.2, 1.9]), 2.0, 40.0
    wm = _cup_world("mht")
    wm.ingest(det(0.0, "Cup", *z1))
    wm.ingest(det(dt, "Cup", *z2, covariance=R_FULL.tolist()))
    P_pred = P0 * np.eye(2) + dt * QC * np.eye(2)
    x_post, _, y, S = _kalman(z1, P_pred, z2, R_FULL)
    # the spread counts up to the class's noise (growth while unseen is no exit)
    sd = math.sqrt(min(P_pred[0, 0], R))
    # the region widened by the class's noise at the gate's 1-D quantile (soft region)
    gate = wm.knowledge.world.gate_probability  # 1 here: no margin
    m = math.sqrt(chdtri(1, 1.0 - gate) * R) if gate < 1.0 else 0.0
    inside = (ndtr((10 + m - 1.0) / sd) - ndtr((0 - m - 1.0) / sd)) * (
        ndtr((4 + m - 2.0) / sd) - ndtr((0 - m - 2.0) / sd)
    )
    r0, mu = FN / (FC + FN), 0.01  # mu: the default leave_frequency
    r_left = r0 * math.exp(-mu * dt)  # it may have left: no evidence, no weight
    f = FE * inside  # the same source scans again where it reported the object: a miss
    stay = math.exp(-f * dt)
    r1 = r_left * stay / (1 - r_left + r_left * stay)
    dens = math.exp(-0.5 * y @ np.linalg.inv(S) @ y) / (2 * math.pi * math.sqrt(np.linalg.det(S)))
    w_same, w_new = r1 * FE * dens, (FC + FN) / V
    got = _existence(wm)
    o1, o2 = _obj(0, "Cup", z1), _obj(1, "Cup", z2)
    assert set(got) == {(_obj(0, "Cup", x_post),), (o1, o2)}
    p_same, e_same = got[(_obj(0, "Cup", x_post),)]
    p_two, e_two = got[(o1, o2)]
    assert p_same == pytest.approx(w_same / (w_same + w_new), abs=1e-12)
    assert p_two == pytest.approx(w_new / (w_same + w_new), abs=1e-12)
    assert e_same[0] == pytest.approx(1.0)
    assert e_two == pytest.approx({0: r1, 1: r0}, abs=1e-12)


# ---------------------------------------------------------------- class likelihood


def _taxonomy_world() -> WorldModel:
    return WorldModel(
        knowledge(
            [
                static_class("Table", f_existing=0.7, f_new=FN, r=R, p0=P0, qc=QC),
                static_class("Cup", f_existing=FE, f_new=FN, r=R, p0=P0, qc=QC),
                static_class("Can", f_existing=1.0, f_new=FN, r=R, p0=P0, qc=QC),
                static_class("CokeCan", is_a=["Can"], f_existing=2.0, f_new=FN, r=R, p0=P0, qc=QC),
            ],
            f_clutter=FC,
        )
    )


def test_cup_detection_never_updates_a_table() -> None:
    wm = _taxonomy_world()
    wm.ingest(det(0.0, "Table", 1.0, 1.0))
    wm.ingest(det(1.0, "Cup", 1.0, 1.0))
    got = _hyps(wm)
    # two parents x (clutter, new): no third child, the table never moves
    assert len(got) == 4
    for key in got:
        for lineage, cls, _, pos in key:
            assert (cls, pos) == (("Table", (1.0, 1.0)) if lineage == 0 else ("Cup", (1.0, 1.0)))
    # the Table's rate still counts in F (eq. 5-7: the sum of all frequencies of the parent)
    p_table = FN / (FC + FN)
    w_table_new = p_table * FN / (FC + FN + 0.7)
    w_table_clutter = p_table * FC / (FC + FN + 0.7)
    w_empty_new = (1 - p_table) * FN / (FC + FN)
    total = w_table_new + w_table_clutter + w_empty_new + (1 - p_table) * FC / (FC + FN)
    t = _obj(0, "Table", (1.0, 1.0))
    assert got[(t,)] == pytest.approx(w_table_clutter / total, abs=1e-12)


@pytest.mark.parametrize(
    ("first", "second", "result", "rate"),
    [
        ("CokeCan", "Can", "CokeCan", 2.0),  # a Can detection updates a CokeCan: stays CokeCan
        ("Can", "CokeCan", "CokeCan", 1.0),  # a CokeCan detection refines a Can object
        ("CokeCan", "CokeCan", "CokeCan", 2.0),
    ],
)
def test_taxonomy_update_and_refinement(first: str, second: str, result: str, rate: float) -> None:
    z1, z2 = np.array([1.0, 1.0]), np.array([1.1, 0.95])
    wm = _taxonomy_world()
    wm.ingest(det(0.0, first, *z1))
    wm.ingest(det(1.0, second, *z2))
    P_pred = (P0 + QC) * np.eye(2)
    x_post, P_post, _, _ = _kalman(z1, P_pred, z2, R * np.eye(2))
    delta = z2 - x_post
    lik = math.exp(-0.5 * delta @ delta / R)
    f_first = 2.0 if first == "CokeCan" else 1.0
    p1 = FN / (FC + FN)
    F1 = FC + FN + f_first
    w_same = p1 * rate / F1 * lik  # eq. (6): f_existing of the object's class
    total = w_same + p1 * (FN + FC) / F1 + (1 - p1)
    got = _hyps(wm)
    updated = (_obj(0, result, x_post),)
    assert updated in got
    assert got[updated] == pytest.approx(w_same / total, abs=1e-12)
    # after the refinement the object's rate in F (eq. 5-7) is its new class's: a third, far
    # detection; the clutter child of each parent keeps the ratio of the parents over F
    o1 = (_obj(0, first, z1),)
    ratio_before = got[updated] / got[o1]
    wm.ingest(det(2.0, "Cup", 8.0, 8.0))
    got = _hyps(wm)
    F_updated = FC + FN + {"CokeCan": 2.0, "Can": 1.0}[result]
    F_old = FC + FN + f_first
    assert got[updated] / got[o1] == pytest.approx(ratio_before * F_old / F_updated, rel=1e-12)


# ---------------------------------------------------------------- appearance relations (eq. 4)

F_PRES = 3.0


def _door_world(known=(), model: str = "paper") -> WorldModel:
    relation = AppearanceRelation(target="Door", max_distance=1.0, frequency=F_PRES)
    region = ((0.0, 10.0), (0.0, 4.0)) if model == "mht" else None
    return WorldModel(
        knowledge(
            [
                static_class("Door", f_existing=0.4, f_new=FN, r=R, p0=P0, qc=QC),
                static_class(
                    "Person", f_existing=FE, f_new=FN, r=R, p0=P0, qc=QC, appearance=[relation]
                ),
            ],
            f_clutter=FC,
            known=known,
            model=model,
            region=region,
        )
    )


@pytest.mark.parametrize(("x", "f_new"), [(0.5, F_PRES), (0.99, F_PRES), (3.0, FN)])
def test_person_near_known_door(x: float, f_new: float) -> None:
    wm = _door_world(known=[KnownObject(cls="Door", position=(0.0, 0.0))])
    wm.ingest(det(0.0, "Person", x, 0.0))
    assert _hyps(wm)[()] == pytest.approx(FC / (FC + f_new), abs=1e-12)


def test_person_near_known_door_mht() -> None:
    """mht: near a mapped door a new person is born at the relation's rate spread over its
    disc (eq. 4), so its existence is w_new / (w_new + w_clutter)."""
    wm = _door_world(known=[KnownObject(cls="Door", position=(0.0, 0.0))], model="mht")
    wm.ingest(det(0.0, "Person", 0.5, 0.0))
    w_new, w_cl = F_PRES / math.pi, FC / 40.0  # the relation's disc vs the region
    ((p, existence),) = _existence(wm).values()
    assert existence[0] == pytest.approx(w_new / (w_cl + w_new), abs=1e-12)


def test_person_near_tracked_door_in_one_hypothesis_only() -> None:
    wm = _door_world()
    wm.ingest(det(0.0, "Door", 0.0, 0.0))
    wm.ingest(det(1.0, "Person", 0.5, 0.0))
    p_door = FN / (FC + FN)
    F_door = FC + F_PRES + 0.4  # the door's own rate is in F; it cannot take a Person
    F_empty = FC + FN
    w = {
        "door,new": p_door * F_PRES / F_door,
        "door,clutter": p_door * FC / F_door,
        "empty,new": (1 - p_door) * FN / F_empty,
        "empty,clutter": (1 - p_door) * FC / F_empty,
    }
    total = sum(w.values())
    door, person = _obj(0, "Door", (0.0, 0.0)), _obj(1, "Person", (0.5, 0.0))
    got = _hyps(wm)
    assert got == pytest.approx(
        {
            (door, person): w["door,new"] / total,
            (door,): w["door,clutter"] / total,
            (person,): w["empty,new"] / total,
            (): w["empty,clutter"] / total,
        },
        abs=1e-12,
    )


def test_person_far_from_tracked_door_gets_base_rate() -> None:
    wm = _door_world()
    wm.ingest(det(0.0, "Door", 0.0, 0.0))
    wm.ingest(det(1.0, "Person", 2.0, 0.0))
    got = _hyps(wm)
    door, person = _obj(0, "Door", (0.0, 0.0)), _obj(1, "Person", (2.0, 0.0))
    assert got[(door, person)] / got[(door,)] == pytest.approx(FN / FC, rel=1e-12)


def test_person_near_door_updated_in_the_same_scan() -> None:
    """A scan sees the door and a person next to it: in the hypothesis where the door took
    the door detection, the door is still present, so the person's f_new is f_presence."""
    wm = _door_world()
    wm.ingest(det(0.0, "Door", 0.0, 0.0))
    wm.ingest([det(1.0, "Door", 0.1, 0.0), det(1.0, "Person", 0.5, 0.0)])
    got = _hyps(wm)
    # the door (lineage 0) took the second door detection: its position moved
    moved = [k for k in got if any(o[0] == 0 and o[3] != (0.0, 0.0) for o in k)]
    door = next(k for k in moved if len(k) == 1)
    with_person = next(k for k in moved if len(k) == 2)
    assert with_person[1][:2] == (2, "Person")
    # children of one parent: new / clutter = f_new / f_clutter, f_new = f_presence (eq. 4)
    assert got[with_person] / got[door] == pytest.approx(F_PRES / FC, rel=1e-9)


def test_scan_normaliser_counts_only_objects_open_to_the_detection() -> None:
    """One scan, two detections far apart, empty world. The object the first creates cannot
    take the second, so for the second F = f_clutter + f_new, as for the first: the four
    hypotheses factorise into (new or clutter) x (new or clutter)."""
    wm = _cup_world()
    wm.ingest([det(0.0, "Cup", 1.0, 1.0), det(0.0, "Cup", 8.0, 3.0)])
    pn, pc = FN / (FC + FN), FC / (FC + FN)
    o1, o2 = _obj(0, "Cup", (1.0, 1.0)), _obj(1, "Cup", (8.0, 3.0))
    assert _hyps(wm) == pytest.approx(
        {(o1, o2): pn * pn, (o1,): pn * pc, (o2,): pc * pn, (): pc * pc}, abs=1e-12
    )
