"""The Rust kernels (semwm._core through semwm.filters.rust) against the Python engine's
batched filters, the specification, to 1e-12 on random inputs: 2-D and 3-D, Kalman
(one mode) and IMM (two and three modes), and every class filter of every shipped
knowledge file (transition periods, the passive decay of a ball, dt = 0 and dt < 0)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from semwm.filters import batched, small
from semwm.filters.factory import FilterFactory
from semwm.filters.motion import FloatArray
from semwm.knowledge.loader import load_knowledge
from semwm.knowledge.shipped import shipped_knowledge_path

from . import needs_rust

pytestmark = needs_rust

TOL = 1e-12


def _close(got: FloatArray, expected: FloatArray) -> None:
    assert got.shape == expected.shape and got.dtype == np.float64
    np.testing.assert_allclose(got, expected, rtol=TOL, atol=TOL)


def _spd(rng: np.random.Generator, shape: tuple[int, ...], n: int, scale: float) -> FloatArray:
    A = rng.normal(size=(*shape, n, n)) * np.sqrt(scale)
    result: FloatArray = A @ np.swapaxes(A, -1, -2) + 0.05 * scale * np.eye(n)
    return result


def _stochastic(rng: np.random.Generator, shape: tuple[int, ...], m: int) -> FloatArray:
    T = rng.uniform(0.0, 1.0, size=(*shape, m, m)) ** 3  # some entries near 0
    result: FloatArray = T / T.sum(axis=-1, keepdims=True)
    return result


def _states(
    rng: np.random.Generator, N: int, M: int, n: int, scale: float
) -> tuple[FloatArray, FloatArray, FloatArray]:
    x = rng.normal(size=(N, M, n)) * 3.0
    P = _spd(rng, (N, M), n, scale)
    mu = rng.dirichlet(np.ones(M), size=N)
    return x, P, mu


shapes = st.tuples(
    st.integers(0, 2**32 - 1),  # seed
    st.integers(1, 12),  # N objects
    st.sampled_from([1, 2, 3]),  # M modes
    st.sampled_from([2, 3]),  # d
    st.booleans(),  # with velocity: n = 2d, else d
    st.floats(1e-3, 1e2),  # covariance scale
)


@pytest.fixture(scope="module")
def rust():  # type: ignore[no-untyped-def]
    from semwm.filters import rust

    return rust


@settings(max_examples=150, deadline=None)
@given(shapes, st.booleans())
def test_imm_mix_and_predict(rust, case, per_object_transition) -> None:  # type: ignore[no-untyped-def]
    seed, N, M, d, velocity, scale = case
    rng = np.random.default_rng(seed)
    n = 2 * d if velocity else d
    x, P, mu = _states(rng, N, M, n, scale)
    T = _stochastic(rng, (N,) if per_object_transition else (), M)
    for got, expected in zip(rust.imm_mix(x, P, mu, T), batched.imm_mix(x, P, mu, T), strict=True):
        _close(got, expected)
    F = rng.normal(size=(N, M, n, n))
    Q = _spd(rng, (N, M), n, scale)
    for got, expected in zip(
        rust.batched_predict(x, P, mu, F, Q, T), batched.predict(x, P, mu, F, Q, T), strict=True
    ):
        _close(got, expected)


@settings(max_examples=150, deadline=None)
@given(shapes)
def test_update_and_combine(rust, case) -> None:  # type: ignore[no-untyped-def]
    seed, N, M, d, velocity, scale = case
    rng = np.random.default_rng(seed)
    n = 2 * d if velocity else d
    x, P, mu = _states(rng, N, M, n, scale)
    z = x[:, 0, :d] + rng.normal(size=(N, d)) * np.sqrt(scale)
    R = _spd(rng, (N,), d, 0.1 * scale)
    expected = batched.update(x, P, mu, z, R)
    got = rust.update(x, P, mu, z, R)
    for a, b in zip(got, expected, strict=True):
        _close(a, b)
    for a, b in zip(rust.combine(*got[:3]), batched.combine(*expected[:3]), strict=True):
        _close(a, b)
    # the gate: the innovation's squared Mahalanobis distance
    S = P[:, 0, :d, :d] + R
    residual = z - x[:, 0, :d]
    _close(rust.mahalanobis_squared(residual, S), small.mahalanobis_squared(residual, S))


def _class_filters() -> list[tuple[str, str]]:
    cases = []
    for file in ("sim1.yaml", "sim2.yaml", "robocup.yaml", "robocup_kick.yaml", "grid.yaml"):
        knowledge = load_knowledge(shipped_knowledge_path(file))
        cases += [(file, name) for name in knowledge.classes]
    return cases


@pytest.mark.parametrize(("file", "cls"), _class_filters())
@settings(max_examples=15, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), N=st.integers(1, 9))
def test_class_filter_predict(file: str, cls: str, seed: int, N: int) -> None:
    knowledge = load_knowledge(shipped_knowledge_path(file))
    python = FilterFactory(knowledge, "python").filter_for(cls)
    rust = FilterFactory(knowledge, "rust").filter_for(cls)
    rng = np.random.default_rng(seed)
    x, P, mu = _states(rng, N, python.modes, python.state_size, float(rng.uniform(0.01, 5.0)))
    # objects at rest too (the decay's speed 0), and steps of 0 and below (left as they are)
    x[rng.random(N) < 0.3, :, python.dim :] = 0.0
    dt = rng.choice([-0.5, 0.0, 0.01, 0.1, 0.4, 1.0, 3.0, 20.0], size=N)
    for got, expected in zip(rust.predict(x, P, mu, dt), python.predict(x, P, mu, dt), strict=True):
        _close(got, expected)
    # the inputs are not modified
    x2, P2, mu2 = x.copy(), P.copy(), mu.copy()
    rust.predict(x, P, mu, dt)
    assert (x == x2).all() and (P == P2).all() and (mu == mu2).all()


def test_every_shipped_class_is_covered() -> None:
    """The shipped classes include each branch of ClassFilter.predict: a random walk,
    an IMM with a transition period, and a passive decay."""
    kinds = set()
    for file, cls in _class_filters():
        flt = FilterFactory(load_knowledge(shipped_knowledge_path(file))).filter_for(cls)
        kinds.add("decay" if flt.velocity_decay > 0 else "imm" if flt.modes > 1 else "kf")
        if flt.transition_period is not None and flt.modes > 1:
            kinds.add("period")
    assert kinds == {"decay", "imm", "kf", "period"}


def test_errors_are_python_exceptions_with_messages(rust) -> None:  # type: ignore[no-untyped-def]
    x = np.zeros((2, 1, 2))
    P = np.repeat(np.eye(2)[None, None], 2, axis=0)
    mu = np.ones((2, 1))
    z = np.zeros((2, 2))
    R = np.repeat(np.eye(2)[None], 2, axis=0)
    with pytest.raises(ValueError, match=r"R: expected shape \[2, 2, 2\], got \[1, 2, 2\]"):
        rust.update(x, P, mu, z, R[:1])
    with pytest.raises(ValueError, match=r"mu: expected shape \[2, 1\], got \[2, 2\]"):
        rust.update(x, P, np.ones((2, 2)), z, R)
    not_pd = P.copy()
    not_pd[1, 0] = [[-3.0, 0.0], [0.0, 1.0]]
    with pytest.raises(np.linalg.LinAlgError) as python_error:
        batched.update(x, not_pd, mu, z, R)
    with pytest.raises(np.linalg.LinAlgError, match="not positive definite"):
        rust.update(x, not_pd, mu, z, R)
    assert "positive definite" in str(python_error.value)
    with pytest.raises(TypeError):  # not float64: refused, not reinterpreted
        from semwm import _core

        _core.combine(x.astype(np.float32), P, mu)


def test_class_filter_tables_are_checked() -> None:
    from semwm import _core

    eye = np.eye(2)[None]
    zero = np.zeros((1, 2, 2))
    C = np.zeros((4, 1, 2, 2))
    one = np.ones((1, 1))
    with pytest.raises(ValueError, match="n = dim or 2 dim, got dim 3, n 2"):
        _core.ClassFilter(3, eye, zero, C, one, [False], 0.0)
    with pytest.raises(ValueError, match="C: expected 16 values, got 12"):
        _core.ClassFilter(2, eye, zero, C[:3], one, [False], 0.0)
    flt = _core.ClassFilter(2, eye, zero, C, one, [False], 0.0)
    x, P, mu = np.zeros((2, 1, 2)), np.repeat(eye[None], 2, axis=0), np.ones((2, 1))
    with pytest.raises(ValueError, match="dt: expected 2 time steps"):
        flt.predict(x, P, mu, np.ones(3))
    with pytest.raises(ValueError, match=r"x: expected \(N, 1, 2\) for this filter"):
        flt.predict(np.zeros((2, 1, 4)), np.zeros((2, 1, 4, 4)), mu, np.ones(2))
