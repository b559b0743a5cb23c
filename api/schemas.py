"""Request and response bodies of the HTTP API.

These are the wire format, kept apart from the domain values of :mod:`semwm`
(:class:`semwm.detection.Detection`, :class:`semwm.world_types.WorldObject`, ...):
routes translate between the two. Times are in seconds, positions in metres,
covariances in square metres.
"""

from __future__ import annotations

from typing import Annotated, Any, Literal, NotRequired

import numpy as np
from pydantic import AfterValidator, BaseModel, ConfigDict, Field, TypeAdapter
from typing_extensions import TypedDict  # pydantic needs it before Python 3.12

from semwm.detection import MAX_TIME, MAX_TIME_STD
from semwm.knowledge import ClassSpec, ResolvedClass
from semwm.world import IngestResult

MAX_COORDINATE = 1e6
"""m: the largest absolute coordinate a detection may have (1000 km)."""
MAX_NAME = 256
"""The longest source, class, detector or label (characters)."""
VARIANCE_RANGE = (1e-12, 1e6)
"""m^2: the range of a covariance's eigenvalues (1 micrometre to 1 km standard deviation)."""

Finite = Annotated[float, Field(allow_inf_nan=False)]
Time = Annotated[float, Field(allow_inf_nan=False, ge=-MAX_TIME, le=MAX_TIME)]
"""s: within ±MAX_TIME, the same bound in the past and in the future."""
Coordinate = Annotated[float, Field(allow_inf_nan=False, ge=-MAX_COORDINATE, le=MAX_COORDINATE)]
Vector = Annotated[list[Coordinate], Field(min_length=2, max_length=3)]
Name = Annotated[str, Field(min_length=1, max_length=MAX_NAME)]
TimeStd = Annotated[float, Field(ge=0.0, le=MAX_TIME_STD, allow_inf_nan=False)]
MAX_KEY = 200
"""The longest idempotency key (``Idempotency-Key`` header or a batch's ``batch_id``)."""
BatchId = Annotated[str, Field(min_length=1, max_length=MAX_KEY)]


def _square_covariance(value: list[list[float]]) -> list[list[float]]:
    """A covariance must be square; if symmetric positive definite, within VARIANCE_RANGE.

    (Symmetry and definiteness in the world's dimension are the domain's checks,
    :func:`semwm.validation.check`.)
    """
    if any(len(row) != len(value) for row in value):
        lengths = ", ".join(str(len(row)) for row in value)
        raise ValueError(
            f"covariance must be a square matrix; found {len(value)} rows of lengths {lengths}"
        )
    if value:
        matrix = np.asarray(value, dtype=float)
        if np.allclose(matrix, matrix.T, rtol=1e-9, atol=1e-12):
            low, high = VARIANCE_RANGE
            eigenvalues = np.linalg.eigvalsh(matrix)
            if eigenvalues.min() > 0 and (eigenvalues.min() < low or eigenvalues.max() > high):
                raise ValueError(
                    f"covariance eigenvalues must lie in [{low:g}, {high:g}] m^2; found "
                    f"{eigenvalues.min():.3g} to {eigenvalues.max():.3g}"
                )
    return value


Covariance = Annotated[
    list[Annotated[list[Finite], Field(max_length=3)]],
    Field(max_length=3),
    AfterValidator(_square_covariance),
]


class Body(BaseModel):
    """Base of request bodies: unknown keys are refused, not silently dropped.

    Strict: a number must be a JSON number (not ``"12.3"``, not ``true``), text must
    be a JSON string.
    """

    model_config = ConfigDict(frozen=True, extra="forbid", populate_by_name=True, strict=True)


DETECTION_EXAMPLE: dict[str, Any] = {
    "time": 12.3,
    "class": "Cup",
    "position": [1.0, 2.0],
    "covariance": [[0.01, 0.0], [0.0, 0.01]],
    "source": "robot1",
}


