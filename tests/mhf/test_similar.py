"""Merging hypotheses that hold the same objects with near-identical estimates
(semwm.mhf.similar)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from semwm.mhf.similar import merge_similar, same_estimate
from semwm.mhf.state import Hypothesis, Track


def version(
    key: int, lineage: int, x: float, *, variance: float = 0.01, **changes: object
) -> Track:
    fields: dict[str, object] = dict(
        key=key,
        lineage=lineage,
        cls="Cup",
        label=None,
        x=np.array([[x, 0.0]]),
        P=np.array([np.eye(2) * variance]),
        mu=np.array([1.0]),
        time=1.0,
        last_seen=1.0,
        created=0.0,
        rate=2.0,
        class_probs=np.array([1.0, 0.0]),
    )
    fields.update(changes)
    return Track(**fields)  # type: ignore[arg-type]


def test_versions_a_tenth_of_a_standard_deviation_apart_are_one_estimate() -> None:
    a = version(1, 7, 0.0)
    assert same_estimate(a, version(2, 7, 0.009), 1.0, 1.0, 0.01)  # d^2 = 0.0081
    assert not same_estimate(a, version(2, 7, 0.02), 1.0, 1.0, 0.01)  # d^2 = 0.04
    assert not same_estimate(a, version(2, 7, 0.0, variance=0.02), 1.0, 1.0, 0.01)  # P
    assert not same_estimate(a, version(2, 7, 0.0, label="peer1"), 1.0, 1.0, 0.01)
    assert not same_estimate(a, version(2, 7, 0.0, cls="Mug"), 1.0, 1.0, 0.01)
    assert not same_estimate(
        a, version(2, 7, 0.0, class_probs=np.array([0.9, 0.1])), 1.0, 1.0, 0.01
    )
    assert not same_estimate(a, version(2, 7, 0.0), 1.0, 0.9, 0.01)  # existence


def test_twins_merge_into_the_more_probable_and_probabilities_add() -> None:
    tracks = {
        1: version(1, 7, 0.0),
        2: version(2, 7, 0.005),  # a twin of 1
        3: version(3, 7, 0.5),  # another estimate of the same object
        4: version(4, 8, 2.0),
    }
    p = [0.5, 0.3, 0.15, 0.05]
    hypotheses = (
        Hypothesis(math.log(p[0]), frozenset({1, 4}), 4.0),
        Hypothesis(math.log(p[1]), frozenset({2, 4}), 4.0),
        Hypothesis(math.log(p[2]), frozenset({3, 4}), 4.0),
        Hypothesis(math.log(p[3]), frozenset({1}), 2.0),  # other objects: not a twin
    )
    merged = merge_similar(hypotheses, tracks, {}, 0.01)
    assert [h.tracks for h in merged] == [
        frozenset({1, 4}),
        frozenset({3, 4}),
        frozenset({1}),
    ]
    assert [math.exp(h.log_weight) for h in merged] == pytest.approx([0.8, 0.15, 0.05])
    assert merge_similar(hypotheses, tracks, {}, 0.0) == hypotheses  # 0 turns it off


def test_the_batched_pairs_agree_with_the_pairwise_definition(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    from semwm.mhf import similar

    rng = np.random.default_rng(3)
    versions = [
        version(
            k,
            7 + k % 3,  # three lineages, compared in one batch: never paired across them
            float(rng.choice([0.0, 0.005, 0.02, 0.2])),
            variance=float(rng.choice([0.01, 0.0101, 0.02])),
            label=rng.choice([None, "peer1"], p=[0.8, 0.2]),
        )
        for k in range(30)
    ]
    existence = {k: float(rng.choice([1.0, 0.995, 0.9])) for k in range(30)}
    lineages = [[v for v in versions if v.lineage == lineage] for lineage in (7, 8, 9)]
    batched = similar._same_pairs(lineages, existence, 0.01)
    pairwise = {
        (a.key, b.key)
        for a in versions
        for b in versions
        if a.lineage == b.lineage
        and a.key != b.key
        and same_estimate(a, b, existence[a.key], existence[b.key], 0.01)
    }
    assert batched == pairwise
    assert len(pairwise) > 0  # some twins to find
    monkeypatch.setattr(similar, "_MAX_BATCH", 4)  # batches of whole groups
    assert similar._same_pairs(lineages, existence, 0.01) == pairwise
