"""Warnings about knowledge that loads but will likely not do what its author wants.

Each warning names the field it is about (the loader gives it a line) and says
what will happen and what to change. ``semwm knowledge validate`` prints them as
``FILE:LINE: warning: ...``; they do not stop the knowledge from loading.

The checks, for the ``mht`` model (:mod:`semwm.mhf.existence`,
:mod:`semwm.mhf.association`):

* a class that can never appear (``new_frequency: 0`` and no appearance relation):
  its detections are all clutter;
* a class whose objects are never removed (no detections expected, no leave rate,
  no P_max, no C3): the world never forgets them;
* a class whose detections can never confirm an object: a detection that fits an
  existing object (``f_e N(z; Hx, S)`` at the centre of the gate) must beat the
  clutter and birth densities by more than the existence lost between two
  detections (a factor ``e``), or existence never grows;
* a class whose unseen objects are removed (C3 or P_max) before their confidence can
  turn invalid (paper 004): a robot never learns that it should go and look;
* the literal ``paper`` model, which keeps an empty world with most rates.
"""

from __future__ import annotations

import math

import numpy as np

from semwm.filters.factory import build_class_filter
from semwm.knowledge.coverage import birth_volume, coverage_volume
from semwm.knowledge.model import Knowledge, ResolvedClass
from semwm.knowledge.problems import Problem

CONFIRMATION_LIMIT = 20
"""Warn when confirming a new object takes more detections than this."""


def _ball(radius: float, dim: int) -> float:
    return math.pi * radius**2 if dim == 2 else 4.0 / 3.0 * math.pi * radius**3


def _class_path(knowledge: Knowledge, name: str) -> tuple[str | int, ...]:
    index = next(i for i, c in enumerate(knowledge.document.classes) if c.name == name)
    return ("classes", index)


def _warning(message: str, path: tuple[str | int, ...]) -> Problem:
    return Problem(message, path, severity="warning")


def advice(knowledge: Knowledge) -> list[Problem]:
    """Every warning for usable ``knowledge`` (unlocated: the loader adds lines)."""
    world = knowledge.world
    if world.association_model == "paper":
        return [
            _warning(
                "association_model 'paper' is paper 002's literal model: with most rates the "
                "all-clutter hypothesis wins and the world stays empty; leave it out (mht, the "
                "default) unless you reproduce the paper",
                ("world", "association_model"),
            )
        ]
    warnings: list[Problem] = []
    mapped = {known.cls for known in knowledge.known_objects}
    births = birth_volume(world, tuple(knowledge.detectors.values()))
    for name, spec in knowledge.classes.items():
        if name in mapped:
            continue  # a mapped class (a door): a target of relations, not tracked
        path = _class_path(knowledge, name)
        if spec.new_frequency == 0.0 and not spec.appearance:
            warnings.append(
                _warning(
                    f"no object of class {name!r} can ever appear: new_frequency is 0 and no "
                    "appearance relation applies, so its detections are all clutter; give "
                    "new_frequency the rate (Hz) at which new ones turn up",
                    (*path, "new_frequency"),
                )
            )
            continue
        early = _removed_before_invalid(spec, world.dimension)
        if early is not None:
            when, why, field = early
            warnings.append(
                _warning(
                    f"an unseen {name!r} is removed by {why} about {when:.2g} s after its "
                    f"last detection, before its confidence turns invalid "
                    f"({_time_to_invalid(spec):.2g} s at confidence_decay "
                    f"{spec.confidence_decay:g}): a robot never learns to go and look; raise "
                    f"{field}, or confidence_decay",
                    (*path, field),
                )
            )
        forgets = (
            (spec.detection_frequency > 0.0 and world.missed_detection_term)
            or spec.leave_frequency > 0.0
            or spec.disappearance
            or spec.max_position_variance is not None
            or spec.max_time_without_update is not None
        )
        if not forgets:
            warnings.append(
                _warning(
                    f"objects of class {name!r} are never removed: with no detections expected "
                    "(detection_frequency 0 or missed_detection_term false), no "
                    "leave_frequency, no max_position_variance and no max_time_without_update "
                    "the world keeps them forever",
                    path,
                )
            )
        if births is None:
            continue
        for detector in knowledge.detectors.values():
            volume = coverage_volume(detector, world)
            if volume is None or spec.detection_frequency <= 0.0:
                continue
            noise = np.asarray(
                detector.measurement_noise.get(name, spec.measurement_noise), dtype=float
            )
            S = 2.0 * noise  # a new object's covariance is about R
            peak = 1.0 / math.sqrt(np.linalg.det(2.0 * math.pi * S))
            clutter = detector.clutter_frequency / volume
            # the likeliest birth: the base rate over the region, or a relation's over its
            # disc (ball) (eq. 4)
            birth = max(
                [spec.new_frequency / births]
                + [
                    rel.frequency / _ball(rel.max_distance, world.dimension)
                    for rel in spec.appearance
                ]
            )
            if birth <= 0.0:
                continue
            if clutter + birth <= 0.0:
                continue
            gain = spec.detection_frequency * peak / (clutter + birth) / math.e
            r0 = birth / (clutter + birth)
            floor = world.min_existence
            target = floor / (1.0 - floor) if floor < 1.0 else math.inf
            odds = r0 / (1.0 - r0) if r0 < 1.0 else math.inf
            if odds >= target:
                continue
            decay = math.exp(
                -3.0 * (spec.detection_frequency + spec.leave_frequency) / spec.detection_frequency
            )
            if r0 * decay < world.removal_existence:
                warnings.append(
                    _warning(
                        f"a new {name!r} seen by {detector.name!r} starts with existence "
                        f"{r0:.3g} and is removed (removal_existence "
                        f"{world.removal_existence:g}) if three expected detections are "
                        "missed: lower world.removal_existence, or the clutter density",
                        ("world", "removal_existence"),
                    )
                )
            names = [d.name for d in knowledge.document.detectors]
            where = ("detectors", names.index(detector.name))
            if gain <= 1.0:
                warnings.append(
                    _warning(
                        f"a {name!r} seen by {detector.name!r} is never confirmed: a detection "
                        f"fits it (detection_frequency x N(z; Hx, S) = {gain * math.e:.3g}) no "
                        f"better than clutter and births ({clutter + birth:.3g} per m^d s) by "
                        "the factor e it loses between detections; lower clutter_frequency or "
                        "measurement noise, raise detection_frequency, or give the detector "
                        "its range/field_of_view",
                        where,
                    )
                )
                continue
            needed = 1 + math.ceil(math.log(target / odds) / math.log(gain))
            if needed > CONFIRMATION_LIMIT:
                warnings.append(
                    _warning(
                        f"a new {name!r} seen by {detector.name!r} needs about {needed} "
                        f"detections ({needed / spec.detection_frequency:.3g} s) to reach "
                        f"existence {world.min_existence:g}: clutter "
                        f"({clutter:.3g} per m^d s) is dense for its measurement noise",
                        where,
                    )
                )
    return warnings


