"""Property-based tests (hypothesis): covariances stay symmetric positive definite,
mode probabilities stay a distribution, the batched path equals the scalar one object
by object, and per-object time steps in one batched call equal separate calls."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from semwm.filters import batched
from semwm.filters.imm import IMMState, imm_predict, imm_update
from semwm.filters.kalman import GaussianState, kf_predict, kf_update

from ._oracle import (
    KINDS,
    FloatArray,
    Kind,
    Scenario,
    assert_close,
    class_filter,
    make_scenario,
    random_spd,
)

SETTINGS = settings(max_examples=30, deadline=None, derandomize=True)

kinds = st.sampled_from(KINDS)
dims = st.sampled_from([2, 3])
seeds = st.integers(min_value=0, max_value=2**32 - 1)
time_steps = st.floats(min_value=1e-3, max_value=0.5, allow_nan=False)
offsets = st.floats(min_value=-30.0, max_value=30.0, allow_nan=False)
# one step: a time step and, or not, a measurement offset from the predicted position
steps = st.lists(st.tuples(time_steps, st.one_of(st.none(), offsets)), min_size=1, max_size=25)


def assert_spd(P: FloatArray, what: str) -> None:
    scale = float(np.abs(P).max())
    np.testing.assert_allclose(P, P.T, rtol=0, atol=1e-12 * scale, err_msg=f"{what} symmetric")
    np.linalg.cholesky(P)  # raises unless positive definite
    assert np.linalg.eigvalsh(P).min() > 0.0, what


def random_objects(
    rng: np.random.Generator, s: Scenario, N: int
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """N objects of the scenario's class with their own means, covariances and mu."""
    x = rng.normal(scale=2.0, size=(N, s.modes, s.n))
    P = np.array([[random_spd(rng, s.n, 0.5) for _ in range(s.modes)] for _ in range(N)])
    mu = rng.dirichlet(np.ones(s.modes), size=N) if s.modes > 1 else np.ones((N, 1))
    return x, P, mu


@SETTINGS
@given(seed=seeds, kind=kinds, d=dims, sequence=steps)
def test_covariances_stay_spd_and_mu_a_distribution(
    seed: int, kind: Kind, d: int, sequence: list[tuple[float, float | None]]
) -> None:
    """Scalar KF/IMM and the batched path over a random sequence, including far
    measurements (up to 30 m off)."""
    s = make_scenario(np.random.default_rng(seed), kind, d, length=1)
    state = IMMState.from_gaussian(GaussianState(s.x0, s.P0), s.mu0)
    kf = GaussianState(s.x0, s.P0)
    x, P, mu = state.x[None], state.P[None], state.mu[None]
    for dt, offset in sequence:
        F, Q = s.models(dt)
        state = imm_predict(state, F, Q, s.T)
        kf = kf_predict(kf, F[0], Q[0])
        x, P, mu = batched.predict(x, P, mu, F[None], Q[None], s.T)
        if offset is not None:
            z = state.x[0, :d] + offset
            state = imm_update(state, z, s.H, s.R).state
            kf = kf_update(kf, z, s.H, s.R).state
            x, P, mu, ll = batched.update(x, P, mu, z[None], s.R[None])
            assert np.isfinite(ll).all()
        for j in range(s.modes):
            assert_spd(state.P[j], f"scalar IMM mode {j}")
            assert_spd(P[0, j], f"batched mode {j}")
        if s.modes == 1:
            assert_spd(kf.P, "scalar KF")
        for m in (state.mu, mu[0]):
            assert (m >= 0.0).all()
            np.testing.assert_allclose(m.sum(), 1.0, rtol=0, atol=1e-12)


@SETTINGS
@given(seed=seeds, kind=kinds, d=dims, N=st.integers(min_value=1, max_value=20))
def test_batched_equals_scalar_object_by_object(seed: int, kind: Kind, d: int, N: int) -> None:
    """N objects with their own states, time steps, measurements and measurement noise,
    predicted and updated in one ClassFilter call each, equal the scalar filters run on
    each object alone (two predict/update cycles)."""
    rng = np.random.default_rng(seed)
    s = make_scenario(rng, kind, d, length=1)
    cf = class_filter(s)
    x, P, mu = random_objects(rng, s, N)
    scalar = [IMMState(x[i], P[i], mu[i]) for i in range(N)]
    kfs = [GaussianState(x[i, 0], P[i, 0]) for i in range(N)]
    for _ in range(2):
        dt = 0.5 - rng.uniform(0.0, 0.5, size=N)
        z = x[:, 0, :d] + rng.normal(size=(N, d))
        R = np.array([random_spd(rng, d, 0.3) for _ in range(N)])
        x, P, mu = cf.predict(x, P, mu, dt)
        x, P, mu, ll = cf.update(x, P, mu, z, R)
        xc, Pc = cf.combine(x, P, mu)
        for i in range(N):
            F, Q = s.models(float(dt[i]))
            result = imm_update(imm_predict(scalar[i], F, Q, s.T), z[i], s.H, R[i])
            scalar[i] = result.state
            assert_close(x[i], scalar[i].x)
            assert_close(P[i], scalar[i].P)
            assert_close(mu[i], scalar[i].mu)
            assert_close(ll[i], result.log_likelihood)
            if s.modes == 1:
                update = kf_update(kf_predict(kfs[i], F[0], Q[0]), z[i], s.H, R[i])
                kfs[i] = update.state
                assert_close(xc[i], kfs[i].x)
                assert_close(Pc[i], kfs[i].P)
                assert_close(ll[i], update.log_likelihood)


@SETTINGS
@given(seed=seeds, kind=kinds, d=dims, N=st.integers(min_value=1, max_value=12))
def test_class_filter_dt_zero_leaves_state_unchanged(seed: int, kind: Kind, d: int, N: int) -> None:
    rng = np.random.default_rng(seed)
    s = make_scenario(rng, kind, d, length=1)
    cf = class_filter(s)
    x, P, mu = random_objects(rng, s, N)
    x2, P2, mu2 = cf.predict(x, P, mu, np.zeros(N))
    np.testing.assert_array_equal(x2, x)
    np.testing.assert_array_equal(P2, P)
    np.testing.assert_array_equal(mu2, mu)
    assert x2 is not x  # a new value, not the caller's arrays


@SETTINGS
@given(
    seed=seeds,
    kind=kinds,
    d=dims,
    dts=st.lists(st.one_of(st.just(0.0), time_steps), min_size=1, max_size=12),
)
def test_per_object_dt_in_one_call_equals_separate_calls(
    seed: int, kind: Kind, d: int, dts: list[float]
) -> None:
    rng = np.random.default_rng(seed)
    s = make_scenario(rng, kind, d, length=1)
    cf = class_filter(s)
    N = len(dts)
    x, P, mu = random_objects(rng, s, N)
    dt = np.array(dts)
    xb, Pb, mub = cf.predict(x, P, mu, dt)
    for i in range(N):
        xi, Pi, mui = cf.predict(x[i : i + 1], P[i : i + 1], mu[i : i + 1], dt[i : i + 1])
        np.testing.assert_allclose(xb[i], xi[0], rtol=1e-13, atol=1e-13)
        np.testing.assert_allclose(Pb[i], Pi[0], rtol=1e-13, atol=1e-13)
        np.testing.assert_allclose(mub[i], mui[0], rtol=1e-13, atol=1e-13)
