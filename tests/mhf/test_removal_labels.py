"""Leaving objects (paper 002 III-E: P_max; paper 000 C3) and labels (paper 000 III-B)."""

from __future__ import annotations

import pytest

from semwm.world import WorldModel

from .kb import det, knowledge, static_class

P0, QC, P_MAX = 0.1, 0.05, 0.3
# P(t) = P0 + (t - t0) Qc exceeds P_MAX when t - t0 > (P_MAX - P0) / QC = 4 s
T_LEAVE = (P_MAX - P0) / QC


def _world(**cup) -> WorldModel:
    return WorldModel(
        knowledge(
            [
                static_class("Cup", f_existing=2.0, f_new=1.0, p0=P0, qc=QC, **cup),
                static_class("Table", f_existing=1.0, f_new=1.0),
            ],
            f_clutter=0.1,
        )
    )


def _lineages(wm: WorldModel) -> list[set[int]]:
    return [{o.track for o in h.objects} for h in wm.hypotheses(10**6)]


@pytest.mark.parametrize("t0", [0.0, 2.5])
def test_pmax_removal_time_at_queries(t0: float) -> None:
    wm = _world(p_max=P_MAX)
    wm.ingest(det(t0, "Cup", 1.0, 1.0))
    before = wm.world(t0 + T_LEAVE - 0.01).objects
    assert len(before) == 1
    assert before[0].covariance[0][0] == pytest.approx(P0 + (T_LEAVE - 0.01) * QC, abs=1e-12)
    assert wm.world(t0 + T_LEAVE + 0.01).objects == ()


@pytest.mark.parametrize("t0", [0.0, 2.5])
def test_pmax_removal_time_at_scans(t0: float) -> None:
    wm = _world(p_max=P_MAX)
    wm.ingest(det(t0, "Cup", 1.0, 1.0))
    wm.ingest(det(t0 + T_LEAVE - 0.01, "Table", 8.0, 8.0))  # a Table cannot update the Cup
    assert any(0 in s for s in _lineages(wm))
    wm.ingest(det(t0 + T_LEAVE + 0.01, "Table", 8.0, 8.0))
    assert not any(0 in s for s in _lineages(wm))
    assert all(t.cls == "Table" for t in wm._state.tracks.values())


def test_pmax_an_update_shrinks_the_covariance_and_postpones_removal() -> None:
    wm = _world(p_max=P_MAX)
    wm.ingest(det(0.0, "Cup", 1.0, 1.0))
    wm.ingest(det(3.0, "Cup", 1.0, 1.0))
    # updated at t=3 (R = 0.09): P+ = P- R / (P- + R) with P- = P0 + 3 Qc
    p_minus = P0 + 3 * QC
    p_plus = p_minus * 0.09 / (p_minus + 0.09)
    leave = 3.0 + (P_MAX - p_plus) / QC
    objects = wm.world(leave - 0.01).objects
    assert [o.covariance[0][0] for o in objects] == [pytest.approx(P_MAX - 0.01 * QC, abs=1e-12)]
    assert wm.world(leave + 0.01).objects == ()


def test_c3_removal_after_max_time_without_update() -> None:
    wm = _world(t_max=2.0)
    wm.ingest(det(0.0, "Cup", 1.0, 1.0))
    assert len(wm.world(1.99).objects) == 1
    assert wm.world(2.01).objects == ()
    wm.ingest(det(1.5, "Cup", 1.0, 1.0))  # seen again: the clock restarts
    assert len(wm.world(3.49).objects) == 1
    assert wm.world(3.51).objects == ()
    wm.ingest(det(3.49, "Table", 8.0, 8.0))
    assert any(t.cls == "Cup" for t in wm._state.tracks.values())
    wm.ingest(det(3.51, "Table", 8.0, 8.0))
    assert not any(t.cls == "Cup" for t in wm._state.tracks.values())


# ---------------------------------------------------------------- labels


def _robots() -> WorldModel:
    return WorldModel(knowledge([static_class("Robot", f_existing=2.0, f_new=1.0)], f_clutter=0.1))


def _labels(wm: WorldModel) -> list[dict[int, tuple[str | None, tuple[float, ...]]]]:
    return [{o.track: (o.label, o.position) for o in h.objects} for h in wm.hypotheses(10**6)]


def test_labeled_new_object_takes_the_label_unlabeled_has_none() -> None:
    wm = _robots()
    wm.ingest([det(0.0, "Robot", 0.0, 0.0, label="r1"), det(0.0, "Robot", 5.0, 0.0)])
    for h in _labels(wm):
        if 0 in h:
            assert h[0][0] == "r1"
        if 1 in h:
            assert h[1][0] is None


@pytest.mark.parametrize(
    ("first", "second", "expected"), [("r1", "r2", "r2"), ("r1", None, "r1"), (None, "r2", "r2")]
)
def test_label_of_an_updated_object(first, second, expected) -> None:
    wm = _robots()
    wm.ingest(det(0.0, "Robot", 0.0, 0.0, label=first))
    wm.ingest(det(1.0, "Robot", 0.1, 0.0, label=second))
    updated = [h[0] for h in _labels(wm) if 0 in h and h[0][1] != (0.0, 0.0)]
    assert len(updated) == 1
    assert updated[0][0] == expected
    kept = [h[0] for h in _labels(wm) if 0 in h and h[0][1] == (0.0, 0.0)]
    assert kept and all(label == first for label, _ in kept)


def test_two_objects_with_one_label_the_older_gives_it_up() -> None:
    wm = _robots()
    wm.ingest(det(0.0, "Robot", 0.0, 0.0, label="r1"))
    wm.ingest(det(1.0, "Robot", 5.0, 0.0, label="r1"))  # far: a new object holding r1
    both = [h for h in _labels(wm) if set(h) == {0, 1}]
    assert len(both) == 1
    assert both[0][0][0] is None and both[0][1][0] == "r1"
    # hypotheses with only the old object keep its label
    assert all(h[0][0] == "r1" for h in _labels(wm) if set(h) == {0})
    # the MAP (two objects) answers one object for the label
    objects = wm.world(label="r1").objects
    assert [o.position for o in objects] == [(5.0, 0.0)]
    assert len(wm.world().objects) == 2


def test_label_given_up_is_not_given_back_by_an_unlabeled_update() -> None:
    wm = _robots()
    wm.ingest(det(0.0, "Robot", 0.0, 0.0, label="r1"))
    wm.ingest(det(1.0, "Robot", 5.0, 0.0, label="r1"))
    wm.ingest(det(2.0, "Robot", 0.05, 0.0))  # updates the old object, unlabeled
    for h in _labels(wm):
        labels = [label for label, _ in h.values() if label is not None]
        assert len(labels) == len(set(labels)), h  # a label is held once per hypothesis
        if set(h) == {0, 1} and h[0][1] != (0.0, 0.0):
            assert h[0][0] is None and h[1][0] == "r1"


def test_object_that_gave_up_its_label_can_take_a_later_detection_of_the_scan() -> None:
    wm = _robots()
    wm.ingest(det(0.0, "Robot", 0.0, 0.0, label="r1"))
    # one scan: r1 reports itself far away (a new r1 object), then a detection at the old one
    wm.ingest([det(1.0, "Robot", 5.0, 0.0, label="r1"), det(1.0, "Robot", 0.1, 0.0)])
    found = [
        h
        for h in _labels(wm)
        if set(h) == {0, 1} and h[0][1] != (0.0, 0.0)  # old object updated by the 2nd detection
    ]
    assert len(found) == 1
    assert found[0][0][0] is None and found[0][1][0] == "r1"
