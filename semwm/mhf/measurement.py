"""A detection checked against the knowledge and ready for the MHF."""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

from semwm.filters.motion import FloatArray


class Measurement(NamedTuple):
    """A detection with its measurement noise and clutter rate resolved (a named tuple:
    one is made per detection, and a frozen dataclass sets each field through
    ``object.__setattr__``, 1.7 against 0.4 us).

    ``seq`` is the detection's acceptance number: it identifies the object a new
    track would be (its lineage), stable when the reorder window replays.
    ``sensor``: where the sensor was (the detection's ``sensor_position``), if given;
    ``time_std``: standard uncertainty of ``time`` (s).
    """

    seq: int
    time: float
    cls: str
    z: FloatArray
    R: FloatArray
    detector: str
    source: str | None
    label: str | None
    clutter_rate: float
    sensor: FloatArray | None = None
    time_std: float = 0.0


@dataclass(frozen=True, slots=True)
class SensorView:
    """Where a scan's sensor looked (paper 004: negative information).

    ``position`` ``(2,)`` (m) and ``heading`` (rad) in the horizontal plane;
    ``range`` (m) and ``half_angle`` (rad) bound the view (``None``: unbounded);
    ``looking_at``: lineages of objects flagged as looked at (in view whatever their
    position); ``detector``: the scan's detector.
    """

    time: float
    source: str | None
    position: FloatArray
    heading: float
    range: float | None
    half_angle: float | None
    looking_at: frozenset[int] = frozenset()
    detector: str | None = None
