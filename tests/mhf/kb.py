"""Knowledge bases for the MHF tests, built in Python (2D, static zeroth-order Kalman classes)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from semwm.knowledge.model import (
    AppearanceRelation,
    ClassSpec,
    DetectorSpec,
    KalmanFilterSpec,
    Knowledge,
    KnowledgeDocument,
    KnownObject,
    MotionModelSpec,
    WorldSettings,
)
from semwm.knowledge.resolve import resolve


def diag(value: float, dim: int = 2) -> tuple[tuple[float, ...], ...]:
    return tuple(tuple(value if r == c else 0.0 for c in range(dim)) for r in range(dim))


def static_class(
    name: str,
    *,
    is_a: Sequence[str] = (),
    f_existing: float = 1.0,
    f_new: float = 0.1,
    r: float = 0.09,
    p0: float | None = None,
    qc: float = 0.01,
    p_max: float | None = None,
    t_max: float | None = None,
    appearance: Sequence[AppearanceRelation] | None = None,
) -> ClassSpec:
    """A class with a zeroth-order Kalman filter: R = r I, P0 = p0 I, Qc = qc I."""
    return ClassSpec(
        name=name,
        is_a=tuple(is_a),
        detection_frequency=f_existing,
        new_frequency=f_new,
        filter=KalmanFilterSpec(
            model=MotionModelSpec(motion_model="zeroth_order", system_noise=diag(qc))
        ),
        measurement_noise=diag(r),
        initial_covariance=diag(p0) if p0 is not None else None,
        max_position_variance=p_max,
        max_time_without_update=t_max,
        appearance=tuple(appearance) if appearance is not None else None,
    )


def knowledge(
    classes: Sequence[ClassSpec],
    *,
    f_clutter: float = 0.5,
    model: str = "paper",
    ratio: float = 0.0,
    max_hypotheses: int = 1_000_000,
    gate: float = 1.0,
    region: Any = None,
    known: Sequence[KnownObject] = (),
    detectors: Sequence[DetectorSpec] | None = None,
    observed_rates: bool = False,
    merge_distance: float = 0.0,
) -> Knowledge:
    # The brute-force reference (reference.py) implements the classes' detection
    # rates; the rates observed on the sources' streams (semwm.mhf.rates) are tested
    # on their own (test_observed_rates.py), so they are off here unless asked for; so is merging
    # near-identical hypotheses (semwm.mhf.similar, test_similar.py).
    world = WorldSettings(
        dimension=2,
        pruning_ratio=ratio,
        max_hypotheses=max_hypotheses,
        association_model=model,  # type: ignore[arg-type]
        gate_probability=gate,
        region=region,
        observed_detection_rates=observed_rates,
        merge_distance=merge_distance,
    )
    return resolve(
        KnowledgeDocument(
            world=world,
            classes=tuple(classes),
            detectors=tuple(detectors)
            if detectors is not None
            else (DetectorSpec(name="cam", clutter_frequency=f_clutter),),
            known_objects=tuple(known),
        )
    )


def det(t: float, cls: str, x: float, y: float, **extra: Any) -> dict[str, Any]:
    return {"time": t, "class": cls, "position": [x, y], **extra}