class DetectionIn(Body):
    """One detection, as a robot reports it."""

    model_config = ConfigDict(json_schema_extra={"examples": [DETECTION_EXAMPLE]})

    time: Time = Field(description="When the object was seen (s).")
    cls: Name = Field(alias="class", description="The detected class, e.g. 'Cup'.")
    position: Vector = Field(description="Measured position (m): [x, y] or [x, y, z].")
    covariance: Covariance | None = Field(
        default=None,
        description="Measurement noise (m^2, d x d, symmetric positive definite, eigenvalues "
        f"{VARIANCE_RANGE[0]:g} to {VARIANCE_RANGE[1]:g}); defaults to the detector's or the "
        "class's.",
    )
    source: Name | None = Field(default=None, description="Robot or sensor id.")
    detector: Name | None = Field(default=None, description="Detector name from the knowledge.")
    label: Name | None = Field(default=None, description="An identity, e.g. a robot's own id.")
    sensor_position: Vector | None = Field(
        default=None, description="Where the sensor was (m), for detector ranges."
    )
    time_std: TimeStd | None = Field(
        default=None,
        description="Standard uncertainty of `time` (s): the position is as uncertain as "
        "the object's motion over it. The service sets it for synced sources.",
    )

    def to_domain(self) -> dict[str, Any]:
        """The detection as :meth:`semwm.WorldModel.ingest` takes it."""
        return self.model_dump(by_alias=True, exclude_none=True)


class SensorIn(Body):
    """Where the scan's sensor looked (paper 004: negative information): objects
    predicted in its view (the detector's range and field_of_view around the pose)
    that the scan does not report lose existence and confidence. With it a batch may
    be empty: "I looked and saw nothing"."""

    pose: Annotated[list[Coordinate], Field(min_length=3, max_length=4)] = Field(
        description="[x, y, heading] (m, m, rad), or [x, y, z, heading]"
    )
    time: Time | None = Field(default=None, description="s; default: the detections' time")
    source: Name | None = Field(default=None, description="default: the detections' source")
    detector: Name | None = Field(default=None, description="default: the detections' detector")
    looking_at: list[int] = Field(
        default_factory=list, description="ids of objects the robot is looking at"
    )

    def to_domain(self) -> dict[str, Any]:
        return self.model_dump(exclude_none=True)


class DetectionBatch(Body):
    """Several detections, applied together or not at all."""

    model_config = ConfigDict(
        json_schema_extra={
            "examples": [
                {
                    "detections": [
                        DETECTION_EXAMPLE,
                        {"time": 12.3, "class": "CokeCan", "position": [0.5, 1.5]},
                    ]
                }
            ]
        }
    )

    detections: list[DetectionIn] = Field(
        description="At least one, unless 'sensor' says where the sensor looked."
    )
    sensor: SensorIn | None = None
    batch_id: BatchId | None = Field(
        default=None,
        description="A client's id for this batch: posted again (a retry), it is answered as "
        "the first time and not applied twice. Same as the Idempotency-Key header.",
    )


# -- the fast path: the same bodies validated into plain dicts, straight from the JSON bytes ----
#
# DetectionIn and DetectionBatch document the wire format (OpenAPI) and report problems.
# Validating an accepted body into them and dumping each back to a dict costs more than the
# rest of the HTTP path; these TypedDicts have the same fields and constraints and give the
# dicts the world model takes, in one call into pydantic-core for the whole body.
# tests/api/test_api_fast_path.py holds their JSON schemas equal to the models': a field
# added to a model must be added here too. (A batch with a sensor view, or none at all,
# takes the models' path: api/routes/detections.py parse_json.)

_FAST = ConfigDict(extra="forbid", strict=True)

DetectionDict = TypedDict(
    "DetectionDict",
    {
        "time": Time,
        "class": Name,
        "position": Vector,
        "covariance": NotRequired[Covariance | None],
        "source": NotRequired[Name | None],
        "detector": NotRequired[Name | None],
        "label": NotRequired[Name | None],
        "sensor_position": NotRequired[Vector | None],
        "time_std": NotRequired[TimeStd | None],
    },
)
DetectionDict.__pydantic_config__ = _FAST  # type: ignore[attr-defined]


class DetectionBatchDict(TypedDict):
    __pydantic_config__ = _FAST  # type: ignore[misc]

    detections: Annotated[
        list[DetectionDict],
        Field(description="At least one, unless 'sensor' says where the sensor looked."),
    ]
    sensor: NotRequired[SensorIn | None]
    batch_id: NotRequired[BatchId | None]


DETECTION_ADAPTER: TypeAdapter[DetectionDict] = TypeAdapter(DetectionDict)
BATCH_ADAPTER: TypeAdapter[DetectionBatchDict] = TypeAdapter(DetectionBatchDict)


class IgnoredOut(BaseModel):
    """A detection of the batch accepted but not used, and why."""

    index: int = Field(description="Its place in the batch (0-based).")
    reason: Literal["out_of_range", "outside_region"] = Field(
        description="out_of_range: beyond its detector's range from its sensor_position; "
        "outside_region: outside the knowledge's region by more than its noise."
    )
    message: str = Field(description="What was wrong, with a hint (check units and frame).")


