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


def _merge_by_definition(
    hypotheses: tuple[Hypothesis, ...], tracks: dict[int, Track], max_distance: float
) -> list[tuple[frozenset[int], float]]:
    """The module's rule written out pairwise: each hypothesis (most probable first)
    joins the first earlier kept one with the same objects whose every version is its
    own or the same estimate; probabilities add."""
    kept: list[tuple[frozenset[int], dict[int, int]]] = []  # tracks, lineage -> key
    probability: list[float] = []
    for h in hypotheses:
        versions = {tracks[k].lineage: k for k in h.tracks}
        for i, (_, held) in enumerate(kept):
            if set(held) == set(versions) and all(
                held[lineage] == key
                or same_estimate(tracks[held[lineage]], tracks[key], 1.0, 1.0, max_distance)
                for lineage, key in versions.items()
            ):
                probability[i] += math.exp(h.log_weight)
                break
        else:
            kept.append((h.tracks, versions))
            probability.append(math.exp(h.log_weight))
    result = [(held_tracks, p) for (held_tracks, _), p in zip(kept, probability, strict=True)]
    return sorted(result, key=lambda e: -e[1])


@pytest.mark.parametrize("seed", range(6))
def test_merging_many_hypotheses_follows_the_definition(seed: int) -> None:
    rng = np.random.default_rng(seed)
    # 4 objects with 6 versions each, some twins of one another, some not; 0.0101 apart
    # with variances 0.01 and 0.0105 is a twin seen from one version, not the other
    tracks = {
        10 * lineage + v: version(
            10 * lineage + v,
            lineage,
            float(rng.choice([0.0, 0.004, 0.0101, 0.3])),
            variance=float(rng.choice([0.01, 0.0105])),
        )
        for lineage in range(4)
        for v in range(6)
    }
    hypotheses = []
    for _ in range(40):
        held = rng.choice(4, size=int(rng.integers(2, 5)), replace=False)
        keys = frozenset(int(10 * lineage + rng.integers(6)) for lineage in held)
        hypotheses.append(Hypothesis(float(rng.normal()), keys, 2.0))
    weights = np.array([h.log_weight for h in hypotheses])
    total = np.log(np.exp(weights).sum())
    ordered = tuple(
        Hypothesis(h.log_weight - total, h.tracks, h.rate)
        for h in sorted(hypotheses, key=lambda h: -h.log_weight)
    )
    merged = merge_similar(ordered, tracks, {}, 0.01)
    expected = _merge_by_definition(ordered, tracks, 0.01)
    assert [h.tracks for h in merged] == [tracks_ for tracks_, _ in expected]
    assert [math.exp(h.log_weight) for h in merged] == pytest.approx([p for _, p in expected])
    assert len(merged) < len(ordered)  # some twins merged
