"""Properties of the MHF and the world model: normalisation, pruning keeps the MAP, stable
ids, no underflow, atomic rejection of bad input, the reorder window, structural sharing."""

from __future__ import annotations

import itertools
import math
from typing import Any

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from semwm.detection import DetectionError, OutOfOrderError
from semwm.mhf.filter import MultipleHypothesisFilter
from semwm.mhf.prune import TIE
from semwm.world import WorldModel

from .kb import det, knowledge, static_class

SETTINGS = settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])


def _classes(**kw: Any) -> list:
    return [
        static_class("Can", f_existing=1.0, f_new=0.3, **kw),
        static_class("CokeCan", is_a=["Can"], f_existing=1.5, f_new=0.2, **kw),
        static_class("Cup", f_existing=0.8, f_new=0.3, **kw),
    ]


detections = st.lists(
    st.tuples(
        st.sampled_from(["Can", "CokeCan", "Cup"]),
        st.floats(0.0, 3.0),
        st.floats(0.0, 3.0),
        st.integers(0, 2),  # time step
        st.sampled_from(["a", "b"]),
    ),
    min_size=1,
    max_size=10,
)


def _batches(items, distinct: int = 0) -> list[list[dict[str, Any]]]:
    t = 0.0
    out = []
    for cls, x, y, step, source in items:
        t += 0.5 * (step + distinct)
        out.append([det(t, cls, x, y, source=source)])
    return out


@SETTINGS
@given(
    items=detections, ratio=st.sampled_from([0.0, 0.01, 0.2]), max_h=st.sampled_from([3, 50, 400])
)
def test_probabilities_sum_to_one_after_every_ingest(items, ratio, max_h) -> None:
    wm = WorldModel(knowledge(_classes(), ratio=ratio, max_hypotheses=max_h, gate=0.9999))
    for batch in _batches(items):
        wm.ingest(batch)
        probs = [h.probability for h in wm.hypotheses(10**6)]
        assert len(probs) <= max_h
        assert all(math.isfinite(p) and p > 0 for p in probs)
        assert math.fsum(probs) == pytest.approx(1.0, abs=1e-9)
        # most probable first; hypotheses within TIE of each other are a tie, ordered
        # by their objects (semwm.mhf.prune.ties_in_order)
        tie = math.exp(TIE) * (1 + 1e-12)
        assert all(b <= a * tie for a, b in itertools.pairwise(probs))
        if ratio > 0:
            assert min(probs) >= ratio * max(probs) * math.exp(-TIE) * (1 - 1e-12)


@SETTINGS
@given(
    items=detections,
    last=detections,
    ratio=st.sampled_from([0.01, 0.3]),
    max_h=st.sampled_from([1, 2, 1000]),
)
def test_pruning_keeps_the_map(items, last, ratio, max_h) -> None:
    """From the same state, one detection with pruning and without: the same MAP."""
    full = MultipleHypothesisFilter(knowledge(_classes()))
    pruned = MultipleHypothesisFilter(knowledge(_classes(), ratio=ratio, max_hypotheses=max_h))
    wm = WorldModel(knowledge(_classes(), ratio=1e-4, max_hypotheses=300))
    for batch in _batches(items):
        wm.ingest(batch)
    state = wm._state
    cls, x, y, step, _ = last[0]
    time = (state.time or 0.0) + 0.5 * step
    (m,) = wm.validate(det(time, cls, x, y))
    a = full.process_scan(state, [m])
    b = pruned.process_scan(state, [m])
    if len(a.hypotheses) > 1 and a.hypotheses[0].log_weight - a.hypotheses[1].log_weight < 1e-9:
        return  # a tie: either is the MAP
    assert b.hypotheses[0].tracks == a.hypotheses[0].tracks
    best_a = sorted((a.tracks[k].lineage, a.tracks[k].cls) for k in a.hypotheses[0].tracks)
    best_b = sorted((b.tracks[k].lineage, b.tracks[k].cls) for k in b.hypotheses[0].tracks)
    assert best_a == best_b


# ---------------------------------------------------------------- ids


def _id_world() -> WorldModel:
    return WorldModel(
        knowledge(
            [static_class("Cup", f_existing=2.0, f_new=0.5, qc=0.001)],
            f_clutter=0.05,
            gate=0.9999,
            ratio=0.01,
            max_hypotheses=200,
        )
    )


