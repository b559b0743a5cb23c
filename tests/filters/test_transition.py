"""The IMM transition convention: ``T[i, j] = P(mode j at k | mode i at k-1)``, rows sum
to 1, so a prediction moves the mode probabilities to the row vector ``mu @ T``.

Checked with hand-computed values on the scalar IMM, the batched IMM, the
factory-built ClassFilter and FilterPy's IMMEstimator (whose code follows this
convention although its docstring says otherwise).
"""

from __future__ import annotations

import numpy as np
import pytest

from semwm.filters import batched
from semwm.filters.imm import IMMState, imm_mix, imm_predict
from semwm.filters.kalman import GaussianState

from ._oracle import FloatArray, assert_close, class_filter, filterpy_imm, make_scenario

D = 2
N_STATE = 4
ASYMMETRIC = np.array([[0.9, 0.1], [0.4, 0.6]])

# (T, mu before, mu after), every "after" computed by hand:
CASES = [
    # T = I: nothing switches, probabilities stay.
    (np.eye(2), [0.3, 0.7], [0.3, 0.7]),
    # Certainly in mode 0: the next mode is distributed as row 0 of T.
    (ASYMMETRIC, [1.0, 0.0], [0.9, 0.1]),
    # Certainly in mode 1: row 1.
    (ASYMMETRIC, [0.0, 1.0], [0.4, 0.6]),
    # 0.2 * 0.9 + 0.8 * 0.4 = 0.5,  0.2 * 0.1 + 0.8 * 0.6 = 0.5
    (ASYMMETRIC, [0.2, 0.8], [0.5, 0.5]),
    # 0.5 * 0.9 + 0.5 * 0.4 = 0.65, 0.5 * 0.1 + 0.5 * 0.6 = 0.35
    (ASYMMETRIC, [0.5, 0.5], [0.65, 0.35]),
    # The stationary distribution of ASYMMETRIC (0.8 = 0.8 * 0.9 + 0.2 * 0.4) is kept.
    (ASYMMETRIC, [0.8, 0.2], [0.8, 0.2]),
    # Three modes, a cyclic shift 0 -> 1 -> 2 -> 0.
    (np.roll(np.eye(3), 1, axis=1), [0.5, 0.3, 0.2], [0.2, 0.5, 0.3]),
]


def _models(M: int, dt: float = 0.1) -> tuple[FloatArray, FloatArray]:
    F = np.kron(np.array([[1.0, dt], [0.0, 1.0]]), np.eye(D))
    return np.stack([F] * M), np.stack([0.01 * np.eye(N_STATE)] * M)


def _distinct_modes(M: int) -> IMMState:
    """Modes with different means and covariances, so that mixing shows."""
    x = np.arange(M * N_STATE, dtype=float).reshape(M, N_STATE)
    P = np.stack([(j + 1.0) * np.eye(N_STATE) for j in range(M)])
    return IMMState(x, P, np.full(M, 1.0 / M))


@pytest.mark.parametrize(("T", "mu", "expected"), CASES)
def test_scalar_predict_moves_mu_as_mu_times_T(
    T: FloatArray, mu: list[float], expected: list[float]
) -> None:
    M = len(mu)
    base = _distinct_modes(M)
    state = IMMState(base.x, base.P, np.array(mu))
    F, Q = _models(M)
    predicted = imm_predict(state, F, Q, T)
    np.testing.assert_allclose(predicted.mu, expected, rtol=0, atol=1e-15)


@pytest.mark.parametrize(("T", "mu", "expected"), CASES)
def test_batched_predict_moves_mu_as_mu_times_T(
    T: FloatArray, mu: list[float], expected: list[float]
) -> None:
    M = len(mu)
    base = _distinct_modes(M)
    F, Q = _models(M)
    # A zero in mu @ T (an unreachable mode) is the subject of
    # test_batched_mixing_with_an_unreachable_mode; here only mu is checked.
    with np.errstate(invalid="ignore", divide="ignore"):
        _, _, mu_pred = batched.predict(
            base.x[None], base.P[None], np.array([mu]), F[None], Q[None], T
        )
    np.testing.assert_allclose(mu_pred[0], expected, rtol=0, atol=1e-15)


def test_identity_transition_does_not_mix() -> None:
    """With T = I each mode starts its prediction from its own estimate."""
    state = IMMState(_distinct_modes(2).x, _distinct_modes(2).P, np.array([0.3, 0.7]))
    mixed = imm_mix(state, np.eye(2))
    np.testing.assert_allclose(mixed.x, state.x, rtol=0, atol=1e-15)
    np.testing.assert_allclose(mixed.P, state.P, rtol=0, atol=1e-15)
    x0, P0, _ = batched.imm_mix(state.x[None], state.P[None], state.mu[None], np.eye(2))
    np.testing.assert_allclose(x0[0], state.x, rtol=0, atol=1e-15)
    np.testing.assert_allclose(P0[0], state.P, rtol=0, atol=1e-15)


