"""The scalar IMM: the combined estimate by hand, the update by hand, and its state's
checks. Sequences against FilterPy are in test_agreement.py, the transition
convention in test_transition.py."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import multivariate_normal

from semwm.filters.imm import IMMState, imm_combine, imm_update
from semwm.filters.kalman import GaussianState, kf_update


def test_combine_by_hand() -> None:
    """Scalar modes x = [0, 2], P = [1, 3], mu = [0.25, 0.75]: x̂ = 1.5,
    P̂ = 0.25 (1 + 1.5²) + 0.75 (3 + 0.5²) = 0.8125 + 2.4375 = 3.25."""
    state = IMMState(np.array([[0.0], [2.0]]), np.array([[[1.0]], [[3.0]]]), np.array([0.25, 0.75]))
    combined = imm_combine(state)
    np.testing.assert_allclose(combined.x, [1.5], rtol=0, atol=1e-15)
    np.testing.assert_allclose(combined.P, [[3.25]], rtol=0, atol=1e-15)


def test_update_by_hand() -> None:
    """Mode probabilities follow μ⁺_j ∝ μ_j N(z; H x_j, S_j) and the log-likelihood is
    log Σ_j μ_j N(z; H x_j, S_j), with densities from scipy."""
    x = np.array([[0.0, 0.0], [1.0, 0.5]])
    P = np.array([np.eye(2), 2.0 * np.eye(2)])
    mu = np.array([0.4, 0.6])
    H = np.array([[1.0, 0.0]])
    R = np.array([[0.5]])
    z = np.array([0.8])
    result = imm_update(IMMState(x, P, mu), z, H, R)
    lam = np.array([multivariate_normal.pdf(z, H @ x[j], H @ P[j] @ H.T + R) for j in range(2)])
    np.testing.assert_allclose(result.state.mu, mu * lam / (mu @ lam), rtol=1e-13)
    assert result.log_likelihood == pytest.approx(np.log(mu @ lam), rel=1e-13)
    np.testing.assert_allclose(result.mode_log_likelihoods, np.log(lam), rtol=1e-13)
    for j in range(2):
        expected = kf_update(GaussianState(x[j], P[j]), z, H, R).state
        np.testing.assert_array_equal(result.state.x[j], expected.x)
        np.testing.assert_array_equal(result.state.P[j], expected.P)


def test_far_measurement_does_not_underflow() -> None:
    """Mode likelihoods of e^-10000 would be 0 in linear space; in log space the
    probabilities stay defined and favour the nearer mode."""
    x = np.array([[0.0], [10.0]])
    P = np.array([[[1e-4]], [[1e-4]]])
    result = imm_update(IMMState(x, P, np.array([0.5, 0.5])), np.array([5.2]), [[1.0]], [[1e-4]])
    assert np.isfinite(result.log_likelihood)
    assert result.state.mu.sum() == pytest.approx(1.0)
    assert result.state.mu[1] == pytest.approx(1.0)


def test_from_gaussian_and_checks() -> None:
    state = IMMState.from_gaussian(GaussianState(np.arange(4.0), np.eye(4)), [0.3, 0.7])
    assert state.modes == 2 and state.x.shape == (2, 4) and state.P.shape == (2, 4, 4)
    np.testing.assert_array_equal(state.mode(1).x, np.arange(4.0))
    with pytest.raises(ValueError, match=r"mu must have shape \(2,\); found \(3,\)"):
        IMMState(state.x, state.P, np.ones(3) / 3)
    with pytest.raises(ValueError, match=r"P must have shape \(2, 4, 4\)"):
        IMMState(state.x, state.P[:, :3, :3], state.mu)
    with pytest.raises(ValueError, match="read-only"):
        state.mu[0] = 1.0
