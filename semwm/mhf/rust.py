"""The Rust engine's existence and coverage kernels: :mod:`semwm.mhf.existence` and the
numeric part of :meth:`semwm.mhf.rates.ObservedRates.watched`, computed by the compiled
core ``semwm._core`` (``core/src/existence.rs``, ``core/src/coverage.rs``).

Same arguments, shapes and results as the Python functions, which are the
specification (``tests/engines/`` holds them equal to 1e-12). Importing it is safe
without the extension; calling it then raises
:class:`~semwm.filters.engine.EngineUnavailable`.
"""

from __future__ import annotations

import numpy as np

from semwm.filters.engine import EngineUnavailable
from semwm.filters.motion import FloatArray
from semwm.mhf.existence import Region, _bounds
from semwm.mhf.measurement import SensorView

try:
    from semwm import _core
except ImportError:  # not built: the functions below raise EngineUnavailable
    _core = None  # type: ignore[assignment]


def _require() -> None:
    if _core is None:
        raise EngineUnavailable("semwm._core is not built (docs/engines.md)")


def _f64(a: FloatArray) -> FloatArray:
    return np.asarray(a, dtype=np.float64)


def survive(
    r: FloatArray, mu: FloatArray, f: FloatArray, dt: float
) -> tuple[FloatArray, FloatArray]:
    """:func:`semwm.mhf.existence.survive`."""
    _require()
    result: tuple[FloatArray, FloatArray] = _core.survive(_f64(r), _f64(mu), _f64(f), float(dt))
    return result


def missed(r: FloatArray, p_detect: FloatArray) -> tuple[FloatArray, FloatArray]:
    """:func:`semwm.mhf.existence.missed`."""
    _require()
    result: tuple[FloatArray, FloatArray] = _core.missed(_f64(r), _f64(p_detect))
    return result


def inside_probability(
    position: FloatArray,
    covariance: FloatArray,
    region: Region | None,
    margin: FloatArray | None = None,
) -> FloatArray:
    """:func:`semwm.mhf.existence.inside_probability`."""
    count = position.shape[0]
    if region is None or count == 0:
        return np.ones(count)
    _require()
    low, high = _bounds(region)
    result: FloatArray = _core.inside_probability(
        _f64(position),
        _f64(covariance),
        low,
        high,
        None if margin is None else _f64(margin),
    )
    return result


def in_view_probability(
    position: FloatArray,
    covariance: FloatArray,
    view: SensorView,
    margin: FloatArray | None = None,
) -> FloatArray:
    """:func:`semwm.mhf.existence.in_view_probability`."""
    if position.shape[0] == 0:
        return np.ones(0)
    _require()
    result: FloatArray = _core.in_view_probability(
        _f64(position),
        _f64(covariance),
        _f64(view.position),
        float(view.heading),
        None if view.range is None else float(view.range),
        None if view.half_angle is None else float(view.half_angle),
        None if margin is None else _f64(margin),
    )
    return result


def range_coverage(
    positions: FloatArray, sensor: FloatArray, reach: float, spread: FloatArray | None = None
) -> FloatArray:
    """:func:`semwm.mhf.rates.range_coverage`."""
    _require()
    result: FloatArray = _core.range_coverage(
        _f64(positions), _f64(sensor), float(reach), None if spread is None else _f64(spread)
    )
    return result


def hull_distance(points: FloatArray, corners: FloatArray) -> FloatArray:
    """:func:`semwm.mhf.rates.hull_distance`."""
    _require()
    result: FloatArray = _core.hull_distance(_f64(points), _f64(corners))
    return result
