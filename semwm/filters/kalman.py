"""A readable Kalman filter for one object: the equations, line by line.

This is the reference the batched filters (:mod:`semwm.filters.batched`) are
tested against; the world model runs the batched ones. Each step takes a frozen
:class:`GaussianState` and returns a new one. The code follows the textbook
equations one line each, with the equation as a comment above its line, in the
textbook symbols:

======  ==============  ==================================================
symbol  shape           meaning
======  ==============  ==================================================
``x``   ``(n,)``        state mean (metres, metres per second)
``P``   ``(n, n)``      state covariance
``F``   ``(n, n)``      state transition over one time step
``Q``   ``(n, n)``      process noise accumulated over that time step
``z``   ``(d,)``        measurement (metres)
``H``   ``(d, n)``      measurement matrix
``R``   ``(d, d)``      measurement noise covariance (m^2)
``y``   ``(d,)``        innovation (residual) ``z - H x``
``S``   ``(d, d)``      innovation covariance
``K``   ``(n, d)``      Kalman gain
======  ==============  ==================================================

Reference: Bar-Shalom, Li, Kirubarajan, *Estimation with Applications to
Tracking and Navigation*, Section 5.2; FilterPy's ``KalmanFilter`` (the oracle
of the tests) uses the same equations.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

FloatArray = NDArray[np.float64]
_LOG_2PI = float(np.log(2.0 * np.pi))


def _frozen(value: ArrayLike) -> FloatArray:
    """A read-only float64 copy, so that a state cannot change after it is made."""
    array = np.array(value, dtype=np.float64)
    array.flags.writeable = False
    return array


def _check_shape(name: str, value: FloatArray, expected: tuple[int, ...]) -> None:
    if value.shape != expected:
        raise ValueError(f"{name} must have shape {expected}; found {value.shape}")


@dataclass(frozen=True)
class GaussianState:
    """A Gaussian state estimate: mean ``x`` ``(n,)`` and covariance ``P`` ``(n, n)``.

    Both arrays are stored as read-only float64 copies.
    """

    x: FloatArray
    P: FloatArray

    def __post_init__(self) -> None:
        x = _frozen(self.x)
        P = _frozen(self.P)
        if x.ndim != 1:
            raise ValueError(f"x must be a vector of shape (n,); found shape {x.shape}")
        _check_shape("P", P, (x.shape[0], x.shape[0]))
        object.__setattr__(self, "x", x)
        object.__setattr__(self, "P", P)

    @property
    def size(self) -> int:
        """``n``, the length of the state vector."""
        return int(self.x.shape[0])


@dataclass(frozen=True)
class KalmanUpdate:
    """The result of :func:`kf_update`.

    Attributes
    ----------
    state
        The updated (posterior) state.
    y
        ``(d,)``: the innovation ``z - H x`` of the prior mean.
    S
        ``(d, d)``: the innovation covariance ``H P H^T + R``.
    log_likelihood
        :math:`\\log \\mathcal N(y; 0, S)`, the density of ``z`` under the prior.
    """

    state: GaussianState
    y: FloatArray
    S: FloatArray
    log_likelihood: float


def kf_predict(state: GaussianState, F: ArrayLike, Q: ArrayLike) -> GaussianState:
    """Kalman prediction over one time step.

    Parameters
    ----------
    state
        The estimate at step k-1: ``x`` ``(n,)``, ``P`` ``(n, n)``.
    F
        ``(n, n)``: the state transition F(dt), e.g. from
        :func:`semwm.filters.motion.transition_matrices`.
    Q
        ``(n, n)``: the process noise Q(dt) accumulated over the step.

    Returns
    -------
    GaussianState
        The predicted (prior) estimate at step k.

    Notes
    -----
    .. math::
       x^- = F x, \\qquad P^- = F P F^T + Q
    """
    n = state.size
    F = np.asarray(F, dtype=np.float64)
    Q = np.asarray(Q, dtype=np.float64)
    _check_shape("F", F, (n, n))
    _check_shape("Q", Q, (n, n))
    x, P = state.x, state.P

    # x⁻ = F x
    x_prior = F @ x
    # P⁻ = F P Fᵀ + Q
    P_prior = F @ P @ F.T + Q

    return GaussianState(x_prior, P_prior)


def kf_update(state: GaussianState, z: ArrayLike, H: ArrayLike, R: ArrayLike) -> KalmanUpdate:
    """Kalman update with one measurement, covariance in Joseph form.

    Parameters
    ----------
    state
        The prior estimate: ``x`` ``(n,)``, ``P`` ``(n, n)``.
    z
        ``(d,)``: the measurement (metres).
    H
        ``(d, n)``: the measurement matrix (``[I_d 0]`` when the position is measured).
    R
        ``(d, d)``: the measurement noise covariance (m^2), symmetric positive definite.

    Returns
    -------
    KalmanUpdate
        The posterior state, the innovation ``y``, its covariance ``S`` and the
        measurement's log-likelihood.

    Notes
    -----
    .. math::
       y = z - H x, \\qquad S = H P H^T + R, \\qquad K = P H^T S^{-1}

       x^+ = x + K y, \\qquad P^+ = (I - K H) P (I - K H)^T + K R K^T

       \\log \\mathcal N(y; 0, S) = -\\tfrac12 \\left( y^T S^{-1} y + \\log |S|
       + d \\log 2\\pi \\right)

    The Joseph form keeps ``P`` symmetric positive semi-definite for any gain,
    where the short form ``(I - K H) P`` loses it to rounding.
    """
    n = state.size
    z = np.asarray(z, dtype=np.float64)
    if z.ndim != 1:
        raise ValueError(f"z must be a vector of shape (d,); found shape {z.shape}")
    d = z.shape[0]
    H = np.asarray(H, dtype=np.float64)
    R = np.asarray(R, dtype=np.float64)
    _check_shape("H", H, (d, n))
    _check_shape("R", R, (d, d))
    x, P = state.x, state.P
    I = np.eye(n)  # noqa: E741 (the identity, as in the equations)

    # y = z − H x
    y = z - H @ x
    # S = H P Hᵀ + R
    S = H @ P @ H.T + R
    # K = P Hᵀ S⁻¹
    K = P @ H.T @ np.linalg.inv(S)
    # x⁺ = x + K y
    x_post = x + K @ y
    # P⁺ = (I − K H) P (I − K H)ᵀ + K R Kᵀ
    P_post = (I - K @ H) @ P @ (I - K @ H).T + K @ R @ K.T

    # log N(y; 0, S) = −½ (yᵀ S⁻¹ y + log|S| + d log 2π)
    _, log_det_S = np.linalg.slogdet(S)
    log_likelihood = -0.5 * float(y @ np.linalg.solve(S, y) + log_det_S + d * _LOG_2PI)

    return KalmanUpdate(GaussianState(x_post, P_post), _frozen(y), _frozen(S), log_likelihood)
