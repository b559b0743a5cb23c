"""Candidate pairs from a k-d tree (semwm.mhf.nearby) are what the dense tests find, in
their order, and the worlds are the same whichever way the pairs are found."""

from __future__ import annotations

import numpy as np
import pytest

from semwm.mhf import nearby

from .worlds import scenario_worlds as _worlds


def test_within_finds_every_pair_in_the_dense_order() -> None:
    rng = np.random.default_rng(3)
    points = rng.uniform(0.0, 5.0, size=(300, 2))
    centres = rng.uniform(0.0, 5.0, size=(200, 2))
    radius = rng.uniform(0.0, 0.6, size=200)
    pp, cc = nearby.within(points, centres, radius)
    distance = np.linalg.norm(points[:, None, :] - centres[None, :, :], axis=-1)
    exact = distance <= radius[None, :]
    found = np.zeros_like(exact)
    found[pp, cc] = True
    assert np.all(found >= exact)  # a superset: nothing within the radius is missed
    assert np.all(distance[pp, cc] <= radius[cc] * (1 + 1e-6) + 1e-9)  # and barely more
    keep = distance[pp, cc] <= radius[cc]
    dense_p, dense_c = np.nonzero(exact)
    assert np.array_equal(pp[keep], dense_p) and np.array_equal(cc[keep], dense_c)


def test_close_pairs_are_each_pair_once_in_the_dense_order() -> None:
    rng = np.random.default_rng(4)
    points = rng.uniform(0.0, 3.0, size=(250, 3))
    radius = rng.uniform(0.0, 0.5, size=250)
    aa, bb = nearby.close_pairs(points, radius)
    distance = np.linalg.norm(points[:, None, :] - points[None, :, :], axis=-1)
    exact = distance <= np.maximum(radius[:, None], radius[None, :])
    dense_a, dense_b = np.nonzero(np.triu(exact, k=1))
    keep = distance[aa, bb] <= np.maximum(radius[aa], radius[bb])
    assert np.all(aa < bb)
    assert np.array_equal(aa[keep], dense_a) and np.array_equal(bb[keep], dense_b)
    assert nearby.close_pairs(points[:1], radius[:1])[0].size == 0
    assert not nearby.usable(np.array([[0.0, np.inf]]))


@pytest.mark.parametrize(
    ("name", "seed", "sizes"),
    [
        ("grid", 0, {"n_objects": 120, "duration": 0.6}),
        ("sim1", 5, {}),
        ("robocup", 9, {"duration": 0.6}),
    ],
)
def test_the_tree_changes_no_world(
    monkeypatch: pytest.MonkeyPatch, name: str, seed: int, sizes: dict[str, float]
) -> None:
    # the k-d tree is the Python engine's (the Rust core gates its pairs itself)
    monkeypatch.setenv("SEMWM_ENGINE", "python")
    calls = []
    within = nearby.within

    def counted(*args: object) -> object:
        calls.append(1)
        return within(*args)  # type: ignore[arg-type]

    monkeypatch.setattr(nearby, "within", counted)
    monkeypatch.setattr(nearby, "DENSE_PAIRS", 0)  # the tree wherever it may be used
    with_tree = _worlds(name, seed, **sizes)
    assert calls  # it was used
    monkeypatch.setattr(nearby, "DENSE_PAIRS", 10**12)  # every pair, densely
    assert _worlds(name, seed, **sizes) == with_tree
