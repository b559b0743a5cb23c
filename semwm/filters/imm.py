"""A readable interacting multiple model (IMM) filter for one object.

This is the reference the batched IMM (:mod:`semwm.filters.batched`) is tested
against; the world model runs the batched one. It is written as the textbook
steps, each on its own lines with its equation as a comment, on top of the scalar
Kalman filter of :mod:`semwm.filters.kalman`.

Shapes (M modes, n state entries, d measured entries):

* ``x``: ``(M, n)`` mode-matched means, ``P``: ``(M, n, n)`` mode-matched
  covariances, ``mu``: ``(M,)`` mode probabilities (sum to 1);
* ``Fs``, ``Qs``: ``(M, n, n)``: each mode's transition and process noise;
* ``T``: ``(M, M)`` mode transition matrix.

Transition convention (the same everywhere in semwm, and tested):

.. math:: T_{ij} = P(\\text{mode } j \\text{ at } k \\mid \\text{mode } i \\text{ at } k-1),

so every row sums to 1 and the predicted mode probabilities are the row vector
``mu @ T`` (:math:`\\bar c_j = \\sum_i T_{ij} \\mu_i`). FilterPy's ``IMMEstimator``
computes exactly this (``cbar = dot(mu, M)``), although its docstring describes
``M`` the other way round. ``T`` applies once per prediction step, whatever the
step's length.

Reference: Bar-Shalom, Li, Kirubarajan, *Estimation with Applications to
Tracking and Navigation*, Section 11.6.6.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from semwm.filters.kalman import (
    FloatArray,
    GaussianState,
    _check_shape,
    _frozen,
    kf_predict,
    kf_update,
)


@dataclass(frozen=True)
class IMMState:
    """The mode-matched estimates of an IMM and its mode probabilities.

    Attributes
    ----------
    x
        ``(M, n)``: each mode's mean.
    P
        ``(M, n, n)``: each mode's covariance.
    mu
        ``(M,)``: the mode probabilities.

    All arrays are stored as read-only float64 copies.
    """

    x: FloatArray
    P: FloatArray
    mu: FloatArray

    def __post_init__(self) -> None:
        x = _frozen(self.x)
        P = _frozen(self.P)
        mu = _frozen(self.mu)
        if x.ndim != 2:
            raise ValueError(f"x must have shape (M, n); found shape {x.shape}")
        M, n = x.shape
        _check_shape("P", P, (M, n, n))
        _check_shape("mu", mu, (M,))
        object.__setattr__(self, "x", x)
        object.__setattr__(self, "P", P)
        object.__setattr__(self, "mu", mu)

    @property
    def modes(self) -> int:
        """``M``, the number of modes."""
        return int(self.x.shape[0])

    def mode(self, j: int) -> GaussianState:
        """Mode ``j``'s estimate as a :class:`GaussianState`."""
        return GaussianState(self.x[j], self.P[j])

    @classmethod
    def from_gaussian(cls, state: GaussianState, mu: ArrayLike) -> IMMState:
        """Every mode starting from the same estimate, with mode probabilities ``mu``."""
        M = len(np.asarray(mu))
        return cls(
            np.repeat(state.x[None, :], M, axis=0),
            np.repeat(state.P[None, :, :], M, axis=0),
            np.asarray(mu, dtype=np.float64),
        )


@dataclass(frozen=True)
class IMMUpdate:
    """The result of :func:`imm_update`.

    Attributes
    ----------
    state
        The updated mode-matched estimates and mode probabilities.
    log_likelihood
        :math:`\\log \\sum_j \\mu_j \\Lambda_j`: the measurement's density under
        the predicted mixture.
    mode_log_likelihoods
        ``(M,)``: :math:`\\log \\Lambda_j`, each mode's measurement log-likelihood.
    """

    state: IMMState
    log_likelihood: float
    mode_log_likelihoods: FloatArray


def imm_mix(state: IMMState, T: ArrayLike) -> IMMState:
    """IMM interaction (mixing): each mode's starting estimate for the next step.

    Parameters
    ----------
    state
        The posterior at step k-1.
    T
        ``(M, M)``: ``T[i, j] = P(mode j at k | mode i at k-1)``, rows sum to 1.

    Returns
    -------
    IMMState
        The mixed means and covariances, with the predicted mode probabilities
        :math:`\\bar c` as ``mu``.

    Notes
    -----
    .. math::
       \\bar c_j = \\sum_i T_{ij} \\mu_i, \\qquad
       \\omega_{ij} = T_{ij} \\mu_i / \\bar c_j

       x^0_j = \\sum_i \\omega_{ij} x_i, \\qquad
       P^0_j = \\sum_i \\omega_{ij} \\left[ P_i + (x_i - x^0_j)(x_i - x^0_j)^T \\right]

    A mode that cannot be reached (:math:`\\bar c_j = 0`) has no defined mixing
    weights; it starts from the mixture of all modes (:math:`\\omega_{ij} = \\mu_i`)
    and keeps probability 0.
    """
    M = state.modes
    T = np.asarray(T, dtype=np.float64)
    _check_shape("T", T, (M, M))
    x, P, mu = state.x, state.P, state.mu

    # c̄_j = Σ_i T_ij μ_i
    c_bar = mu @ T
    # ω_ij = T_ij μ_i / c̄_j   (ω_ij = μ_i for an unreachable mode j)
    reachable = c_bar > 0.0
    omega = np.where(
        reachable[None, :], T * mu[:, None] / np.where(reachable, c_bar, 1.0)[None, :], mu[:, None]
    )

    x0 = np.zeros_like(x)
    P0 = np.zeros_like(P)
    for j in range(M):
        # x⁰_j = Σ_i ω_ij x_i
        x0[j] = omega[:, j] @ x
        for i in range(M):
            # P⁰_j = Σ_i ω_ij [P_i + (x_i − x⁰_j)(x_i − x⁰_j)ᵀ]
            spread = x[i] - x0[j]
            P0[j] += omega[i, j] * (P[i] + np.outer(spread, spread))

    return IMMState(x0, P0, c_bar)


