"""Shared test helpers: random scenarios, independent F/Q builders and FilterPy oracles.

The F and Q built here are written from the formulas (Kronecker products of the
one-axis matrices, the one-axis Q from FilterPy's ``Q_continuous_white_noise``), not
from :mod:`semwm.filters.motion`, so the FilterPy runs are independent of it.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np
from filterpy.common import Q_continuous_white_noise
from filterpy.kalman import IMMEstimator, KalmanFilter
from numpy.typing import NDArray

from semwm.filters.engine import Engine
from semwm.filters.factory import ClassFilter, FilterFactory
from semwm.knowledge.model import (
    ClassSpec,
    DetectorSpec,
    IMMFilterSpec,
    KalmanFilterSpec,
    KnowledgeDocument,
    MotionModelSpec,
    WorldSettings,
)
from semwm.knowledge.resolve import resolve

FloatArray = NDArray[np.float64]
Kind = Literal["kf0", "kf1", "imm"]
KINDS: tuple[Kind, ...] = ("kf0", "kf1", "imm")
RTOL = ATOL = 1e-9
"""The agreement required between implementations (and with FilterPy)."""


def assert_close(actual: object, desired: object, err_msg: str = "") -> None:
    """``actual == desired`` to the agreement tolerance (1e-9 relative or absolute)."""
    np.testing.assert_allclose(
        np.asarray(actual, dtype=float),
        np.asarray(desired, dtype=float),
        rtol=RTOL,
        atol=ATOL,
        err_msg=err_msg,
    )


def random_spd(rng: np.random.Generator, d: int, scale: float = 1.0) -> FloatArray:
    """A random symmetric positive definite d x d matrix (exactly symmetric)."""
    A = rng.normal(size=(d, d))
    S = scale * (A @ A.T / d + 0.2 * np.eye(d))
    return (S + S.T) / 2.0


def random_transition(rng: np.random.Generator, M: int) -> FloatArray:
    """A random row-stochastic M x M matrix with entries bounded away from 0."""
    T = np.asarray(rng.dirichlet(np.ones(M), size=M), dtype=np.float64) + 0.05
    normalised: FloatArray = T / T.sum(axis=1, keepdims=True)
    return normalised


def random_dt(rng: np.random.Generator) -> float:
    """A time step in (0, 0.5] s."""
    return float(0.5 - rng.uniform(0.0, 0.5))


def H_position(d: int, n: int) -> FloatArray:
    """H = [I_d 0]."""
    H = np.zeros((d, n))
    H[:, :d] = np.eye(d)
    return H


# --- F and Q from the formulas -------------------------------------------------------------


def F_first(dt: float, d: int) -> FloatArray:
    """[[I, dt I], [0, I]]."""
    return np.kron(np.array([[1.0, dt], [0.0, 1.0]]), np.eye(d))


def Q_first(dt: float, Qc: FloatArray) -> FloatArray:
    """[[dt^3/3, dt^2/2], [dt^2/2, dt]] (x) Q_c, with the one-axis block from FilterPy."""
    return np.kron(Q_continuous_white_noise(dim=2, dt=dt, spectral_density=1.0), Qc)


def F_zeroth(dt: float, d: int, with_velocity: bool) -> FloatArray:
    """I_d, or [[I, 0], [0, 0]] with a velocity that is reset."""
    reset = np.diag([1.0, 0.0]) if with_velocity else np.eye(1)
    return np.asarray(np.kron(reset, np.eye(d)), dtype=np.float64)


def Q_zeroth(dt: float, Qc: FloatArray, with_velocity: bool, sigma_v2: float) -> FloatArray:
    """dt Q_c, or [[dt Q_c, 0], [0, sigma_v^2 I]] with velocity."""
    if not with_velocity:
        return dt * Qc
    d = Qc.shape[0]
    return np.block([[dt * Qc, np.zeros((d, d))], [np.zeros((d, d)), sigma_v2 * np.eye(d)]])


# --- a random scenario ---------------------------------------------------------------------


@dataclass(frozen=True)
class Scenario:
    """One filter configuration and one random sequence of steps for it."""

    kind: Kind
    d: int
    Qcs: tuple[FloatArray, ...]  # per mode
    R: FloatArray
    T: FloatArray  # (M, M)
    mu0: FloatArray
    P0_pos: FloatArray
    P0_vel: FloatArray
    sigma_v2: float
    z0: FloatArray
    steps: tuple[tuple[float, FloatArray | None], ...]  # (dt, measurement or None)

    @property
    def modes(self) -> int:
        return len(self.Qcs)

    @property
    def with_velocity(self) -> bool:
        return self.kind != "kf0"

    @property
    def n(self) -> int:
        return 2 * self.d if self.with_velocity else self.d

    @property
    def x0(self) -> FloatArray:
        x = np.zeros(self.n)
        x[: self.d] = self.z0
        return x

    @property
    def P0(self) -> FloatArray:
        P = np.zeros((self.n, self.n))
        P[: self.d, : self.d] = self.P0_pos
        if self.with_velocity:
            P[self.d :, self.d :] = self.P0_vel
        return P

    @property
    def H(self) -> FloatArray:
        return H_position(self.d, self.n)

    def models(self, dt: float) -> tuple[FloatArray, FloatArray]:
        """(M, n, n) F and Q for a step dt, from the formulas."""
        if self.kind == "kf0":
            return F_zeroth(dt, self.d, False)[None], Q_zeroth(dt, self.Qcs[0], False, 0.0)[None]
        if self.kind == "kf1":
            return F_first(dt, self.d)[None], Q_first(dt, self.Qcs[0])[None]
        F = np.stack([F_zeroth(dt, self.d, True), F_first(dt, self.d)])
        Q = np.stack([Q_zeroth(dt, self.Qcs[0], True, self.sigma_v2), Q_first(dt, self.Qcs[1])])
        return F, Q


def make_scenario(rng: np.random.Generator, kind: Kind, d: int, length: int = 25) -> Scenario:
    """A random configuration and a random step sequence.

    Each step predicts by a dt in (0, 0.5] s and is followed by a measurement with
    probability 0.8; measurements follow a random constant-velocity truth plus noise,
    so that the likelihoods stay in a range where FilterPy's do not underflow.
    """
    M = 2 if kind == "imm" else 1
    Qcs = tuple(random_spd(rng, d, scale) for scale in rng.uniform(0.05, 2.0, size=M))
    R = random_spd(rng, d, float(rng.uniform(0.01, 0.5)))
    T = random_transition(rng, 2) if kind == "imm" else np.ones((1, 1))
    mu0 = rng.dirichlet(np.ones(M)) if kind == "imm" else np.ones(1)
    z0 = rng.normal(scale=3.0, size=d)
    position = z0.copy()
    velocity = rng.normal(size=d)
    steps: list[tuple[float, FloatArray | None]] = []
    for _ in range(length):
        dt = random_dt(rng)
        if rng.uniform() < 0.3:
            velocity = rng.normal(size=d) * rng.choice([0.0, 1.0])
        position = position + dt * velocity
        z = position + rng.multivariate_normal(np.zeros(d), R) if rng.uniform() < 0.8 else None
        steps.append((dt, z))
    return Scenario(
        kind=kind,
        d=d,
        Qcs=Qcs,
        R=R,
        T=T,
        mu0=mu0,
        P0_pos=random_spd(rng, d, 0.5),
        P0_vel=random_spd(rng, d, 1.0),
        sigma_v2=float(rng.uniform(1e-4, 1e-2)),
        z0=z0,
        steps=tuple(steps),
    )


# --- FilterPy ------------------------------------------------------------------------------


def filterpy_kf(s: Scenario, x: FloatArray, P: FloatArray) -> KalmanFilter:
    kf = KalmanFilter(dim_x=s.n, dim_z=s.d)
    kf.x = x.copy()
    kf.P = P.copy()
    kf.H = s.H
    kf.R = s.R.copy()
    return kf


def filterpy_imm(s: Scenario) -> IMMEstimator:
    filters = [filterpy_kf(s, s.x0, s.P0) for _ in range(s.modes)]
    return IMMEstimator(filters, s.mu0.copy(), s.T.copy())


# --- the factory-built ClassFilter for a scenario -----------------------------------------


def _matrix(a: FloatArray) -> tuple[tuple[float, ...], ...]:
    return tuple(tuple(float(v) for v in row) for row in a)


def class_filter(s: Scenario, engine: Engine = "python") -> ClassFilter:
    """The scenario's filter built by the factory from a resolved KnowledgeDocument,
    run by ``engine``."""
    if s.kind == "imm":
        spec: KalmanFilterSpec | IMMFilterSpec = IMMFilterSpec(
            models=(
                MotionModelSpec(motion_model="zeroth_order", system_noise=_matrix(s.Qcs[0])),
                MotionModelSpec(motion_model="first_order", system_noise=_matrix(s.Qcs[1])),
            ),
            transition_matrix=_matrix(s.T),
            initial_mode_probabilities=tuple(float(v) for v in s.mu0),
            stationary_velocity_variance=s.sigma_v2,
        )
    else:
        order = "zeroth_order" if s.kind == "kf0" else "first_order"
        spec = KalmanFilterSpec(
            model=MotionModelSpec(motion_model=order, system_noise=_matrix(s.Qcs[0]))
        )
    document = KnowledgeDocument(
        world=WorldSettings(dimension=2 if s.d == 2 else 3),
        classes=(
            ClassSpec(
                name="Thing",
                detection_frequency=1.0,
                filter=spec,
                measurement_noise=_matrix(s.R),
                initial_covariance=_matrix(s.P0_pos),
                initial_velocity_covariance=_matrix(s.P0_vel),
            ),
        ),
        detectors=(DetectorSpec(name="camera", clutter_frequency=0.1, range=10.0),),
    )
    return FilterFactory(resolve(document), engine).filter_for("Thing")
