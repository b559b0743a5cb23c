"""Detections: what robots and sensors report."""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import BaseModel, ConfigDict, Field

Finite = Annotated[float, Field(allow_inf_nan=False)]
MAX_TIME = 1e12
"""Largest absolute time accepted (s), in the past as in the future: about 31,700 years
either side of the epoch (a Unix time today is 1.8e9 s). Times and clock exchanges stay
within it, so their differences, squares and sums are finite."""
Time = Annotated[float, Field(allow_inf_nan=False, ge=-MAX_TIME, le=MAX_TIME)]
MAX_TIME_STD = 10.0
"""Largest ``time_std`` accepted (s): a stamp less certain than that is not a time."""


class Detection(BaseModel):
    """One object detection.

    Attributes
    ----------
    time
        When the object was seen (s).
    cls
        The detected class label (``class`` in JSON), e.g. ``"Cup"``.
    position
        Measured position (m), with as many entries as the knowledge's dimension.
    covariance
        Measurement noise of this detection (m^2, d x d); else the detector's noise
        for the class, else the class's.
    source
        Robot or sensor id. Detections with the same source and time form one scan.
    detector
        The detector (knowledge ``detectors``) that produced it; defaults to the
        knowledge's default detector.
    label
        An identity, e.g. a robot reporting its own position carries its id
        (paper 000 III-B labeling rules).
    sensor_position
        Where the sensor was (m); with a detector ``range`` it enables paper 000's C2.
    time_std
        Standard uncertainty of ``time`` (s), e.g. a synced clock's offset uncertainty
        (set by the service for synced sources): the position is then as uncertain as
        the object's motion over it (``R + time_std^2 v v^T``).
    """

    model_config = ConfigDict(frozen=True, extra="forbid", populate_by_name=True)

    time: Time
    cls: str = Field(alias="class", min_length=1)
    position: tuple[Finite, ...]
    covariance: tuple[tuple[Finite, ...], ...] | None = None
    source: str | None = None
    detector: str | None = None
    label: str | None = None
    sensor_position: tuple[Finite, ...] | None = None
    time_std: Annotated[float, Field(ge=0.0, le=MAX_TIME_STD, allow_inf_nan=False)] | None = None

    def to_dict(self) -> dict[str, object]:
        return self.model_dump(by_alias=True, exclude_none=True)


class DetectionProblem(BaseModel):
    """One reason a detection was refused: the field path and a message."""

    model_config = ConfigDict(frozen=True)

    path: tuple[str | int, ...]
    message: str


class DetectionError(ValueError):
    """Detections refused as a whole; nothing of the batch was applied."""

    def __init__(self, problems: list[DetectionProblem]) -> None:
        self.problems = tuple(problems)
        super().__init__(
            "; ".join(f"{'.'.join(map(str, p.path)) or '<batch>'}: {p.message}" for p in problems)
        )


class OutOfOrderError(ValueError):
    """A detection older than the reorder window allows; nothing of the batch was applied."""

    def __init__(self, time: float, latest: float, window: float, why: str = "") -> None:
        self.time = time
        self.latest = latest
        self.window = window
        super().__init__(
            f"detection at time {time:g} s is older than the latest processed time {latest:g} s "
            f"minus the reorder window {window:g} s" + (f" ({why})" if why else "")
        )


class BeforeHistoryError(ValueError):
    """A query about a time older than the reorder history remembers: semwm does not
    know the world as it was then (it never answers with the current one instead)."""

    def __init__(self, time: float, oldest: float | None, latest: float) -> None:
        self.time = time
        self.oldest = oldest
        self.latest = latest
        since = (
            f"the world is remembered from {oldest:g} s"
            if oldest is not None
            else "no earlier state is remembered (reorder window 0)"
        )
        super().__init__(
            f"time {time:g} s is before the newest scan ({latest:g} s) and {since}; "
            "ask for a later time, or keep a longer history (--reorder-window)"
        )


class SensorReport(BaseModel):
    """What a sensor looked at in one scan (paper 004: negative information).

    With it, a scan says where the sensor was and where it pointed, so objects
    predicted in its view that the scan did not report lose existence and
    confidence; a scan may then be empty ("I looked and saw nothing").

    Attributes
    ----------
    pose
        ``[x, y, heading]`` (m, m, rad; heading counter-clockwise from the x axis), or
        ``[x, y, z, heading]`` in a 3D world. The view is the detector's ``range`` and
        ``field_of_view`` around the heading, in the horizontal plane.
    time
        The scan's time (s); default: its detections' time (required for an empty scan).
    source
        The scan's source; default: its detections' source.
    detector
        Whose ``range`` and ``field_of_view`` make the view; default: the detections'
        detector, else the knowledge's default.
    looking_at
        Ids of objects the robot is looking at (paper 004's flag): treated as in view.
    """

    model_config = ConfigDict(frozen=True, extra="forbid")

    pose: tuple[Finite, ...]
    time: Time | None = None
    source: str | None = None
    detector: str | None = None
    looking_at: tuple[int, ...] = ()


class ActionReport(BaseModel):
    """An action a robot took on an object (paper 004 IV-B): a kick.

    Attributes
    ----------
    time
        When (s); not before the latest processed detection.
    type
        ``"kick"``.
    source
        The robot that acted.
    object
        The id of the object acted on; or
    near
        a position (m): the nearest passive object within ``radius`` of it.
    direction
        The direction it was kicked in (any length but 0).
    speed
        The speed the kick gives it (m/s).
    """

    model_config = ConfigDict(frozen=True, extra="forbid", populate_by_name=True)

    time: Time
    type: Literal["kick"] = "kick"
    source: str | None = None
    object: int | None = None
    near: tuple[Finite, ...] | None = None
    radius: Annotated[float, Field(gt=0.0, le=1e6)] = 1.0
    direction: tuple[Finite, ...]
    speed: Annotated[float, Field(ge=0.0, le=1e3)]