SETTLING_DETECTIONS = 5
"""Detections an object has had when it goes out of view, for the P_max check."""


def _time_to_invalid(spec: ResolvedClass) -> float:
    """s unseen until the confidence turns invalid (paper 004: exp(-lambda t) below
    ``invalid_confidence``); infinite when it does not decay with time."""
    if spec.confidence_decay <= 0.0 or spec.invalid_confidence <= 0.0:
        return math.inf
    return math.log(1.0 / spec.invalid_confidence) / spec.confidence_decay


def _removed_before_invalid(spec: ResolvedClass, dim: int) -> tuple[float, str, str] | None:
    """When (s after its last detection) C3 or P_max removes an unseen object of the class
    before it can become invalid, by what, and the field: ``None`` if neither does. P_max
    is judged on an object seen :data:`SETTLING_DETECTIONS` times at the class's rate."""
    invalid = _time_to_invalid(spec)
    if not math.isfinite(invalid):
        return None
    c3 = spec.max_time_without_update
    p_max = spec.max_position_variance
    if p_max is not None:
        flt = build_class_filter(spec, dim)
        x, P, mu = flt.initial_states(np.zeros((1, dim)))
        R = np.asarray(spec.measurement_noise, dtype=float)[None]
        step = 1.0 / spec.detection_frequency if spec.detection_frequency > 0 else 0.1
        for _ in range(SETTLING_DETECTIONS - 1):
            x, P, mu = flt.predict(x, P, mu, np.array([step]))
            x, P, mu, _ = flt.update(x, P, mu, np.zeros((1, dim)), R)
        for t in np.linspace(0.0, invalid, 65)[1:]:
            _, Pt = flt.combine(*flt.predict(x, P, mu, np.array([t])))
            if float(np.linalg.eigvalsh(Pt[0, :dim, :dim]).max()) > p_max:
                if c3 is None or t < c3:
                    return float(t), "P_max", "max_position_variance"
                break
    if c3 is not None and c3 < invalid:
        return c3, "C3", "max_time_without_update"
    return None
