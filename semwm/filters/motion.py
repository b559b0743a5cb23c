"""Motion models: the transition matrix F(dt) and the process noise Q(dt).

State layout: position first, then velocity, ``x = [p_1..p_d, v_1..v_d]``.

* ``zeroth_order`` (constant position, a random walk of the position), state ``p``:

  .. math:: F = I_d, \\qquad Q = \\Delta t\\, Q_c

* ``first_order`` (constant velocity, white-noise acceleration), state ``[p, v]``:

  .. math::
     F = \\begin{bmatrix} I & \\Delta t I \\\\ 0 & I \\end{bmatrix}, \\qquad
     Q = \\begin{bmatrix} \\tfrac{\\Delta t^3}{3} Q_c & \\tfrac{\\Delta t^2}{2} Q_c \\\\
                          \\tfrac{\\Delta t^2}{2} Q_c & \\Delta t\\, Q_c \\end{bmatrix}

* ``zeroth_order`` inside an IMM (state ``[p, v]``, paper 002 IV-B): the position
  random-walks and the velocity is reset to zero with variance
  ``stationary_velocity_variance``:

  .. math::
     F = \\begin{bmatrix} I & 0 \\\\ 0 & 0 \\end{bmatrix}, \\qquad
     Q = \\begin{bmatrix} \\Delta t\\, Q_c & 0 \\\\ 0 & \\sigma_v^2 I \\end{bmatrix}

``Q_c`` is the d x d spectral density from the knowledge's ``system_noise``.
Every builder takes an array of time steps and returns one matrix per step, so
that objects last updated at different times are predicted in one call.
"""

from __future__ import annotations

from typing import Literal

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]
MotionOrder = Literal["zeroth_order", "first_order"]


def state_size(order: MotionOrder, dim: int, with_velocity: bool) -> int:
    """Length of the state vector: ``d`` for a lone zeroth-order filter, else ``2d``."""
    return 2 * dim if (with_velocity or order == "first_order") else dim


def transition_matrices(
    order: MotionOrder, dim: int, dt: FloatArray, with_velocity: bool = False
) -> FloatArray:
    """F(dt) for each time step; shape ``(len(dt), n, n)``."""
    dt = np.asarray(dt, dtype=float)
    n = state_size(order, dim, with_velocity)
    eye = np.eye(dim)
    F = np.zeros((dt.shape[0], n, n))
    F[:, :dim, :dim] = eye
    if order == "first_order":
        F[:, dim:, dim:] = eye
        F[:, :dim, dim:] = dt[:, None, None] * eye
    return F


def process_noises(
    order: MotionOrder,
    dim: int,
    dt: FloatArray,
    spectral_density: FloatArray,
    with_velocity: bool = False,
    stationary_velocity_variance: float = 0.0,
) -> FloatArray:
    """Q(dt) for each time step; shape ``(len(dt), n, n)``."""
    dt = np.asarray(dt, dtype=float)[:, None, None]
    Qc = np.asarray(spectral_density, dtype=float)
    n = state_size(order, dim, with_velocity)
    Q = np.zeros((dt.shape[0], n, n))
    if order == "first_order":
        Q[:, :dim, :dim] = dt**3 / 3.0 * Qc
        Q[:, :dim, dim:] = dt**2 / 2.0 * Qc
        Q[:, dim:, :dim] = dt**2 / 2.0 * Qc
        Q[:, dim:, dim:] = dt * Qc
    else:
        Q[:, :dim, :dim] = dt * Qc
        if n > dim:
            Q[:, dim:, dim:] = stationary_velocity_variance * np.eye(dim)
    return Q


def decay_factors(speed: FloatArray, dt: FloatArray, alpha: float) -> tuple[FloatArray, FloatArray]:
    r"""Position gain ``g`` and velocity factor ``k`` of a velocity that decays at ``alpha``.

    Paper 004 IV-B: a passive object's speed decays at a constant rate :math:`\alpha`
    (m/s^2) along its direction until it stops. Integrated exactly over ``dt`` (so the
    result does not depend on how the interval is split), with :math:`s = |v|` and
    :math:`\tau = \min(\Delta t, s / \alpha)` the time it still moves:

    .. math::
       p' = p + g\, v, \quad g = \tau - \frac{\alpha \tau^2}{2 s}, \qquad
       v' = k\, v, \quad k = \frac{\max(0, s - \alpha \Delta t)}{s}

    The paper's discrete rule :math:`x \leftarrow x + v \Delta t,\ v \leftarrow
    \max(0, |v| - \alpha \Delta t)` is its Euler form (equal as :math:`\Delta t \to 0`).
    ``speed`` and ``dt`` broadcast; ``s = 0`` gives ``g = k = 0`` (it stays put).
    """
    speed = np.asarray(speed, dtype=float)
    dt = np.asarray(dt, dtype=float)
    if alpha <= 0.0:
        return np.broadcast_to(dt, np.broadcast(speed, dt).shape).copy(), np.ones(
            np.broadcast(speed, dt).shape
        )
    safe = np.where(speed > 0.0, speed, 1.0)
    tau = np.minimum(dt, speed / alpha)
    g = np.where(speed > 0.0, tau - alpha * tau**2 / (2.0 * safe), 0.0)
    k = np.where(speed > 0.0, np.maximum(0.0, speed - alpha * dt) / safe, 0.0)
    return g, k


def transition_coefficients(
    order: MotionOrder, dim: int, with_velocity: bool = False
) -> tuple[FloatArray, FloatArray]:
    """``F0, F1`` with ``F(dt) = F0 + dt F1`` (:func:`transition_matrices`), each ``(n, n)``."""
    F0 = transition_matrices(order, dim, np.zeros(1), with_velocity)[0]
    F1 = transition_matrices(order, dim, np.ones(1), with_velocity)[0] - F0
    return F0, F1


def process_noise_coefficients(
    order: MotionOrder,
    dim: int,
    spectral_density: FloatArray,
    with_velocity: bool = False,
    stationary_velocity_variance: float = 0.0,
) -> FloatArray:
    """``C`` ``(4, n, n)`` with ``Q(dt) = C[0] + dt C[1] + dt^2 C[2] + dt^3 C[3]``, the
    polynomial :func:`process_noises` evaluates (so that a batch of time steps costs a
    few array operations)."""
    Qc = np.asarray(spectral_density, dtype=float)
    n = state_size(order, dim, with_velocity)
    C = np.zeros((4, n, n))
    if order == "first_order":
        C[3, :dim, :dim] = Qc / 3.0
        C[2, :dim, dim:] = Qc / 2.0
        C[2, dim:, :dim] = Qc / 2.0
        C[1, dim:, dim:] = Qc
    else:
        C[1, :dim, :dim] = Qc
        if n > dim:
            C[0, dim:, dim:] = stationary_velocity_variance * np.eye(dim)
    return C
