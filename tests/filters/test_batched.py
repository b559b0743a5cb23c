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


def test_zeroth_order_kalman_prediction_equals_the_general_equations() -> None:
    """A one-mode zeroth-order filter predicts without matrix products (x- = x,
    P- = P + Q(dt)); the result is exactly the general IMM prediction's with
    F = I, and objects with dt <= 0 are left as they are."""
    for d in (2, 3):
        s = make_scenario(np.random.default_rng(30 + d), "kf0", d)
        cf = class_filter(s)
        assert cf._random_walk is not None
        rng = np.random.default_rng(31)
        x, P, mu = cf.initial_states(rng.normal(size=(4, d)))
        x, P, mu, _ = cf.update(x, P, mu, rng.normal(size=(4, d)), np.stack([s.R] * 4))
        dt = np.array([0.0, 0.3, -1.0, 0.1])
        x2, P2, mu2 = cf.predict(x, P, mu, dt)
        moving = dt > 0.0
        F, Q = cf.models(dt[moving])
        x_ref, P_ref, mu_ref = batched.predict(
            x[moving], P[moving], mu[moving], F, Q, cf.transitions(dt[moving])
        )
        np.testing.assert_array_equal(x2[moving], x_ref)
        np.testing.assert_array_equal(P2[moving], P_ref)
        np.testing.assert_array_equal(mu2[moving], mu_ref)
        np.testing.assert_array_equal(x2[~moving], x[~moving])
        np.testing.assert_array_equal(P2[~moving], P[~moving])
    imm = class_filter(make_scenario(np.random.default_rng(33), "imm", 2))
    assert imm._random_walk is None
    first = class_filter(make_scenario(np.random.default_rng(34), "kf1", 2))
    assert first._random_walk is None
