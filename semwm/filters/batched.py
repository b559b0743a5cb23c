"""Batched Kalman and IMM steps: N objects predicted, updated and gated in one call.

A Kalman filter is handled as an IMM with one mode, so there is one code path.
Shapes (N objects, M modes, n state entries, d measured position entries):

* ``x``: ``(N, M, n)`` mode-matched means, ``P``: ``(N, M, n, n)`` covariances,
* ``mu``: ``(N, M)`` mode probabilities,
* ``z``: ``(N, d)`` measured positions, ``R``: ``(N, d, d)`` measurement noise.

The measurement matrix is ``H = [I_d 0]``: the position is measured.

IMM convention (stated once, tested): ``T[i, j] = P(mode j at k | mode i at k-1)``;
rows sum to 1.

References: Bar-Shalom, Li, Kirubarajan, *Estimation with Applications to
Tracking and Navigation*, Section 11.6.6 (IMM); FilterPy's ``KalmanFilter`` and
``IMMEstimator`` are the oracles these functions are tested against.
"""

from __future__ import annotations

import functools

import numpy as np
from numpy.typing import NDArray

from semwm.filters.small import inverse_and_log_det, mahalanobis_squared, quadratic_form

__all__ = ["combine", "imm_mix", "mahalanobis_squared", "predict", "update"]

FloatArray = NDArray[np.float64]
_LOG_2PI = float(np.log(2.0 * np.pi))


def imm_mix(
    x: FloatArray, P: FloatArray, mu: FloatArray, T: FloatArray
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """IMM interaction (mixing) step.

    .. math::
       \\bar c_j = \\sum_i T_{ij} \\mu_i, \\quad
       \\omega_{ij} = T_{ij} \\mu_i / \\bar c_j, \\quad
       x^0_j = \\sum_i \\omega_{ij} x_i, \\quad
       P^0_j = \\sum_i \\omega_{ij} [P_i + (x_i - x^0_j)(x_i - x^0_j)^T]

    Returns the mixed means and covariances and the predicted mode probabilities
    :math:`\\bar c`. ``T`` is ``(M, M)``, or ``(N, M, M)`` (one per object: a
    transition over each object's own time step).
    """
    if x.shape[1] == 1:
        return x, P, mu
    T3 = T[None, :, :] if T.ndim == 2 else T
    cbar = (mu[:, None, :] @ T3)[:, 0, :]  # (N, j)
    reachable = cbar > 0.0
    omega = T3 * mu[:, :, None] / np.where(reachable, cbar, 1.0)[:, None, :]
    # a mode nobody can reach starts from the mixture (its probability is 0 anyway)
    omega = np.where(reachable[:, None, :], omega, mu[:, :, None])  # (N, i, j)
    x0 = np.swapaxes(omega, 1, 2) @ x  # (N, j, n)
    spread = x[:, :, None, :] - x0[:, None, :, :]  # (N, i, j, n)
    # matmul and broadcasting, not einsum: a few µs less per call on tiny stacks
    outer = spread[..., :, None] * spread[..., None, :]  # (N, i, j, n, n)
    P0 = (omega[:, :, :, None, None] * (P[:, :, None] + outer)).sum(axis=1)
    return x0, P0, cbar


def predict(
    x: FloatArray,
    P: FloatArray,
    mu: FloatArray,
    F: FloatArray,
    Q: FloatArray,
    T: FloatArray,
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """IMM prediction: mixing, then each mode's Kalman prediction.

    Parameters
    ----------
    F, Q
        ``(N, M, n, n)``: per object and mode transition and process noise.

    .. math:: x^-_j = F_j x^0_j, \\qquad P^-_j = F_j P^0_j F_j^T + Q_j
    """
    x0, P0, cbar = imm_mix(x, P, mu, T)
    x_pred = np.einsum("nmij,nmj->nmi", F, x0)
    P_pred = F @ P0 @ np.swapaxes(F, -1, -2) + Q
    return x_pred, P_pred, cbar


def update(
    x: FloatArray, P: FloatArray, mu: FloatArray, z: FloatArray, R: FloatArray
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """IMM update: each mode's Kalman update (Joseph form), then the mode probabilities.

    .. math::
       y_j = z - H x_j, \\quad S_j = H P_j H^T + R, \\quad K_j = P_j H^T S_j^{-1}

       x^+_j = x_j + K_j y_j, \\quad
       P^+_j = (I - K_j H) P_j (I - K_j H)^T + K_j R K_j^T

       \\Lambda_j = \\mathcal N(y_j; 0, S_j), \\quad
       \\mu^+_j = \\mu_j \\Lambda_j / \\sum_i \\mu_i \\Lambda_i

    Returns
    -------
    x, P, mu
        The updated mode-matched states and mode probabilities.
    log_likelihood
        ``(N,)``: :math:`\\log \\sum_j \\mu_j \\Lambda_j`, the measurement's density
        under the predicted mixture.
    """
    N, M, n = x.shape
    d = z.shape[-1]
    y = z[:, None, :] - x[:, :, :d]  # (N, M, d)
    PHt = P[:, :, :, :d]  # (N, M, n, d)
    S = P[:, :, :d, :d] + R[:, None, :, :]  # (N, M, d, d)
    S_inv, log_det = inverse_and_log_det(S)  # closed form for d <= 2 (semwm.filters.small)
    # K = P H^T S^-1
    K = PHt @ S_inv  # (N, M, n, d)
    x_new = x + np.einsum("nmid,nmd->nmi", K, y)
    IKH = np.empty((N, M, n, n))
    IKH[...] = _identity(n)
    IKH[:, :, :, :d] -= K
    P_new = IKH @ P @ np.swapaxes(IKH, -1, -2) + K @ R[:, None, :, :] @ np.swapaxes(K, -1, -2)
    # log N(y; 0, S)
    log_lam = -0.5 * (quadratic_form(y, S_inv) + log_det + d * _LOG_2PI)  # (N, M)
    if M == 1:  # a Kalman filter: one mode, probability 1
        return x_new, P_new, np.ones((N, 1)), log_lam[:, 0]
    log_weighted = log_lam + np.log(np.maximum(mu, 1e-300))
    top = log_weighted.max(axis=1, keepdims=True)
    log_total = top[:, 0] + np.log(np.exp(log_weighted - top).sum(axis=1))
    mu_new = np.exp(log_weighted - log_total[:, None])
    return x_new, P_new, mu_new, log_total


@functools.cache
def _identity(n: int) -> FloatArray:
    identity = np.eye(n)
    identity.flags.writeable = False
    return identity


def combine(x: FloatArray, P: FloatArray, mu: FloatArray) -> tuple[FloatArray, FloatArray]:
    """The IMM's combined estimate: moment-matched mixture of the modes.

    .. math:: \\hat x = \\sum_j \\mu_j x_j, \\quad
       \\hat P = \\sum_j \\mu_j [P_j + (x_j - \\hat x)(x_j - \\hat x)^T]
    """
    if x.shape[1] == 1:
        return x[:, 0], P[:, 0]
    x_hat = np.einsum("nm,nmi->ni", mu, x)
    spread = x - x_hat[:, None, :]
    P_hat = np.einsum("nm,nmij->nij", mu, P) + np.einsum("nm,nmi,nmj->nij", mu, spread, spread)
    return x_hat, P_hat