def imm_predict(state: IMMState, Fs: ArrayLike, Qs: ArrayLike, T: ArrayLike) -> IMMState:
    """IMM prediction: mixing (:func:`imm_mix`), then each mode's Kalman prediction.

    Parameters
    ----------
    state
        The posterior at step k-1.
    Fs, Qs
        ``(M, n, n)``: each mode's transition F_j(dt) and process noise Q_j(dt).
    T
        ``(M, M)``: ``T[i, j] = P(mode j at k | mode i at k-1)``, rows sum to 1.

    Returns
    -------
    IMMState
        The mode-matched priors at step k and the predicted mode probabilities
        ``mu @ T``.

    Notes
    -----
    .. math::
       x^-_j = F_j x^0_j, \\qquad P^-_j = F_j P^0_j F_j^T + Q_j, \\qquad
       \\mu^-_j = \\bar c_j
    """
    M = state.modes
    Fs = np.asarray(Fs, dtype=np.float64)
    Qs = np.asarray(Qs, dtype=np.float64)
    if Fs.shape[0] != M or Qs.shape[0] != M:
        raise ValueError(
            f"Fs and Qs need one matrix per mode ({M}); found {Fs.shape[0]} and {Qs.shape[0]}"
        )

    # x⁰_j, P⁰_j, c̄_j  (interaction)
    mixed = imm_mix(state, T)
    # x⁻_j = F_j x⁰_j,  P⁻_j = F_j P⁰_j F_jᵀ + Q_j  (mode-matched prediction)
    priors = [kf_predict(mixed.mode(j), Fs[j], Qs[j]) for j in range(M)]

    return IMMState(
        np.stack([prior.x for prior in priors]),
        np.stack([prior.P for prior in priors]),
        mixed.mu,
    )


def imm_update(state: IMMState, z: ArrayLike, H: ArrayLike, R: ArrayLike) -> IMMUpdate:
    """IMM update: each mode's Kalman update, then the mode probabilities.

    Parameters
    ----------
    state
        The mode-matched priors and predicted mode probabilities.
    z
        ``(d,)``: the measurement (metres).
    H
        ``(d, n)``: the measurement matrix.
    R
        ``(d, d)``: the measurement noise covariance (m^2).

    Returns
    -------
    IMMUpdate
        The posterior state, the log-likelihood of ``z`` under the mixture and
        each mode's log-likelihood.

    Notes
    -----
    .. math::
       \\Lambda_j = \\mathcal N(z - H x^-_j;\\, 0,\\, S_j), \\qquad
       c = \\sum_j \\Lambda_j \\mu^-_j, \\qquad
       \\mu^+_j = \\Lambda_j \\mu^-_j / c

    The sums are taken in log space, so far-off measurements do not underflow.
    """
    M = state.modes

    # x⁺_j, P⁺_j, log Λ_j  (mode-matched Kalman updates)
    updates = [kf_update(state.mode(j), z, H, R) for j in range(M)]
    log_Lambda = np.array([update.log_likelihood for update in updates])
    # log(Λ_j μ⁻_j)
    with np.errstate(divide="ignore"):
        log_weighted = log_Lambda + np.log(state.mu)
    # log c = log Σ_j Λ_j μ⁻_j
    top = float(np.max(log_weighted))
    log_c = top + float(np.log(np.sum(np.exp(log_weighted - top))))
    # μ⁺_j = Λ_j μ⁻_j / c
    mu_post = np.exp(log_weighted - log_c)

    posterior = IMMState(
        np.stack([update.state.x for update in updates]),
        np.stack([update.state.P for update in updates]),
        mu_post,
    )
    return IMMUpdate(posterior, log_c, _frozen(log_Lambda))


def imm_combine(state: IMMState) -> GaussianState:
    """The IMM's combined estimate: the moment-matched Gaussian of the mode mixture.

    Returns
    -------
    GaussianState
        ``x`` ``(n,)`` and ``P`` ``(n, n)``.

    Notes
    -----
    .. math::
       \\hat x = \\sum_j \\mu_j x_j, \\qquad
       \\hat P = \\sum_j \\mu_j \\left[ P_j + (x_j - \\hat x)(x_j - \\hat x)^T \\right]
    """
    x, P, mu = state.x, state.P, state.mu

    # x̂ = Σ_j μ_j x_j
    x_hat = mu @ x
    # P̂ = Σ_j μ_j [P_j + (x_j − x̂)(x_j − x̂)ᵀ]
    P_hat = np.zeros_like(P[0])
    for j in range(state.modes):
        spread = x[j] - x_hat
        P_hat += mu[j] * (P[j] + np.outer(spread, spread))

    return GaussianState(x_hat, P_hat)
