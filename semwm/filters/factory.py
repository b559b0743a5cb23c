"""The filter factory: the one place that reads class knowledge and builds filters.

``FilterFactory(knowledge).filter_for("Person")`` gives a :class:`ClassFilter`: a
Kalman filter (one mode) or an IMM (several modes) with its motion models,
noise and initial state, as batched operations over many objects of the class.

``FilterFactory(knowledge, engine="rust")`` runs the same operations in the Rust core
(:mod:`semwm.filters.rust`): the factory and each class filter are the one place that
chooses the engine; their callers do not know which runs.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from semwm.filters import batched, rust, small
from semwm.filters.engine import Engine
from semwm.filters.motion import (
    FloatArray,
    MotionOrder,
    decay_factors,
    process_noise_coefficients,
    transition_coefficients,
)
from semwm.knowledge.model import IMMFilterSpec, Knowledge, ResolvedClass

if TYPE_CHECKING:
    from semwm import _core


@dataclass(frozen=True, eq=False)
class ClassFilter:
    """The filter of one class, batched over objects (see :mod:`semwm.filters.batched`).

    Attributes
    ----------
    orders
        The motion model of each mode; one mode for a Kalman filter.
    spectral_densities
        ``(M, d, d)``: each mode's system noise Q_c.
    transition
        ``(M, M)``: ``T[i, j] = P(mode j at k | mode i at k-1)``.
    transition_period
        The time step (s) ``transition`` is stated for; ``None``: one prediction step.
    engine
        ``"python"`` (:mod:`semwm.filters.batched`) or ``"rust"``
        (:mod:`semwm.filters.rust`): who computes :meth:`predict`, :meth:`update` and
        :meth:`combine`.
    initial_mode_probabilities
        ``(M,)``.
    initial_covariance
        ``(n, n)``: covariance of a new object's state.
    """

    class_name: str
    dim: int
    orders: tuple[MotionOrder, ...]
    spectral_densities: FloatArray
    transition: FloatArray
    initial_mode_probabilities: FloatArray
    initial_covariance: FloatArray
    stationary_velocity_variance: float = 0.0
    with_velocity: bool = field(default=False)
    velocity_decay: float = 0.0
    transition_period: float | None = None
    engine: Engine = "python"

    @property
    def modes(self) -> int:
        return len(self.orders)

    @property
    def state_size(self) -> int:
        return int(self.initial_covariance.shape[0])

    @cached_property
    def mode_names(self) -> tuple[str, ...]:
        """Each mode's name as a world object's ``mode_probabilities`` gives it: its
        motion model, numbered (``cv_0``, ``cv_1``) where two modes share one."""
        orders = list(self.orders)
        return tuple(o if orders.count(o) == 1 else f"{o}_{j}" for j, o in enumerate(self.orders))

    def initial_states(self, z: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
        """New objects at measured positions ``z`` ``(K, d)``, zero velocity (paper 002 III-A)."""
        K = z.shape[0]
        x = np.zeros((K, self.modes, self.state_size))
        x[:, :, : self.dim] = z[:, None, :]
        P = np.empty((K, self.modes, *self.initial_covariance.shape))
        P[...] = self.initial_covariance
        mu = np.empty((K, self.modes))
        mu[...] = self.initial_mode_probabilities
        return x, P, mu

    @cached_property
    def _transition_eigen(self) -> tuple[FloatArray, FloatArray, FloatArray]:
        """``T = V diag(lam) V^-1`` (real, ``lam > 0``: checked with the knowledge)."""
        lam, V = np.linalg.eig(self.transition)
        return lam.real, V.real, np.linalg.inv(V).real

    def transitions(self, dt: FloatArray) -> FloatArray:
        r"""The mode transition over each object's step ``dt``: ``(M, M)`` once per
        prediction step (paper 002), or with ``transition_period`` ``(N, M, M)``:

        .. math:: T(\Delta) = T^{\Delta / \Delta_T} = V \operatorname{diag}
           (\lambda^{\Delta / \Delta_T}) V^{-1}

        (a continuous-time Markov chain that is ``T`` after one period), so that how
        often the modes mix does not depend on how often scans come.
        """
        if self.transition_period is None or self.modes == 1:
            return self.transition
        lam, V, V_inv = self._transition_eigen
        steps = np.asarray(dt, dtype=float) / self.transition_period
        powers = lam[None, :] ** steps[:, None]  # (N, M)
        result: FloatArray = np.einsum("ik,nk,kj->nij", V, powers, V_inv)
        result = np.clip(result, 0.0, 1.0)
        result /= result.sum(axis=2, keepdims=True)
        return result

    @property
    def transition_eigen(self) -> tuple[FloatArray, FloatArray, FloatArray]:
        """``lam, V, V^-1`` of ``T = V diag(lam) V^-1``."""
        return self._transition_eigen

    @property
    def model_coefficients(self) -> tuple[FloatArray, FloatArray, FloatArray]:
        """``F0, F1`` ``(M, n, n)`` and ``C`` ``(4, M, n, n)`` (see :meth:`models`)."""
        return self._model_coefficients

    @cached_property
    def _rust(self) -> _core.ClassFilter:
        """This filter's tables in the Rust core, made on first use."""
        return rust.class_filter(self)

    @cached_property
    def _model_coefficients(self) -> tuple[FloatArray, FloatArray, FloatArray]:
        """``F0, F1`` ``(M, n, n)`` and ``C`` ``(4, M, n, n)``: ``F(dt) = F0 + dt F1`` and
        ``Q(dt) = sum_k dt^k C[k]`` per mode (:mod:`semwm.filters.motion`)."""
        pairs = [
            transition_coefficients(order, self.dim, self.with_velocity) for order in self.orders
        ]
        C = [
            process_noise_coefficients(
                order, self.dim, Qc, self.with_velocity, self.stationary_velocity_variance
            )
            for order, Qc in zip(self.orders, self.spectral_densities, strict=True)
        ]
        return (
            np.array([F0 for F0, _ in pairs]),
            np.array([F1 for _, F1 in pairs]),
            np.stack(C, axis=1),
        )

    def models(self, dt: FloatArray) -> tuple[FloatArray, FloatArray]:
        """F and Q per object and mode for time steps ``dt``; each ``(N, M, n, n)``.

        .. math:: F(\\Delta) = F_0 + \\Delta F_1, \\quad
           Q(\\Delta) = C_0 + \\Delta (C_1 + \\Delta (C_2 + \\Delta C_3))
        """
        F0, F1, C = self._model_coefficients
        t = np.asarray(dt, dtype=float)[:, None, None, None]
        F = F0 + t * F1
        Q = C[0] + t * (C[1] + t * (C[2] + t * C[3]))
        return F, Q

    @cached_property
    def _random_walk(self) -> tuple[FloatArray, FloatArray] | None:
        """``(C0, C1)`` when the filter is one mode with ``F(dt) = I`` and
        ``Q(dt) = C0 + dt C1`` (a zeroth-order Kalman filter), else ``None``."""
        if self.modes != 1:
            return None
        F0, F1, C = self._model_coefficients
        identity = np.eye(self.state_size)
        if np.any(F1 != 0.0) or np.any(F0[0] != identity) or np.any(C[2:] != 0.0):
            return None
        return C[0], C[1]

    def predict(
        self, x: FloatArray, P: FloatArray, mu: FloatArray, dt: FloatArray
    ) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Predict each object by its own ``dt`` (s). Objects with ``dt <= 0`` are left as
        they are: no time passes, so no mode transition either."""
        if self.engine == "rust":
            return rust.predict(self._rust, x, P, mu, dt)
        moving = dt > 0.0
        walk = self._random_walk
        if walk is not None:
            # zeroth order, one mode: x- = x, P- = P + Q(dt) (the general equations with
            # F = I, without their matrix products)
            C0, C1 = walk
            steps = np.where(moving, dt, 0.0)[:, None, None, None]
            Q = np.where(moving[:, None, None, None], C0 + steps * C1, 0.0)
            return x.copy(), P + Q, mu.copy()
        if self.velocity_decay > 0.0 and self.state_size > self.dim:
            return self._predict_decaying(x, P, mu, dt, moving)
        if moving.all():
            F, Q = self.models(dt)
            return batched.predict(x, P, mu, F, Q, self.transitions(dt))
        x, P, mu = x.copy(), P.copy(), mu.copy()
        if moving.any():
            F, Q = self.models(dt[moving])
            x[moving], P[moving], mu[moving] = batched.predict(
                x[moving], P[moving], mu[moving], F, Q, self.transitions(dt[moving])
            )
        return x, P, mu

    def _predict_decaying(
        self,
        x: FloatArray,
        P: FloatArray,
        mu: FloatArray,
        dt: FloatArray,
        moving: NDArray[np.bool_],
    ) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Prediction of a passive object whose speed decays (:func:`decay_factors`).

        After the IMM mixing, each first-order mode's mean moves by the exact decayed
        motion (``p + g v``, ``k v``). The covariance is carried by the same linear map
        evaluated at the speed ``sqrt(|v|^2 + tr P_vv)`` (mean speed and its spread), so
        that an object at rest with an uncertain velocity still passes that uncertainty
        on to its position (the map's Jacobian vanishes at ``v = 0``).
        """
        x, P, mu = x.copy(), P.copy(), mu.copy()
        if not moving.any():
            return x, P, mu
        d = self.dim
        xs, Ps, mus, dts = x[moving], P[moving], mu[moving], dt[moving]
        F, Q = self.models(dts)
        x0, P0, cbar = batched.imm_mix(xs, Ps, mus, self.transitions(dts))
        F_mean, F_cov = F.copy(), F.copy()
        eye = np.eye(d)
        for m, order in enumerate(self.orders):
            if order != "first_order":
                continue
            v = x0[:, m, d:]
            speed = np.linalg.norm(v, axis=1)
            spread = np.sqrt(speed**2 + np.trace(P0[:, m, d:, d:], axis1=1, axis2=2))
            for target, s in ((F_mean, speed), (F_cov, spread)):
                g, k = decay_factors(s, dts, self.velocity_decay)
                target[:, m, :d, d:] = g[:, None, None] * eye
                target[:, m, d:, d:] = k[:, None, None] * eye
        x[moving] = np.einsum("nmij,nmj->nmi", F_mean, x0)
        P[moving] = F_cov @ P0 @ np.swapaxes(F_cov, -1, -2) + Q
        mu[moving] = cbar
        return x, P, mu

    def update(
        self, x: FloatArray, P: FloatArray, mu: FloatArray, z: FloatArray, R: FloatArray
    ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
        """Update with measured positions; see :func:`semwm.filters.batched.update`."""
        return update_with(self.engine, x, P, mu, z, R)

    def combine(
        self, x: FloatArray, P: FloatArray, mu: FloatArray
    ) -> tuple[FloatArray, FloatArray]:
        """Combined mean ``(N, n)`` and covariance ``(N, n, n)``."""
        return combine_with(self.engine, x, P, mu)


def update_with(
    engine: Engine, x: FloatArray, P: FloatArray, mu: FloatArray, z: FloatArray, R: FloatArray
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """The Kalman / IMM update of any filter shape (:func:`batched.update`) by ``engine``."""
    if engine == "rust":
        return rust.update(x, P, mu, z, R)
    return batched.update(x, P, mu, z, R)


def combine_with(
    engine: Engine, x: FloatArray, P: FloatArray, mu: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """The combined estimate of any filter shape (:func:`batched.combine`) by ``engine``."""
    if engine == "rust":
        return rust.combine(x, P, mu)
    return batched.combine(x, P, mu)


class FilterFactory:
    """Builds and caches each class's :class:`ClassFilter` and measurement noise, and runs
    the filter steps that do not depend on the class (an update, the combined estimate,
    the gate) with its ``engine``."""

    def __init__(self, knowledge: Knowledge, engine: Engine = "python") -> None:
        self.knowledge = knowledge
        self.engine: Engine = engine
        self._filters: dict[str, ClassFilter] = {}
        self._noise: dict[tuple[str, str], FloatArray] = {}

    @cached_property
    def dim(self) -> int:
        return self.knowledge.world.dimension

    def filter_for(self, class_name: str) -> ClassFilter:
        built = self._filters.get(class_name)
        if built is None:
            built = build_class_filter(self.knowledge.classes[class_name], self.dim, self.engine)
            self._filters[class_name] = built
        return built

    def update(
        self, x: FloatArray, P: FloatArray, mu: FloatArray, z: FloatArray, R: FloatArray
    ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
        """The Kalman / IMM update of any filter shape (:func:`batched.update`)."""
        return update_with(self.engine, x, P, mu, z, R)

    def combine(
        self, x: FloatArray, P: FloatArray, mu: FloatArray
    ) -> tuple[FloatArray, FloatArray]:
        """The combined estimate of any filter shape (:func:`batched.combine`)."""
        return combine_with(self.engine, x, P, mu)

    def mahalanobis_squared(self, residual: FloatArray, covariance: FloatArray) -> FloatArray:
        """The gate's :math:`r^T C^{-1} r` of ``(K, d)`` residuals and ``(K, d, d)``
        covariances (:func:`small.mahalanobis_squared`)."""
        if self.engine == "rust":
            return rust.mahalanobis_squared(residual, covariance)
        return small.mahalanobis_squared(residual, covariance)

    def measurement_noise(self, class_name: str, detector: str) -> FloatArray:
        """R for a class seen by a detector: the detector's per-class noise if it sets one
        (for the class or its nearest ancestor), else the class's own. Made once per
        pair and shared by every detection: read-only."""
        known = self._noise.get((class_name, detector))
        if known is not None:
            return known
        spec = self.knowledge.detectors[detector]
        resolved = self.knowledge.classes[class_name]
        noise = next(
            (
                spec.measurement_noise[name]
                for name in (class_name, *resolved.ancestors)
                if name in spec.measurement_noise
            ),
            resolved.measurement_noise,
        )
        R = np.array(noise, dtype=float)
        R.setflags(write=False)
        self._noise[(class_name, detector)] = R
        return R


def build_class_filter(resolved: ResolvedClass, dim: int, engine: Engine = "python") -> ClassFilter:
    """Turn a resolved class into its filter (paper 002 IV-B), run by ``engine``."""
    spec = resolved.filter
    if isinstance(spec, IMMFilterSpec):
        orders = tuple(m.motion_model for m in spec.models)
        densities = np.array([m.system_noise for m in spec.models], dtype=float)
        transition = np.array(spec.transition_matrix, dtype=float)
        modes = len(orders)
        initial_mu = (
            np.array(spec.initial_mode_probabilities, dtype=float)
            if spec.initial_mode_probabilities is not None
            else np.full(modes, 1.0 / modes)
        )
        with_velocity = True
        stationary = spec.stationary_velocity_variance
        period = spec.transition_period
    else:
        orders = (spec.model.motion_model,)
        densities = np.array([spec.model.system_noise], dtype=float)
        transition = np.ones((1, 1))
        initial_mu = np.ones(1)
        with_velocity = spec.model.motion_model == "first_order"
        stationary = 0.0
        period = None
    n = 2 * dim if with_velocity else dim
    P0 = np.zeros((n, n))
    P0[:dim, :dim] = np.asarray(resolved.initial_covariance, dtype=float)
    if with_velocity:
        P0[dim:, dim:] = np.asarray(resolved.initial_velocity_covariance, dtype=float)
    return ClassFilter(
        class_name=resolved.name,
        dim=dim,
        orders=orders,
        spectral_densities=densities,
        transition=transition,
        initial_mode_probabilities=initial_mu,
        initial_covariance=P0,
        stationary_velocity_variance=stationary,
        with_velocity=with_velocity,
        velocity_decay=resolved.velocity_decay if with_velocity else 0.0,
        transition_period=period,
        engine=engine,
    )