def test_mixing_weights_by_hand() -> None:
    """mu = [0.2, 0.8], T = ASYMMETRIC: c̄ = [0.5, 0.5], ω_00 = 0.2 * 0.9 / 0.5 = 0.36,
    ω_10 = 0.64, ω_01 = 0.2 * 0.1 / 0.5 = 0.04, ω_11 = 0.96. With scalar modes x = [0, 1]
    and P = [1, 2]: x⁰ = [0.64, 0.96], P⁰_0 = 0.36 (1 + 0.64²) + 0.64 (2 + 0.36²)."""
    state = IMMState(np.array([[0.0], [1.0]]), np.array([[[1.0]], [[2.0]]]), np.array([0.2, 0.8]))
    mixed = imm_mix(state, ASYMMETRIC)
    np.testing.assert_allclose(mixed.mu, [0.5, 0.5], rtol=0, atol=1e-15)
    np.testing.assert_allclose(mixed.x[:, 0], [0.64, 0.96], rtol=0, atol=1e-15)
    P00 = 0.36 * (1 + 0.64**2) + 0.64 * (2 + 0.36**2)
    P01 = 0.04 * (1 + 0.96**2) + 0.96 * (2 + 0.04**2)
    np.testing.assert_allclose(mixed.P[:, 0, 0], [P00, P01], rtol=1e-14, atol=0)
    x0, P0, _ = batched.imm_mix(state.x[None], state.P[None], state.mu[None], ASYMMETRIC)
    np.testing.assert_allclose(x0[0, :, 0], [0.64, 0.96], rtol=0, atol=1e-15)
    np.testing.assert_allclose(P0[0, :, 0, 0], [P00, P01], rtol=1e-14, atol=0)


def test_convention_matches_filterpy_and_class_filter() -> None:
    """The same asymmetric T in FilterPy's IMMEstimator, the scalar IMM, the batched IMM
    and the factory-built ClassFilter gives the same predicted probabilities, and they
    are mu @ T (not mu @ T.T, which would not even sum to one here)."""
    s = make_scenario(np.random.default_rng(11), "imm", D)
    T = ASYMMETRIC
    mu0 = np.array([0.2, 0.8])
    s = type(s)(**{**s.__dict__, "T": T, "mu0": mu0})
    dt = 0.25
    F, Q = s.models(dt)

    imm = filterpy_imm(s)
    for j, f in enumerate(imm.filters):
        f.F, f.Q = F[j], Q[j]
    imm.predict()
    np.testing.assert_allclose(imm.cbar, [0.5, 0.5], rtol=0, atol=1e-15)
    assert not np.isclose((mu0 @ T.T).sum(), 1.0)

    scalar = imm_predict(IMMState.from_gaussian(GaussianState(s.x0, s.P0), mu0), F, Q, T)
    cf = class_filter(s)
    np.testing.assert_allclose(cf.transition, T, rtol=0, atol=0)
    x, P, mu = cf.initial_states(s.z0[None])
    x, P, mu = cf.predict(x, P, mu, np.array([dt]))
    np.testing.assert_allclose(scalar.mu, imm.cbar, rtol=0, atol=1e-15)
    np.testing.assert_allclose(mu[0], imm.cbar, rtol=0, atol=1e-15)
    for j, f in enumerate(imm.filters):
        assert_close(scalar.x[j], f.x)
        assert_close(scalar.P[j], f.P)
        assert_close(x[0, j], f.x)
        assert_close(P[0, j], f.P)


def test_scalar_mixing_with_an_unreachable_mode() -> None:
    """mu = [1, 0] and T = I: mode 1 cannot be reached (c̄_1 = 0). Its probability stays 0
    and every number stays finite."""
    state = IMMState(_distinct_modes(2).x, _distinct_modes(2).P, np.array([1.0, 0.0]))
    F, Q = _models(2)
    predicted = imm_predict(state, F, Q, np.eye(2))
    np.testing.assert_array_equal(predicted.mu, [1.0, 0.0])
    assert np.isfinite(predicted.x).all() and np.isfinite(predicted.P).all()


def test_batched_mixing_with_an_unreachable_mode() -> None:
    """Knowledge may give a transition row with a zero and a zero initial probability
    (resolve accepts both), e.g. T = [[1, 0], [0.1, 0.9]], mu0 = [1, 0]: then c̄_1 = 0.
    The batched mixing must stay finite and keep mode 0's estimate and probability
    exactly as they are (mode 0 mixes only with itself).

    Fails on batched.imm_mix as of b69a9c4: ω = T μ / c̄ divides 0 by 0, mode 1 becomes
    NaN, and the update then turns mu and the log-likelihood into NaN.
    """
    state = _distinct_modes(2)
    T = np.array([[1.0, 0.0], [0.1, 0.9]])
    F, Q = _models(2)
    with np.errstate(all="ignore"):
        x, P, mu = batched.predict(
            state.x[None], state.P[None], np.array([[1.0, 0.0]]), F[None], Q[None], T
        )
        _, _, mu_post, log_likelihood = batched.update(x, P, mu, np.zeros((1, D)), np.eye(D)[None])
    np.testing.assert_array_equal(mu[0], [1.0, 0.0])
    assert np.isfinite(x).all() and np.isfinite(P).all()
    np.testing.assert_allclose(x[0, 0], F[0] @ state.x[0], rtol=0, atol=1e-15)
    assert np.isfinite(mu_post).all() and np.isfinite(log_likelihood).all()
    np.testing.assert_allclose(mu_post[0], [1.0, 0.0], rtol=0, atol=1e-12)
