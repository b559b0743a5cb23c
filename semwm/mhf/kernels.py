"""The existence and coverage kernels of one engine, chosen once per filter.

:class:`ExistenceKernels` names the numeric functions of the missed-detection model
(docs/knowledge.md, "What semwm concludes from not seeing something"):
:func:`~semwm.mhf.existence.survive`, :func:`~semwm.mhf.existence.missed`,
:func:`~semwm.mhf.existence.inside_probability`,
:func:`~semwm.mhf.existence.in_view_probability`, and the coverage of
:meth:`~semwm.mhf.rates.ObservedRates.watched` (:func:`~semwm.mhf.rates.range_coverage`,
:func:`~semwm.mhf.rates.hull_distance`). ``engine="python"`` runs those functions, the
specification; ``engine="rust"`` their counterparts in the compiled core
(:mod:`semwm.mhf.rust`). The MHF asks :func:`existence_kernels` once and calls through
it, as the filters ask :class:`~semwm.filters.factory.FilterFactory`.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from semwm.filters.engine import Engine
from semwm.filters.motion import FloatArray
from semwm.mhf import existence, rates
from semwm.mhf.existence import Region
from semwm.mhf.measurement import SensorView


@dataclass(frozen=True, slots=True)
class ExistenceKernels:
    """One engine's existence and coverage kernels (same signatures as the Python
    functions they are named after)."""

    engine: Engine
    survive: Callable[[FloatArray, FloatArray, FloatArray, float], tuple[FloatArray, FloatArray]]
    missed: Callable[[FloatArray, FloatArray], tuple[FloatArray, FloatArray]]
    inside_probability: Callable[
        [FloatArray, FloatArray, Region | None, FloatArray | None], FloatArray
    ]
    in_view_probability: Callable[
        [FloatArray, FloatArray, SensorView, FloatArray | None], FloatArray
    ]
    range_coverage: rates.RangeCoverage
    hull_distance: rates.HullDistance


PYTHON_KERNELS = ExistenceKernels(
    "python",
    existence.survive,
    existence.missed,
    existence.inside_probability,
    existence.in_view_probability,
    rates.range_coverage,
    rates.hull_distance,
)
"""The specification."""


def existence_kernels(engine: Engine) -> ExistenceKernels:
    """The kernels of ``engine`` (``"rust"`` needs the extension; resolve the engine
    first with :func:`semwm.filters.engine.resolve_engine`)."""
    if engine == "python":
        return PYTHON_KERNELS
    from semwm.mhf import rust

    rust._require()
    return ExistenceKernels(
        "rust",
        rust.survive,
        rust.missed,
        rust.inside_probability,
        rust.in_view_probability,
        rust.range_coverage,
        rust.hull_distance,
    )
