"""The Rust existence and coverage kernels (core/src/existence.rs, core/src/coverage.rs,
through semwm.mhf.rust) against the Python functions, the specification, to 1e-12 on
random inputs: ``survive``, ``missed``, ``inside_probability`` with and without margins,
``in_view_probability`` (7 x 7 Gauss-Hermite), the range coverage and hull distance of
``ObservedRates.watched``, and the normal CDF they share (scipy's ``ndtr``)."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.special import ndtr

from semwm.filters.engine import rust_core
from semwm.filters.motion import FloatArray
from semwm.mhf import existence, kernels, rates, rust
from semwm.mhf.measurement import SensorView

from . import needs_rust

pytestmark = needs_rust

_core: Any = rust_core()

TOL = 1e-12
seeds = st.integers(0, 2**32 - 1)


def _close(got: FloatArray, expected: FloatArray, tol: float = TOL) -> None:
    assert got.shape == expected.shape and got.dtype == np.float64
    np.testing.assert_allclose(got, expected, rtol=tol, atol=tol)


def _spd(rng: np.random.Generator, n: int, d: int, scale: float) -> FloatArray:
    A = rng.normal(size=(n, d, d)) * np.sqrt(scale)
    result: FloatArray = A @ np.swapaxes(A, -1, -2) + 0.01 * scale * np.eye(d)
    return result


@settings(max_examples=200, deadline=None)
@given(seeds, st.integers(0, 20), st.floats(0.0, 100.0))
def test_survive(seed: int, n: int, dt: float) -> None:
    rng = np.random.default_rng(seed)
    r = rng.uniform(0.0, 1.0, n)
    r[rng.uniform(size=n) < 0.2] = 1.0
    mu = rng.exponential(1.0, n) * (rng.uniform(size=n) < 0.7)  # some rates exactly 0
    f = rng.exponential(5.0, n) * (rng.uniform(size=n) < 0.7)
    expected = existence.survive(r, mu, f, dt)
    got = rust.survive(r, mu, f, dt)
    for g, e in zip(got, expected, strict=True):
        _close(g, e)


@settings(max_examples=200, deadline=None)
@given(seeds, st.integers(0, 20))
def test_missed(seed: int, n: int) -> None:
    rng = np.random.default_rng(seed)
    r = rng.uniform(0.0, 1.0, n)
    p = rng.uniform(0.0, 1.0, n) * (rng.uniform(size=n) < 0.8)
    r[rng.uniform(size=n) < 0.2] = 1.0
    p[rng.uniform(size=n) < 0.1] = 1.0  # r = p = 1: q at its floor
    for g, e in zip(rust.missed(r, p), existence.missed(r, p), strict=True):
        _close(g, e)


def test_ndtr_is_scipys() -> None:
    x = np.concatenate(
        [np.linspace(-40.0, 40.0, 20001), [-1e300, -38.5, 0.0, -0.0, 1e-300, 8.0, 1e300]]
    )
    # relative, also in the far tails: the same Cephes algorithm
    np.testing.assert_allclose(_core.ndtr(x), ndtr(x), rtol=1e-13, atol=0.0)


def test_gauss_hermite_rule_is_numpys() -> None:
    x, w = np.polynomial.hermite_e.hermegauss(7)
    got_x, got_w = _core.gauss_hermite_rule()
    np.testing.assert_array_equal(got_x, x)
    np.testing.assert_array_equal(got_w, w / w.sum())


@settings(max_examples=200, deadline=None)
@given(seeds, st.integers(0, 12), st.sampled_from([2, 3]), st.floats(1e-6, 1e2), st.booleans())
def test_inside_probability(seed: int, n: int, d: int, scale: float, with_margin: bool) -> None:
    rng = np.random.default_rng(seed)
    low = rng.uniform(-10.0, 0.0, d)
    high = low + rng.uniform(0.1, 20.0, d)
    region = tuple((float(a), float(b)) for a, b in zip(low, high, strict=True))
    # objects around the edges, inside and outside
    position = rng.uniform(low - 2.0, high + 2.0, size=(n, d))
    covariance = _spd(rng, n, d, scale)
    margin = rng.uniform(0.0, 0.5, size=(n, d)) if with_margin else None
    expected = existence.inside_probability(position, covariance, region, margin)
    _close(rust.inside_probability(position, covariance, region, margin), expected)
    _close(rust.inside_probability(position, covariance, None, margin), np.ones(n))


@settings(max_examples=200, deadline=None)
@given(
    seeds,
    st.integers(0, 12),
    st.sampled_from([2, 3]),
    st.floats(1e-4, 1e2),
    st.one_of(st.none(), st.floats(0.5, 15.0)),
    st.one_of(st.none(), st.floats(0.05, math.pi)),
    st.floats(-10.0, 10.0),
)
def test_in_view_probability(
    seed: int,
    n: int,
    d: int,
    scale: float,
    view_range: float | None,
    half_angle: float | None,
    heading: float,
) -> None:
    rng = np.random.default_rng(seed)
    position = rng.uniform(-10.0, 10.0, size=(n, d))
    covariance = _spd(rng, n, d, scale)
    view = SensorView(0.0, None, rng.uniform(-3.0, 3.0, 2), heading, view_range, half_angle)
    expected = existence.in_view_probability(position, covariance, view)
    _close(rust.in_view_probability(position, covariance, view), expected)
    margin = rng.uniform(0.0, 1.5, n)  # the view eroded by each object's margin
    eroded = existence.in_view_probability(position, covariance, view, margin)
    _close(rust.in_view_probability(position, covariance, view, margin), eroded)
    assert np.all(eroded <= expected + 1e-12)


def test_an_eroded_view_counts_only_what_is_its_margin_inside() -> None:
    """A view of 5 m and +-45 degrees from the origin, heading along x; a point estimate
    (1 mm) 0.2 m inside the upper edge counts with margin 0.1 m, not with 0.3 m; 4.8 m
    along the axis likewise against the range."""
    view = SensorView(0.0, None, np.zeros(2), 0.0, 5.0, math.pi / 4)
    along_edge = np.array([math.cos(math.pi / 4), math.sin(math.pi / 4)]) * 3.0
    inward = np.array([math.sin(math.pi / 4), -math.cos(math.pi / 4)])
    position = np.array([along_edge + 0.2 * inward, [4.8, 0.0]])
    covariance = np.tile(1e-6 * np.eye(2), (2, 1, 1))
    for kernel in (existence.in_view_probability, rust.in_view_probability):
        assert kernel(position, covariance, view, np.array([0.1, 0.1])) == pytest.approx([1, 1])
        assert kernel(position, covariance, view, np.array([0.3, 0.3])) == pytest.approx([0, 0])


def test_in_view_probability_of_a_covariance_that_is_not_positive_definite() -> None:
    view = SensorView(0.0, None, np.zeros(2), 0.0, 5.0, 1.0)
    bad = np.array([[[-1.0, 0.0], [0.0, 1.0]]])
    with pytest.raises(np.linalg.LinAlgError):
        existence.in_view_probability(np.zeros((1, 2)), bad, view)
    with pytest.raises(np.linalg.LinAlgError):
        rust.in_view_probability(np.zeros((1, 2)), bad, view)


@settings(max_examples=200, deadline=None)
@given(seeds, st.integers(0, 12), st.sampled_from([2, 3]), st.integers(1, 3), st.booleans())
def test_range_coverage(seed: int, n: int, d: int, k: int, soft: bool) -> None:
    rng = np.random.default_rng(seed)
    positions = rng.uniform(-10.0, 10.0, size=(n, d))
    sensor = rng.uniform(-3.0, 3.0, k)
    # up to 30 m: wide against the reach, where the disc's share is summed
    spread = rng.uniform(0.0, 2.0, n) * 10.0 ** rng.integers(0, 2, n) * 1.5 if soft else None
    if spread is not None and n:
        spread[0] = 0.0  # the 1e-9 floor
    reach = float(rng.uniform(1.0, 10.0))
    expected = rates.range_coverage(positions, sensor, reach, spread)
    _close(rust.range_coverage(positions, sensor, reach, spread), expected)


@settings(max_examples=300, deadline=None)
@given(
    seeds,
    st.integers(0, 12),
    st.integers(1, 12),
    st.sampled_from([2, 3]),
    st.sampled_from(["spread", "line", "thin"]),
)
def test_hull_distance(seed: int, n: int, m: int, d: int, layout: str) -> None:
    rng = np.random.default_rng(seed)
    corners = rng.uniform(-5.0, 5.0, size=(m, d))
    if layout == "line":  # on one line: the segment of the extremes
        corners = rng.uniform(-5.0, 5.0, d) + rng.uniform(-3.0, 3.0, (m, 1)) * rng.normal(size=d)
    elif layout == "thin":  # nearly on one line: qhull's tolerance decides
        corners[:, 1:] = corners[:, :1] * 0.5 + rng.normal(size=(m, d - 1)) * 1e-10
    points = rng.uniform(-8.0, 8.0, size=(n, d))
    points[: n // 2] = corners[rng.integers(0, m, n // 2)] + rng.normal(size=(n // 2, d)) * 0.1
    expected = rates.hull_distance(points, corners)
    _close(rust.hull_distance(points, corners), expected)


def test_hull_distance_of_squares_lines_and_cubes() -> None:
    square = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
    points = np.array([[0.5, 0.5], [3.0, 0.5], [0.5, -0.25]])
    _close(_core.hull_distance(points, square), np.array([0.0, 2.0, 0.25]))
    line = np.array([[0.0, 0.0], [1.0, 1.0], [2.0, 2.0]])  # flat: the segment
    _close(_core.hull_distance(points, line), rates.hull_distance(points, line))
    cube = np.array([[i & 1, (i >> 1) & 1, (i >> 2) & 1] for i in range(8)], dtype=float)
    inner = np.array([[0.5, 0.5, 0.5], [0.5, 0.5, 3.0], [-2.0, 0.5, 0.5]])
    _close(_core.hull_distance(inner, cube), np.array([0.0, 2.0, 2.0]))


def test_engines_choose_their_kernels() -> None:
    assert kernels.existence_kernels("python") is kernels.PYTHON_KERNELS
    assert kernels.PYTHON_KERNELS.survive is existence.survive
    chosen = kernels.existence_kernels("rust")
    assert chosen.engine == "rust" and chosen.survive is rust.survive


def test_shape_errors_name_the_argument() -> None:
    with pytest.raises(ValueError, match="mu"):
        _core.survive(np.ones(3), np.ones(2), np.ones(3), 1.0)
    with pytest.raises(ValueError, match="margin"):
        _core.inside_probability(
            np.zeros((2, 2)), np.ones((2, 2, 2)), np.zeros(2), np.ones(2), np.zeros((3, 2))
        )