@SETTINGS
@given(
    truth=st.lists(st.integers(0, 8), min_size=1, max_size=4, unique=True),
    seq=st.lists(st.tuples(st.integers(0, 3), st.booleans()), min_size=2, max_size=25),
    seed=st.integers(0, 1000),
)
def test_ids_belong_to_one_object(truth, seq, seed) -> None:
    """Well-separated objects (10 m apart): each id always names the same true object,
    an object seen repeatedly keeps its id, and clutter far away changes no id."""
    rng = np.random.default_rng(seed)
    positions = [np.array([10.0 * (i % 3), 10.0 * (i // 3)]) for i in truth]
    wm = _id_world()
    owner: dict[int, int] = {}  # id -> true object
    current: dict[int, int] = {}  # true object -> its id at the last step
    for t, (which, clutter) in enumerate(seq):
        if clutter:  # far from every object
            z = np.array([100.0 + 10 * t, -100.0])
        else:
            z = positions[which % len(positions)] + rng.normal(0, 0.05, 2)
        before = {o.id: o.position for o in wm.world().objects}
        wm.ingest(det(float(t), "Cup", *z))
        objects = wm.world().objects
        assert len({o.id for o in objects}) == len(objects)
        for o in objects:
            d = [np.linalg.norm(np.asarray(o.position) - p) for p in positions]
            nearest = int(np.argmin(d))
            if d[nearest] > 1.0:
                continue  # the clutter object
            assert owner.setdefault(o.id, nearest) == nearest, "an id moved to another object"
            if nearest in current and current[nearest] in before:
                assert o.id == current[nearest], "an object seen again changed its id"
            current[nearest] = o.id
        if clutter:  # objects still in the world keep their ids (they did not move)
            for o in objects:
                if o.position in before.values():
                    assert before.get(o.id) == o.position, "clutter elsewhere changed an id"


def test_an_object_seen_repeatedly_keeps_its_id() -> None:
    wm = _id_world()
    ids = []
    for t in range(20):
        wm.ingest(det(float(t), "Cup", 1.0 + 0.01 * (t % 3), 2.0))
        ids.append([o.id for o in wm.world().objects])
    assert ids[0] == [1]
    assert all(i == [1] for i in ids)


# ---------------------------------------------------------------- underflow


def _two_hundred(model: str, f_clutter: float) -> None:
    region = ((-10.0, 200.0), (-10.0, 100.0)) if model == "mht" else None
    kb = knowledge(
        [static_class("Cup", f_existing=5.0, f_new=1.0)],
        f_clutter=f_clutter,
        ratio=0.01,
        max_hypotheses=1000,
        gate=0.9999,
        model=model,
        region=region,
    )
    wm = WorldModel(kb)
    grid = [(10.0 * (i % 20), 10.0 * (i // 20)) for i in range(200)]
    wm.ingest([det(0.0, "Cup", x, y, source="r") for x, y in grid])
    probs = [h.probability for h in wm.hypotheses(100)]  # mht factorises: 2^200 in all
    assert all(math.isfinite(p) and p > 0 for p in probs)
    assert math.fsum(probs) <= 1.0 + 1e-9
    assert math.isfinite(wm._state.best.log_weight)
    objects = wm.world().objects
    assert len(objects) == 200
    assert sorted(o.position for o in objects) == sorted(grid)
    assert len({o.id for o in objects}) == 200
    # a second scan of the same 200: every object is updated, none added
    wm.ingest([det(1.0, "Cup", x + 0.01, y, source="r") for x, y in grid])
    objects2 = wm.world().objects
    assert len(objects2) == 200
    assert {o.id for o in objects2} == {o.id for o in objects}
    assert all(o.last_seen == 1.0 for o in objects2)


@pytest.mark.parametrize(("model", "f_clutter"), [("mht", 0.1), ("paper", 1e-5)])
def test_two_hundred_objects_in_one_scan(model: str, f_clutter: float) -> None:
    """The C++ reference silently creates nothing past ~53 detections in a scan."""
    _two_hundred(model, f_clutter)


def test_two_hundred_objects_in_one_scan_paper_model() -> None:
    _two_hundred("paper", 0.1)


# ---------------------------------------------------------------- bad input


def _snapshot(wm: WorldModel):
    return wm.hypotheses(100), wm.world(), wm.latest_time, wm.track_count


def _busy_world(window: float = 0.0) -> WorldModel:
    wm = WorldModel(knowledge(_classes(), gate=0.9999), reorder_window=window)
    wm.ingest([det(0.0, "Can", 1.0, 1.0), det(0.0, "Cup", 2.0, 2.0)])
    wm.ingest(det(1.0, "CokeCan", 1.05, 1.0))
    return wm


GOOD = det(2.0, "Cup", 2.0, 2.0)


@pytest.mark.parametrize(
    ("bad", "path"),
    [
        (det(2.0, "Mug", 1.0, 1.0), (1, "class")),
        ({"time": 2.0, "class": "Cup", "position": [1.0, 1.0, 1.0]}, (1, "position")),
        ({"time": 2.0, "class": "Cup", "position": [1.0]}, (1, "position")),
        ({"time": 2.0, "class": "Cup", "position": [float("nan"), 1.0]}, (1, "position", 0)),
        ({"time": float("nan"), "class": "Cup", "position": [1.0, 1.0]}, (1, "time")),
        (det(2.0, "Cup", 1.0, 1.0, covariance=[[1.0, 0.0], [0.0, -1.0]]), (1, "covariance")),
        (det(2.0, "Cup", 1.0, 1.0, covariance=[[1.0, 0.5], [0.0, 1.0]]), (1, "covariance")),
        (det(2.0, "Cup", 1.0, 1.0, covariance=[[1.0, 0.0, 0.0]]), (1, "covariance")),
        (det(2.0, "Cup", 1.0, 1.0, detector="lidar"), (1, "detector")),
    ],
)
def test_bad_detection_changes_nothing(bad, path) -> None:
    wm = _busy_world()
    before = _snapshot(wm)
    with pytest.raises(DetectionError) as info:
        wm.ingest([GOOD, bad])
    assert [p.path for p in info.value.problems] == [path]
    assert _snapshot(wm) == before
    wm.ingest(GOOD)  # and the model still works
    assert wm.latest_time == 2.0


def test_out_of_order_beyond_the_window_changes_nothing() -> None:
    wm = _busy_world(window=0.5)
    before = _snapshot(wm)
    with pytest.raises(OutOfOrderError):
        wm.ingest([det(1.2, "Cup", 5.0, 5.0), det(0.4, "Cup", 5.0, 5.0)])
    assert _snapshot(wm) == before


def _content(wm: WorldModel):
    hyps = sorted(
        (
            round(h.probability, 12),
            sorted((o.cls, o.label, tuple(round(v, 12) for v in o.position)) for o in h.objects),
        )
        for h in wm.hypotheses(10**6)
    )
    world = sorted((o.cls, o.position, o.covariance, o.last_seen) for o in wm.world().objects)
    return hyps, world


@SETTINGS
@given(items=detections, late=st.integers(0, 9), delay=st.integers(1, 3))
def test_a_late_detection_within_the_window_gives_the_in_order_world(items, late, delay) -> None:
    batches = _batches(items, distinct=1)  # one scan per time: the order within a scan counts
    late %= len(batches)
    kb = knowledge(_classes(), gate=0.9999, ratio=1e-3, max_hypotheses=200)
    in_order = WorldModel(kb, reorder_window=1.5)
    for b in batches:
        in_order.ingest(b)
    shuffled = WorldModel(kb, reorder_window=1.5)
    order = list(range(len(batches)))
    # the late detection arrives `delay` batches later, and within the window
    held = order.pop(late)
    pos = min(late + delay, len(order))
    while pos > late and batches[order[pos - 1]][0]["time"] > batches[held][0]["time"] + 1.5:
        pos -= 1
    order.insert(pos, held)
    for i in order:
        shuffled.ingest(batches[i])
    assert _content(shuffled) == _content(in_order)


# ---------------------------------------------------------------- structural sharing


def test_object_versions_are_shared_and_none_leak() -> None:
    wm = WorldModel(knowledge(_classes(), ratio=0.0, max_hypotheses=5000, gate=0.9999))
    rng = np.random.default_rng(3)
    sites = rng.uniform(0, 20, size=(6, 2))
    for t in range(14):
        site = sites[t % len(sites)]
        wm.ingest(det(float(t), "Cup", *(site + rng.normal(0, 0.05, 2))))
    state = wm._state
    hyps = state.hypotheses
    assert len(hyps) > 200
    referenced = set().union(*(h.tracks for h in hyps))
    assert referenced == set(state.tracks)  # every stored version is held, none missing
    total = sum(len(h.tracks) for h in hyps)
    assert wm.track_count == len(state.tracks)
    assert len(state.tracks) * 20 < total, (len(state.tracks), total)