class IngestOut(BaseModel):
    """What ``POST /detections`` acknowledges."""

    model_config = ConfigDict(json_schema_extra={"examples": [{"applied": 2, "time": 12.3}]})

    applied: int = Field(description="How many detections were applied.")
    time: float | None = Field(description="The world time after them (s).")
    ignored: int = Field(
        default=0,
        description="Accepted but not used: beyond their detector's range, or clearly "
        "outside the knowledge's region (each listed in ignored_detections).",
    )
    ignored_detections: list[IgnoredOut] = Field(
        default_factory=list,
        description="Each detection accepted but not used: its index in the batch, why "
        "(out_of_range, outside_region) and a message; usually a unit or frame mistake.",
    )


class ConfidenceOut(BaseModel):
    """Paper 004's confidence: a value in [0, 1] and its state by the class's thresholds."""

    value: float
    state: Literal["valid", "suspicious", "invalid"]


class WorldObjectOut(BaseModel):
    """An object of the world, predicted to the query time."""

    model_config = ConfigDict(populate_by_name=True)

    id: int = Field(
        description="public id (positive): stays with the object while it lives; a tentative "
        "object has 1000000001 + the number of the detection that started it"
    )
    cls: str = Field(alias="class", description="its most probable class")
    label: str | None = Field(description="its identity, from labelled detections (else null)")
    position: list[float] = Field(description="m")
    velocity: list[float] | None = Field(description="m/s; null for classes without velocity")
    covariance: list[list[float]] = Field(description="position covariance (m^2)")
    existence: float = Field(
        description="probability that the object exists, over every hypothesis"
    )
    last_seen: float = Field(description="time of its last detection (s)")
    created: float | None = Field(default=None, description="time of its first detection (s)")
    mode_probabilities: dict[str, float] | None = Field(
        default=None, description="IMM motion model -> probability"
    )
    class_probabilities: dict[str, float] | None = Field(
        default=None,
        description="class -> probability that it is the object's true class (classes below "
        "0.001 left out); 'class' is the most specific class holding more than half",
    )
    confidence: ConfidenceOut | None = Field(
        default=None, description="paper 004's confidence (mht): value and state"
    )
    tentative: bool = Field(
        default=False,
        description="below the publishing threshold (listed because min_existence asked "
        "for it); its id is 1000000001 + the number of the detection that started it, and "
        "GET /world/objects/{id} answers it, later under its published id",
    )


WORLD_OBJECT_EXAMPLE: dict[str, Any] = {
    "id": 1,
    "class": "Cup",
    "label": None,
    "position": [1.0, 2.0],
    "velocity": None,
    "covariance": [[0.01, 0.0], [0.0, 0.01]],
    "existence": 0.97,
    "last_seen": 12.3,
    "created": 10.0,
    "mode_probabilities": None,
    "class_probabilities": {"Cup": 0.97, "Mug": 0.03},
}


class WorldOut(BaseModel):
    """The world at ``time``."""

    model_config = ConfigDict(
        json_schema_extra={"examples": [{"time": 12.3, "objects": [WORLD_OBJECT_EXAMPLE]}]}
    )

    time: float | None = Field(description="The time the objects are predicted to (s).")
    objects: list[WorldObjectOut] = Field(
        description="every object whose existence is at least min_existence (0.5 unless asked)"
    )


class HypothesisObjectOut(BaseModel):
    """An object of a hypothesis."""

    model_config = ConfigDict(populate_by_name=True)

    id: int | None = Field(
        description="its public id (as in GET /world) if the object was ever published; null "
        "for an object that exists only in this hypothesis's view so far (e.g. one new "
        "detection, or an alternative not yet the most probable)"
    )
    track: int = Field(
        description="the filter's internal number of the object's lineage (its versions since "
        "its first detection): the same number in two hypotheses is the same object; not a "
        "public id (use id)"
    )
    cls: str = Field(alias="class", description="its class in this hypothesis")
    label: str | None = Field(description="its identity, from labelled detections (else null)")
    position: list[float] = Field(description="its estimated position (m)")
    existence: float = Field(
        description="its existence probability in this hypothesis (mht; 1 under paper)"
    )


class HypothesisOut(BaseModel):
    """One hypothesis: its probability and its objects."""

    probability: float = Field(
        description="probability of this global hypothesis (one hypothesis of each cluster)"
    )
    log10_probability: float = Field(
        description="log10 of the probability (exact where the probability rounds to 0)"
    )
    objects: list[HypothesisObjectOut] = Field(description="the objects this hypothesis holds")


