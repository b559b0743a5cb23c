"""Motion models: F(dt) and Q(dt) against matrices written out by hand."""

from __future__ import annotations

import numpy as np
import pytest

from semwm.filters.motion import process_noises, state_size, transition_matrices

DT = np.array([0.5])
# dt = 0.5: dt^3 / 3 = 1/24, dt^2 / 2 = 1/8, dt = 1/2.

QC_2D = np.array([[2.0, 0.5], [0.5, 1.0]])
QC_3D = np.array([[3.0, 0.0, 0.6], [0.0, 1.2, 0.0], [0.6, 0.0, 2.4]])


def test_first_order_2d() -> None:
    F = np.array(
        [
            [1.0, 0.0, 0.5, 0.0],
            [0.0, 1.0, 0.0, 0.5],
            [0.0, 0.0, 1.0, 0.0],
            [0.0, 0.0, 0.0, 1.0],
        ]
    )
    Q = np.array(
        [
            [2 / 24, 0.5 / 24, 2 / 8, 0.5 / 8],
            [0.5 / 24, 1 / 24, 0.5 / 8, 1 / 8],
            [2 / 8, 0.5 / 8, 1.0, 0.25],
            [0.5 / 8, 1 / 8, 0.25, 0.5],
        ]
    )
    np.testing.assert_allclose(transition_matrices("first_order", 2, DT)[0], F, rtol=0, atol=0)
    np.testing.assert_allclose(
        process_noises("first_order", 2, DT, QC_2D)[0], Q, rtol=1e-15, atol=1e-16
    )


def test_first_order_3d() -> None:
    F = np.array(
        [
            [1.0, 0.0, 0.0, 0.5, 0.0, 0.0],
            [0.0, 1.0, 0.0, 0.0, 0.5, 0.0],
            [0.0, 0.0, 1.0, 0.0, 0.0, 0.5],
            [0.0, 0.0, 0.0, 1.0, 0.0, 0.0],
            [0.0, 0.0, 0.0, 0.0, 1.0, 0.0],
            [0.0, 0.0, 0.0, 0.0, 0.0, 1.0],
        ]
    )
    # blocks QC/24, QC/8, QC/2
    Q = np.array(
        [
            [0.125, 0.0, 0.025, 0.375, 0.0, 0.075],
            [0.0, 0.05, 0.0, 0.0, 0.15, 0.0],
            [0.025, 0.0, 0.1, 0.075, 0.0, 0.3],
            [0.375, 0.0, 0.075, 1.5, 0.0, 0.3],
            [0.0, 0.15, 0.0, 0.0, 0.6, 0.0],
            [0.075, 0.0, 0.3, 0.3, 0.0, 1.2],
        ]
    )
    np.testing.assert_allclose(transition_matrices("first_order", 3, DT)[0], F, rtol=0, atol=0)
    np.testing.assert_allclose(
        process_noises("first_order", 3, DT, QC_3D)[0], Q, rtol=1e-14, atol=1e-16
    )


def test_zeroth_order_2d_and_3d() -> None:
    np.testing.assert_array_equal(transition_matrices("zeroth_order", 2, DT)[0], np.eye(2))
    np.testing.assert_array_equal(transition_matrices("zeroth_order", 3, DT)[0], np.eye(3))
    np.testing.assert_allclose(
        process_noises("zeroth_order", 2, DT, QC_2D)[0], [[1.0, 0.25], [0.25, 0.5]], rtol=1e-15
    )
    np.testing.assert_allclose(
        process_noises("zeroth_order", 3, DT, QC_3D)[0],
        [[1.5, 0.0, 0.3], [0.0, 0.6, 0.0], [0.3, 0.0, 1.2]],
        rtol=1e-15,
    )


def test_zeroth_order_with_velocity_2d() -> None:
    """Inside an IMM: the position random-walks, the velocity is reset to 0 with
    variance sigma_v^2 (paper 002 IV-B)."""
    F = np.diag([1.0, 1.0, 0.0, 0.0])
    Q = np.array(
        [
            [1.0, 0.25, 0.0, 0.0],
            [0.25, 0.5, 0.0, 0.0],
            [0.0, 0.0, 0.01, 0.0],
            [0.0, 0.0, 0.0, 0.01],
        ]
    )
    np.testing.assert_array_equal(transition_matrices("zeroth_order", 2, DT, True)[0], F)
    np.testing.assert_allclose(
        process_noises("zeroth_order", 2, DT, QC_2D, True, 0.01)[0], Q, rtol=1e-15
    )


def test_zeroth_order_with_velocity_3d() -> None:
    F = np.diag([1.0, 1.0, 1.0, 0.0, 0.0, 0.0])
    Q = np.zeros((6, 6))
    Q[:3, :3] = [[1.5, 0.0, 0.3], [0.0, 0.6, 0.0], [0.3, 0.0, 1.2]]
    Q[3:, 3:] = np.diag([0.02, 0.02, 0.02])
    np.testing.assert_array_equal(transition_matrices("zeroth_order", 3, DT, True)[0], F)
    np.testing.assert_allclose(
        process_noises("zeroth_order", 3, DT, QC_3D, True, 0.02)[0], Q, rtol=1e-15
    )


@pytest.mark.parametrize("dim", [2, 3])
def test_first_order_F_of_zero_is_identity_and_Q_of_zero_is_zero(dim: int) -> None:
    zero = np.array([0.0])
    np.testing.assert_array_equal(transition_matrices("first_order", dim, zero)[0], np.eye(2 * dim))
    Qc = QC_2D if dim == 2 else QC_3D
    np.testing.assert_array_equal(process_noises("first_order", dim, zero, Qc)[0], 0.0)


@pytest.mark.parametrize("with_velocity", [False, True])
@pytest.mark.parametrize("order", ["zeroth_order", "first_order"])
@pytest.mark.parametrize("dim", [2, 3])
def test_Q_symmetric_positive_semidefinite(dim: int, order: str, with_velocity: bool) -> None:
    rng = np.random.default_rng([dim, len(order), with_velocity])
    A = rng.normal(size=(dim, dim))
    Qc = A @ A.T + 0.1 * np.eye(dim)
    dt = np.concatenate([[0.0, 1e-6, 0.5, 10.0], rng.uniform(0.0, 2.0, size=50)])
    Q = process_noises(order, dim, dt, Qc, with_velocity, 1e-4)  # type: ignore[arg-type]
    n = state_size(order, dim, with_velocity)  # type: ignore[arg-type]
    assert Q.shape == (dt.size, n, n)
    np.testing.assert_array_equal(Q, np.swapaxes(Q, -1, -2))
    eigenvalues = np.linalg.eigvalsh(Q)
    assert (eigenvalues >= -1e-12 * np.abs(eigenvalues).max(axis=1, keepdims=True)).all()
    # strictly positive definite for dt > 0 (first order, or with the velocity variance)
    if order == "first_order" or with_velocity:
        assert (eigenvalues[dt > 0].min(axis=1) > 0).all()


def test_one_matrix_per_time_step() -> None:
    dt = np.array([0.1, 0.2, 0.3])
    F = transition_matrices("first_order", 2, dt)
    Q = process_noises("first_order", 2, dt, QC_2D)
    for k, step in enumerate(dt):
        np.testing.assert_array_equal(
            F[k], transition_matrices("first_order", 2, np.array([step]))[0]
        )
        np.testing.assert_array_equal(
            Q[k], process_noises("first_order", 2, np.array([step]), QC_2D)[0]
        )
