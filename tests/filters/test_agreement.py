"""Random predict/update sequences through FilterPy, the scalar filters, the batched
functions and the factory-built ClassFilter: all must agree to 1e-9.

Filters: a zeroth-order Kalman filter, a first-order Kalman filter and an IMM of a
zeroth-order (velocity reset) and a first-order model with a random row-stochastic
transition matrix, in 2D and 3D. Compared after every predict and every update:
mode-matched means and covariances, mode probabilities, the combined estimate and
the measurement log-likelihood (FilterPy: ``kf.log_likelihood``; for the IMM
``log(cbar @ imm.likelihood)``).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
import pytest

from semwm.filters import batched
from semwm.filters.engine import Engine, rust_core, rust_core_error
from semwm.filters.imm import IMMState, imm_combine, imm_predict, imm_update
from semwm.filters.kalman import GaussianState, kf_predict, kf_update

from ._oracle import (
    KINDS,
    Scenario,
    assert_close,
    class_filter,
    filterpy_imm,
    filterpy_kf,
    make_scenario,
)

Record = dict[str, Any]
SEEDS = (0, 1, 2, 3)


def _record(x: object, P: object, mu: object, xc: object, Pc: object, ll: float | None) -> Record:
    return {
        "x": np.array(x, dtype=float),
        "P": np.array(P, dtype=float),
        "mu": np.array(mu, dtype=float),
        "x_combined": np.array(xc, dtype=float),
        "P_combined": np.array(Pc, dtype=float),
        "log_likelihood": ll,
    }


def run_filterpy(s: Scenario) -> list[Record]:
    records: list[Record] = []
    if s.kind != "imm":
        kf = filterpy_kf(s, s.x0, s.P0)
        for dt, z in s.steps:
            F, Q = s.models(dt)
            kf.F, kf.Q = F[0], Q[0]
            kf.predict()
            records.append(_record(kf.x[None], kf.P[None], [1.0], kf.x, kf.P, None))
            if z is not None:
                kf.update(z)
                ll = float(kf.log_likelihood)
                records.append(_record(kf.x[None], kf.P[None], [1.0], kf.x, kf.P, ll))
        return records
    imm = filterpy_imm(s)
    for dt, z in s.steps:
        F, Q = s.models(dt)
        for j, f in enumerate(imm.filters):
            f.F, f.Q = F[j], Q[j]
        imm.predict()
        # FilterPy keeps the posterior in imm.mu after predict: the predicted mode
        # probabilities are imm.cbar (and imm.x there is weighted by the old mu).
        c_bar = imm.cbar.copy()
        xs = np.stack([f.x for f in imm.filters])
        Ps = np.stack([f.P for f in imm.filters])
        xc, Pc = batched.combine(xs[None], Ps[None], c_bar[None])
        records.append(_record(xs, Ps, c_bar, xc[0], Pc[0], None))
        if z is not None:
            imm.update(z)
            ll = float(np.log(c_bar @ imm.likelihood))
            xs = np.stack([f.x for f in imm.filters])
            Ps = np.stack([f.P for f in imm.filters])
            records.append(_record(xs, Ps, imm.mu, imm.x, imm.P, ll))
        else:
            # FilterPy's IMM moves the mode probabilities only in update(): a predict
            # without an update would mix again with the old posterior. A step with no
            # measurement carries the predicted probabilities over, as update() would
            # with equal likelihoods.
            imm.mu = c_bar
            imm._compute_mixing_probabilities()
    return records


def run_scalar_kf(s: Scenario) -> list[Record]:
    records: list[Record] = []
    state = GaussianState(s.x0, s.P0)
    for dt, z in s.steps:
        F, Q = s.models(dt)
        state = kf_predict(state, F[0], Q[0])
        records.append(_record(state.x[None], state.P[None], [1.0], state.x, state.P, None))
        if z is not None:
            result = kf_update(state, z, s.H, s.R)
            state = result.state
            ll = result.log_likelihood
            records.append(_record(state.x[None], state.P[None], [1.0], state.x, state.P, ll))
    return records


def run_scalar_imm(s: Scenario) -> list[Record]:
    records: list[Record] = []
    state = IMMState.from_gaussian(GaussianState(s.x0, s.P0), s.mu0)
    for dt, z in s.steps:
        F, Q = s.models(dt)
        state = imm_predict(state, F, Q, s.T)
        c = imm_combine(state)
        records.append(_record(state.x, state.P, state.mu, c.x, c.P, None))
        if z is not None:
            result = imm_update(state, z, s.H, s.R)
            state = result.state
            c = imm_combine(state)
            records.append(_record(state.x, state.P, state.mu, c.x, c.P, result.log_likelihood))
    return records


def run_batched(s: Scenario) -> list[Record]:
    records: list[Record] = []
    x = np.repeat(s.x0[None, None], s.modes, axis=1)
    P = np.repeat(s.P0[None, None], s.modes, axis=1)
    mu = s.mu0[None].copy()
    for dt, z in s.steps:
        F, Q = s.models(dt)
        x, P, mu = batched.predict(x, P, mu, F[None], Q[None], s.T)
        xc, Pc = batched.combine(x, P, mu)
        records.append(_record(x[0], P[0], mu[0], xc[0], Pc[0], None))
        if z is not None:
            x, P, mu, ll = batched.update(x, P, mu, z[None], s.R[None])
            xc, Pc = batched.combine(x, P, mu)
            records.append(_record(x[0], P[0], mu[0], xc[0], Pc[0], float(ll[0])))
    return records


def run_class_filter(s: Scenario, engine: Engine = "python") -> list[Record]:
    records: list[Record] = []
    cf = class_filter(s, engine)
    x, P, mu = cf.initial_states(s.z0[None])
    np.testing.assert_allclose(x[0, 0], s.x0, rtol=0, atol=0)
    np.testing.assert_allclose(P[0, 0], s.P0, rtol=0, atol=0)
    for dt, z in s.steps:
        x, P, mu = cf.predict(x, P, mu, np.array([dt]))
        xc, Pc = cf.combine(x, P, mu)
        records.append(_record(x[0], P[0], mu[0], xc[0], Pc[0], None))
        if z is not None:
            x, P, mu, ll = cf.update(x, P, mu, z[None], s.R[None])
            xc, Pc = cf.combine(x, P, mu)
            records.append(_record(x[0], P[0], mu[0], xc[0], Pc[0], float(ll[0])))
    return records


RUNNERS: dict[str, Callable[[Scenario], list[Record]]] = {
    "scalar": lambda s: run_scalar_imm(s) if s.kind == "imm" else run_scalar_kf(s),
    "scalar_imm": run_scalar_imm,
    "batched": run_batched,
    "class_filter": run_class_filter,
    # the Rust engine's kernels (semwm._core) behind the same ClassFilter
    "class_filter_rust": lambda s: run_class_filter(s, "rust"),
}


def max_disagreement(ours: list[Record], oracle: list[Record]) -> float:
    """The largest absolute difference over every compared quantity (for the report)."""
    worst = 0.0
    for a, b in zip(ours, oracle, strict=True):
        for key in a:
            if a[key] is not None:
                worst = max(worst, float(np.max(np.abs(np.asarray(a[key]) - b[key]))))
    return worst


def assert_records_agree(ours: list[Record], oracle: list[Record]) -> None:
    assert len(ours) == len(oracle)
    for step, (a, b) in enumerate(zip(ours, oracle, strict=True)):
        for key in a:
            if b[key] is None:
                assert a[key] is None, f"step {step}: {key}"
                continue
            assert_close(a[key], b[key], err_msg=f"step {step}: {key}")


@pytest.mark.parametrize("runner", sorted(RUNNERS))
@pytest.mark.parametrize("d", [2, 3])
@pytest.mark.parametrize("kind", KINDS)
@pytest.mark.parametrize("seed", SEEDS)
def test_agrees_with_filterpy(seed: int, kind: str, d: int, runner: str) -> None:
    if runner.endswith("_rust") and rust_core() is None:
        pytest.skip(f"the Rust core semwm._core is not built ({rust_core_error()})")
    s = make_scenario(np.random.default_rng([seed, d, KINDS.index(kind)]), kind, d)  # type: ignore[arg-type]
    oracle = run_filterpy(s)
    assert sum(r["log_likelihood"] is not None for r in oracle) > 5
    assert_records_agree(RUNNERS[runner](s), oracle)


def test_scenarios_exercise_both_modes() -> None:
    """The IMM sequences are not degenerate: both modes keep a real share of probability
    and the log-likelihoods differ between modes, so the comparisons test the mixing."""
    s = make_scenario(np.random.default_rng([0, 2, 2]), "imm", 2)
    mus = np.array([r["mu"] for r in run_filterpy(s)])
    assert mus.min() < 0.9 and mus.max() > 0.1
    assert np.ptp(mus[:, 0]) > 0.05


def test_filterpy_oracle_detects_a_wrong_filter() -> None:
    """The comparison can fail: a filter with a transposed transition matrix disagrees."""
    s = make_scenario(np.random.default_rng(7), "imm", 2)
    wrong = Scenario(**{**s.__dict__, "T": s.T.T / s.T.T.sum(axis=1, keepdims=True)})
    with pytest.raises(AssertionError):
        assert_records_agree(run_batched(wrong), run_filterpy(s))
