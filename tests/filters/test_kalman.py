"""The scalar Kalman filter: a hand-computed step, FilterPy's intermediate values,
immutability and argument checks. Long random sequences are in test_agreement.py."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from semwm.filters.kalman import GaussianState, kf_predict, kf_update

from ._oracle import assert_close, filterpy_kf, make_scenario


def test_one_dimensional_step_by_hand() -> None:
    """x = 0, P = 1, F = 1, Q = 0.5 -> P⁻ = 1.5; z = 1, R = 0.5 -> S = 2, K = 0.75,
    x⁺ = 0.75, P⁺ = (1 - K)² P⁻ + K² R = 0.09375 + 0.28125 = 0.375."""
    prior = kf_predict(GaussianState(np.array([0.0]), np.array([[1.0]])), [[1.0]], [[0.5]])
    np.testing.assert_allclose(prior.P, [[1.5]], rtol=0, atol=1e-15)
    result = kf_update(prior, np.array([1.0]), [[1.0]], [[0.5]])
    np.testing.assert_allclose(result.y, [1.0], rtol=0, atol=1e-15)
    np.testing.assert_allclose(result.S, [[2.0]], rtol=0, atol=1e-15)
    np.testing.assert_allclose(result.state.x, [0.75], rtol=0, atol=1e-15)
    np.testing.assert_allclose(result.state.P, [[0.375]], rtol=0, atol=1e-15)
    expected = -0.5 * (1.0 / 2.0 + np.log(2.0) + np.log(2.0 * np.pi))
    assert result.log_likelihood == pytest.approx(expected, rel=1e-14)


def test_two_dimensional_constant_velocity_by_hand() -> None:
    """Position and velocity, dt = 1, no process noise, measurement of the position."""
    state = GaussianState(np.array([0.0, 1.0]), np.diag([1.0, 1.0]))
    prior = kf_predict(state, [[1.0, 1.0], [0.0, 1.0]], np.zeros((2, 2)))
    np.testing.assert_allclose(prior.x, [1.0, 1.0], rtol=0, atol=1e-15)
    np.testing.assert_allclose(prior.P, [[2.0, 1.0], [1.0, 1.0]], rtol=0, atol=1e-15)
    result = kf_update(prior, np.array([3.0]), [[1.0, 0.0]], [[2.0]])
    # S = 4, K = [0.5, 0.25], y = 2
    np.testing.assert_allclose(result.state.x, [2.0, 1.5], rtol=0, atol=1e-15)
    # P⁺ = P⁻ - K S Kᵀ = [[2 - 1, 1 - 0.5], [1 - 0.5, 1 - 0.25]]
    np.testing.assert_allclose(result.state.P, [[1.0, 0.5], [0.5, 0.75]], rtol=0, atol=1e-15)


@pytest.mark.parametrize("d", [2, 3])
def test_innovation_and_its_covariance_match_filterpy(d: int) -> None:
    s = make_scenario(np.random.default_rng([5, d]), "kf1", d)
    kf = filterpy_kf(s, s.x0, s.P0)
    dt, _ = s.steps[0]
    F, Q = s.models(dt)
    kf.F, kf.Q = F[0], Q[0]
    kf.predict()
    z = s.z0 + 0.3
    kf.update(z)
    result = kf_update(kf_predict(GaussianState(s.x0, s.P0), F[0], Q[0]), z, s.H, s.R)
    assert_close(result.y, kf.y)
    assert_close(result.S, kf.S)
    assert result.log_likelihood == pytest.approx(kf.log_likelihood, rel=1e-12)


def test_state_is_an_immutable_value() -> None:
    x = np.array([1.0, 2.0])
    P = np.eye(2)
    state = GaussianState(x, P)
    x[0] = 99.0
    P[0, 0] = 99.0
    assert state.x[0] == 1.0 and state.P[0, 0] == 1.0
    with pytest.raises(ValueError, match="read-only"):
        state.x[0] = 5.0
    with pytest.raises(dataclasses.FrozenInstanceError):
        state.x = np.zeros(2)  # type: ignore[misc]
    predicted = kf_predict(state, np.eye(2), np.eye(2))
    assert predicted is not state
    np.testing.assert_array_equal(state.P, np.eye(2))


def test_wrong_shapes_name_the_argument() -> None:
    state = GaussianState(np.zeros(2), np.eye(2))
    with pytest.raises(ValueError, match=r"P must have shape \(2, 2\); found \(3, 3\)"):
        GaussianState(np.zeros(2), np.eye(3))
    with pytest.raises(ValueError, match=r"F must have shape \(2, 2\)"):
        kf_predict(state, np.eye(3), np.eye(2))
    with pytest.raises(ValueError, match=r"H must have shape \(1, 2\); found \(2, 2\)"):
        kf_update(state, np.zeros(1), np.eye(2), np.eye(1))
    with pytest.raises(ValueError, match=r"R must have shape \(1, 1\)"):
        kf_update(state, np.zeros(1), [[1.0, 0.0]], np.eye(2))
