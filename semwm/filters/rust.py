"""The Rust engine's filters: :mod:`semwm.filters.batched` and the gate of
:mod:`semwm.filters.small`, computed by the compiled core ``semwm._core``.

Same arguments, shapes and results as the numpy functions (the parity tests in
``tests/engines/`` hold them to 1e-12); arrays cross the boundary, never one Python
object per track. :func:`class_filter` hands the core a class's numeric tables once
(``F(dt) = F0 + dt F1``, ``Q(dt)`` as a polynomial, the mode transition and its
eigen-decomposition, the passive decay): knowledge and validation stay in Python.
Importing it is safe without the extension; calling it then raises
:class:`~semwm.filters.engine.EngineUnavailable`.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from semwm.filters.engine import EngineUnavailable
from semwm.filters.motion import FloatArray

try:
    from semwm import _core
except ImportError:  # not built: the functions below raise EngineUnavailable
    _core = None  # type: ignore[assignment]

if TYPE_CHECKING:
    from semwm.filters.factory import ClassFilter


def _require() -> None:
    if _core is None:
        raise EngineUnavailable("semwm._core is not built (docs/engines.md)")


def _f64(a: FloatArray) -> FloatArray:
    return np.asarray(a, dtype=np.float64)


def class_filter(flt: ClassFilter) -> _core.ClassFilter:
    """The Rust counterpart of ``flt``: its tables, built once per class filter."""
    _require()
    F0, F1, C = flt.model_coefficients
    period = None
    if flt.transition_period is not None and flt.modes > 1:
        lam, V, V_inv = flt.transition_eigen
        period = (float(flt.transition_period), _f64(lam), _f64(V), _f64(V_inv))
    decay = flt.velocity_decay if flt.state_size > flt.dim else 0.0
    result: _core.ClassFilter = _core.ClassFilter(
        flt.dim,
        _f64(F0),
        _f64(F1),
        _f64(C),
        _f64(flt.transition),
        [order == "first_order" for order in flt.orders],
        float(decay),
        period,
    )
    return result


def predict(
    core_filter: _core.ClassFilter, x: FloatArray, P: FloatArray, mu: FloatArray, dt: FloatArray
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """``ClassFilter.predict``: each object by its own ``dt`` (s)."""
    return core_filter.predict(_f64(x), _f64(P), _f64(mu), _f64(dt))


def imm_mix(
    x: FloatArray, P: FloatArray, mu: FloatArray, T: FloatArray
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """:func:`semwm.filters.batched.imm_mix`."""
    _require()
    return _core.imm_mix(_f64(x), _f64(P), _f64(mu), _f64(T))


def batched_predict(
    x: FloatArray, P: FloatArray, mu: FloatArray, F: FloatArray, Q: FloatArray, T: FloatArray
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """:func:`semwm.filters.batched.predict`."""
    _require()
    return _core.predict(_f64(x), _f64(P), _f64(mu), _f64(F), _f64(Q), _f64(T))


def update(
    x: FloatArray, P: FloatArray, mu: FloatArray, z: FloatArray, R: FloatArray
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """:func:`semwm.filters.batched.update`."""
    _require()
    return _core.update(_f64(x), _f64(P), _f64(mu), _f64(z), _f64(R))


def combine(x: FloatArray, P: FloatArray, mu: FloatArray) -> tuple[FloatArray, FloatArray]:
    """:func:`semwm.filters.batched.combine`."""
    _require()
    return _core.combine(_f64(x), _f64(P), _f64(mu))


def mahalanobis_squared(residual: FloatArray, covariance: FloatArray) -> FloatArray:
    """:func:`semwm.filters.small.mahalanobis_squared` for ``(K, d)`` and ``(K, d, d)``."""
    _require()
    return _core.mahalanobis_squared(_f64(residual), _f64(covariance))