class HypothesesOut(BaseModel):
    """The most probable hypotheses, best first."""

    total: int = Field(
        description="How many hypotheses the filter stores (the sum over its clusters)."
    )
    clusters: int = Field(description="Independent groups of hypotheses.")
    log10_joint: float = Field(
        description="log10 of the number of global hypotheses (combinations of the clusters')."
    )
    limit: int | None = Field(
        default=None,
        description="The limit applied: the one asked, or fewer so that the answer lists at "
        "most 100,000 objects (each hypothesis lists all it holds).",
    )
    hypotheses: list[HypothesisOut] = Field(description="the most probable ones, best first")


class ClassOut(BaseModel):
    """A class: as resolved (inheritance applied) and as written."""

    name: str = Field(description="the class's name")
    resolved: ResolvedClass = Field(
        description="its settings with inheritance applied (what the world model uses)"
    )
    spec: ClassSpec = Field(description="its settings as written in the knowledge")
    written: bool = Field(
        default=False, description="PUT only: whether the edit was written to the knowledge file."
    )


class ReloadOut(BaseModel):
    """The knowledge reloaded from its file."""

    knowledge: str = Field(description="the knowledge file read")
    classes: list[str] = Field(description="its classes")


class ResetOut(BaseModel):
    """The world after a reset."""

    status: str = Field(default="reset", description="always 'reset'")
    time: float | None = Field(description="the world's time after the reset: null (empty)")


class HealthOut(BaseModel):
    """Liveness and a one-line summary of the world."""

    model_config = ConfigDict(
        json_schema_extra={
            "examples": [
                {
                    "status": "ok",
                    "engine": "python",
                    "knowledge": "knowledge/sim1.yaml",
                    "time": 12.3,
                    "hypotheses": 4,
                    "hypotheses_log10_joint": 0.6,
                    "objects": 7,
                }
            ]
        }
    )

    status: str = Field(default="ok", description="'ok' while the process answers (liveness)")
    engine: Literal["python", "rust"] | None = Field(
        default=None,
        description="Readers only: who runs the world model's numeric kernels (docs/engines.md).",
    )
    knowledge: str | None = Field(default=None, description="Readers only.")
    time: float | None = Field(default=None, description="Readers only.")
    hypotheses: int | None = Field(
        default=None, description="Readers only: hypotheses stored (the sum over clusters)."
    )
    hypotheses_log10_joint: float | None = Field(
        default=None, description="Readers only: log10 of the number of global hypotheses."
    )
    objects: int | None = Field(default=None, description="Readers only.")
    commit: int | None = Field(
        default=None, description="Readers only: the number of the last accepted change."
    )
    store_damage: list[str] | None = Field(
        default=None,
        description="Readers only, with --data-dir: the damage the last start found in the "
        "store (docs/persistence.md, 'Damage'); null when none.",
    )
    lost_records: list[int] | None = Field(
        default=None, description="Readers only: [first, last] seq of the records lost."
    )


class ReadyOut(BaseModel):
    """Readiness: ``ready``, or ``not ready`` with the reasons."""

    status: str = Field(description="'ready', or 'not ready' (with status code 503)")
    reasons: list[str] = Field(description="why not ready; empty when ready")


class ErrorItem(BaseModel):
    """One problem with a request: where (``loc``) and what (``msg``)."""

    loc: list[str | int] = Field(description="where: the path of the field in the request")
    msg: str = Field(description="what is wrong")
    type: str = Field(description="the kind of problem (pydantic's error type)")


class ValidationErrorOut(BaseModel):
    """422: every problem found; nothing was changed."""

    detail: list[ErrorItem] = Field(description="every problem, each with where and what")


class MessageOut(BaseModel):
    """An error with a message (404, 409)."""

    detail: str = Field(description="what was not found or is in conflict")


class KnowledgeFileErrorOut(BaseModel):
    """422 of ``POST /knowledge/reload``: the problems of the file, ``FILE:LINE: message``."""

    detail: str = Field(description="the file could not be used; the running knowledge stays")
    problems: list[str] = Field(description="every problem, as FILE:LINE: message")


def ingest_out(result: IngestResult) -> IngestOut:
    """The acknowledgement of an applied batch."""
    return IngestOut(
        applied=result.applied,
        time=result.time,
        ignored=result.ignored,
        ignored_detections=[
            IgnoredOut(index=i.index, reason=i.reason, message=i.message)
            for i in result.ignored_detections
        ],
    )
