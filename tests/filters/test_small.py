"""The closed forms for small matrices and the polynomial F(dt), Q(dt) against numpy and
the per-step builders they replace on the hot path."""

from __future__ import annotations

import numpy as np
import pytest

from semwm.filters.motion import (
    process_noise_coefficients,
    process_noises,
    transition_coefficients,
    transition_matrices,
)
from semwm.filters.small import inverse_and_log_det, largest_eigenvalue, mahalanobis_squared


def _spd(rng: np.random.Generator, count: int, d: int) -> np.ndarray:
    A = rng.normal(size=(count, d, d))
    return A @ np.swapaxes(A, -1, -2) + 0.1 * np.eye(d)


@pytest.mark.parametrize("d", [1, 2, 3])
def test_small_matrix_helpers_agree_with_numpy(d: int) -> None:
    rng = np.random.default_rng(d)
    S = _spd(rng, 7, d)
    r = rng.normal(size=(7, d))
    inverse, log_det = inverse_and_log_det(S)
    np.testing.assert_allclose(inverse, np.linalg.inv(S), rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(log_det, np.linalg.slogdet(S)[1], rtol=1e-12, atol=1e-12)
    expected = np.einsum("ni,ni->n", r, np.linalg.solve(S, r[..., None])[..., 0])
    np.testing.assert_allclose(mahalanobis_squared(r, S), expected, rtol=1e-10)
    np.testing.assert_allclose(largest_eigenvalue(S), np.linalg.eigvalsh(S)[:, -1], rtol=1e-12)


def test_inverse_refuses_a_matrix_that_is_not_positive_definite() -> None:
    with pytest.raises(np.linalg.LinAlgError):
        inverse_and_log_det(np.array([[[1.0, 2.0], [2.0, 1.0]]]))


@pytest.mark.parametrize(
    ("order", "with_velocity", "stationary"),
    [("first_order", True, 0.0), ("zeroth_order", False, 0.0), ("zeroth_order", True, 0.3)],
)
def test_polynomial_models_equal_the_builders(order, with_velocity, stationary) -> None:
    dt = np.array([0.0, 0.01, 0.1, 1.0, 7.5])
    Qc = np.array([[0.2, 0.05], [0.05, 0.1]])
    F0, F1 = transition_coefficients(order, 2, with_velocity)
    np.testing.assert_allclose(
        F0 + dt[:, None, None] * F1, transition_matrices(order, 2, dt, with_velocity), atol=0
    )
    C = process_noise_coefficients(order, 2, Qc, with_velocity, stationary)
    t = dt[:, None, None]
    expected = process_noises(order, 2, dt, Qc, with_velocity, stationary)
    np.testing.assert_allclose(C[0] + t * (C[1] + t * (C[2] + t * C[3])), expected, rtol=1e-14)
