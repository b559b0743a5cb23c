"""A detection checked against the knowledge and ready for the MHF."""

from __future__ import annotations

from dataclasses import dataclass

from semwm.filters.motion import FloatArray


@dataclass(frozen=True, slots=True)
class Measurement:
    """A detection with its measurement noise and clutter rate resolved.

    ``seq`` is the detection's acceptance number: it identifies the object a new
    track would be (its lineage), stable when the reorder window replays.
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
