"""Batched helpers checked by hand: the Mahalanobis distance, and the ClassFilter's
handling of per-object time steps on fixed examples (random ones are in
test_properties.py)."""

from __future__ import annotations

import numpy as np

from semwm.filters import batched

from ._oracle import class_filter, make_scenario


def test_mahalanobis_squared_by_hand() -> None:
    """r = [1, 2], C = [[2, 1], [1, 2]]: C⁻¹ = [[2, -1], [-1, 2]] / 3, C⁻¹ r = [0, 1],
    rᵀ C⁻¹ r = 2. 3D: r = [1, 0, -1], C = diag(1, 4, 0.25): 1 + 0 + 4 = 5."""
    r2 = np.array([1.0, 2.0])
    C2 = np.array([[2.0, 1.0], [1.0, 2.0]])
    np.testing.assert_allclose(batched.mahalanobis_squared(r2, C2), 2.0, rtol=1e-15)
    r3 = np.array([1.0, 0.0, -1.0])
    C3 = np.diag([1.0, 4.0, 0.25])
    np.testing.assert_allclose(batched.mahalanobis_squared(r3, C3), 5.0, rtol=1e-15)


def test_mahalanobis_squared_stacked() -> None:
    """Stacked residuals (2, 3, d) and covariances give one distance each."""
    rng = np.random.default_rng(3)
    r = rng.normal(size=(2, 3, 2))
    A = rng.normal(size=(2, 3, 2, 2))
    C = A @ np.swapaxes(A, -1, -2) + np.eye(2)
    got = batched.mahalanobis_squared(r, C)
    assert got.shape == (2, 3)
    for i in range(2):
        for j in range(3):
            expected = r[i, j] @ np.linalg.inv(C[i, j]) @ r[i, j]
            np.testing.assert_allclose(got[i, j], expected, rtol=1e-12)


def test_class_filter_dt_zero_and_negative_change_nothing() -> None:
    """IMM objects with dt = 0 or dt < 0 keep their means, covariances and mode
    probabilities exactly (no mixing either); the others are predicted."""
    s = make_scenario(np.random.default_rng(21), "imm", 2)
    cf = class_filter(s)
    rng = np.random.default_rng(22)
    x, P, mu = cf.initial_states(rng.normal(size=(4, 2)))
    x, P, mu, _ = cf.update(x, P, mu, rng.normal(size=(4, 2)), np.stack([s.R] * 4))
    dt = np.array([0.0, 0.3, -1.0, 0.1])
    x2, P2, mu2 = cf.predict(x, P, mu, dt)
    for i in (0, 2):
        np.testing.assert_array_equal(x2[i], x[i])
        np.testing.assert_array_equal(P2[i], P[i])
        np.testing.assert_array_equal(mu2[i], mu[i])
    np.testing.assert_allclose(mu2[1], mu[1] @ s.T, rtol=1e-14)
    assert not np.allclose(P2[1], P[1])
