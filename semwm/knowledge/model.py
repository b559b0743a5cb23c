"""The knowledge model: what a knowledge file says, as frozen pydantic values.

Two layers:

* the *document* (:class:`KnowledgeDocument`) is what a file says, class by class,
  with every per-class field optional so that a subclass can leave it to its
  parent (paper 002, Section IV: object descriptions with is-a relations);
* the *resolved* knowledge (:class:`Knowledge`, built by
  :func:`semwm.knowledge.resolve.resolve`) has inheritance applied once, every
  value checked against the world's dimension, and is what the filter factory
  and the MHF read.

Units: seconds, metres, frequencies in Hz (events per second).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Annotated, Literal

from pydantic import BaseModel, ConfigDict, Field

# Bounds that keep every value physically meaningful (and the arithmetic finite).
MAX_MAGNITUDE = 1e12
"""The largest magnitude of a matrix entry, variance, distance or duration."""
MAX_COORDINATE = 1e6
"""m: the largest absolute coordinate (region bounds, known objects)."""
MAX_RATE = 1e6
"""Hz: the largest detection, appearance or clutter frequency."""
MAX_HYPOTHESES = 1_000_000
"""The largest n_hyp,max."""

Name = Annotated[str, Field(min_length=1)]
"""A class or detector name: never empty (an empty name cannot be referred to)."""
Entry = Annotated[float, Field(ge=-MAX_MAGNITUDE, le=MAX_MAGNITUDE, allow_inf_nan=False)]
Matrix = tuple[tuple[Entry, ...], ...]
"""A matrix as a tuple of rows. Checked for shape and definiteness on resolution."""

NonNegative = Annotated[float, Field(ge=0.0, le=MAX_MAGNITUDE, allow_inf_nan=False)]
Positive = Annotated[float, Field(gt=0.0, le=MAX_MAGNITUDE, allow_inf_nan=False)]
Probability = Annotated[float, Field(ge=0.0, le=1.0, allow_inf_nan=False)]
Rate = Annotated[float, Field(ge=0.0, le=MAX_RATE, allow_inf_nan=False)]
Coordinate = Annotated[float, Field(ge=-MAX_COORDINATE, le=MAX_COORDINATE, allow_inf_nan=False)]

MotionOrder = Literal["zeroth_order", "first_order"]
"""``zeroth_order``: constant position; ``first_order``: constant velocity."""

Category = Literal["static", "passive", "actively_controlled", "foreign_controlled"]
"""Object categories of paper 004, Section II."""


CATEGORY_FIELDS = (
    "velocity_decay",
    "confidence_decay",
    "confidence_decay_distance",
    "looking_decay",
    "suspicious_confidence",
    "invalid_confidence",
    "detection_probability",
    "kick_probability",
    "kick_speed_spread",
    "kick_direction_spread",
    "trust_labels",
)
"""Class fields whose default depends on the category (paper 004)."""

_COMMON: dict[str, float | bool] = {
    "velocity_decay": 0.0,
    "confidence_decay": 0.1,
    "confidence_decay_distance": 0.0,
    "looking_decay": 1.0,
    "suspicious_confidence": 0.5,
    "invalid_confidence": 0.25,
    "detection_probability": 0.9,
    "kick_probability": 0.8,
    "kick_speed_spread": 0.2,
    "kick_direction_spread": 10.0,
    "trust_labels": True,
}
CATEGORY_DEFAULTS: Mapping[str | None, Mapping[str, float | bool]] = {
    None: _COMMON,
    # landmarks: no velocity; confidence decays with the observer's motion, not time
    "static": {**_COMMON, "confidence_decay": 0.0, "confidence_decay_distance": 0.1},
    # a ball: rolls out at alpha = 0.3 m/s^2; looked at and not seen, it soon is invalid
    "passive": {
        **_COMMON,
        "velocity_decay": 0.3,
        "confidence_decay": 0.25,
        "looking_decay": 2.0,
        "suspicious_confidence": 0.6,
        "invalid_confidence": 0.3,
    },
    # teammates report themselves (labels are identities)
    "actively_controlled": {**_COMMON, "confidence_decay": 0.2},
    # opponents: observation only (labels on their detections are not identities)
    "foreign_controlled": {**_COMMON, "confidence_decay": 0.2, "trust_labels": False},
}
"""Per-category defaults of :data:`CATEGORY_FIELDS`; a class may set any of them."""


class Frozen(BaseModel):
    """Base of every knowledge value: immutable, unknown keys rejected."""

    model_config = ConfigDict(frozen=True, extra="forbid")


class WorldSettings(Frozen):
    """Settings of the MHF as a whole.

    Attributes
    ----------
    dimension
        2 or 3: the dimension of every position.
    pruning_ratio
        Paper 002 eq. (3), the ratio alpha: a hypothesis whose probability is below
        ``alpha * max p`` is pruned. Paper 000 (C1) uses 0.01.
    max_hypotheses
        n_hyp,max: at most this many hypotheses are kept per cluster of objects tied
        together by detections (paper 000 uses 1000 for its whole tree; every shipped
        file and this default use 100, measured as good at a fraction of the time).
    association_model
        ``mht`` (the default): each object has an existence probability (a Bernoulli
        track, as in JIPDA and PMBM trackers), clutter and birth rates are spread over
        the detectors' coverage, an existing object's likelihood is the predicted
        measurement density N(z; Hx, S) times its class likelihood. ``paper``: paper
        002's literal model, the scaled likelihood of eq. (8) with frequency priors
        (eqs. 5-7) and no existence probabilities (it keeps an empty world with most
        rates; kept to reproduce the paper).
    missed_detection_term
        ``mht`` only: an object that goes undetected while it could be seen loses
        existence (rate f_existing: P(no detection in dt | exists) = exp(-f dt)).
        ``false`` reproduces paper 002's behaviour, where only P_max removes objects.
    observed_detection_rates
        ``mht`` only: an object's detection rate is the larger of its class's
        ``detection_frequency`` and the rate at which the sources that see it are
        observed to report it (a team of robots reporting at 30 Hz each detects an
        object far more often than one camera; :mod:`semwm.mhf.rates`). ``false``
        uses the class's rate only.
    merge_distance
        ``mht`` only: two hypotheses holding the same objects merge when every object
        they hold differently has estimates within this squared Mahalanobis distance
        (and the same class, label, existence; :mod:`semwm.mhf.similar`): twins that
        differ in how one old detection was explained. 0 keeps them apart (paper 002).
    min_existence
        ``mht`` only: the world lists objects whose existence probability is at least
        this (queries may ask for another threshold).
    removal_existence
        ``mht`` only: an object whose existence falls below this is removed from every
        hypothesis (1e-5, as PMBM trackers prune Bernoulli components). It must stay
        well below a new object's first existence b / (b + c), or new objects are
        removed before their second detection (``semwm knowledge validate`` warns).
    label_gate
        Distance (m) within which a labelled detection may update the object holding
        its label even outside the Mahalanobis gate (paper 000: a robot's own report).
    label_error_rate
        Probability that a detection's label is wrong: the prior weight of a labelled
        detection being another object than the one holding the label.
    id_memory
        ``mht`` only: for this long (s) after an object leaves the world, an object
        found again near its prediction (hand-over gate) takes its id back (an
        occlusion the knowledge cannot foresee), unless it was lost out of the
        region or next to a disappearance relation's target.
    gate_probability
        Mahalanobis gate: an object further than the chi-square quantile of this
        probability from a detection spawns no association. 1.0 disables gating.
    region
        The observation region as one ``[min, max]`` pair per axis (metres): objects
        exist inside it (one predicted out of it is removed) and, under ``mht``,
        clutter and new objects are spread over it unless a detector states its own
        coverage (``range``, ``field_of_view``).
    default_detector
        Detector assumed when a detection names none; defaults to the first detector.
    """

    dimension: Literal[2, 3] = 3
    pruning_ratio: Annotated[float, Field(ge=0.0, lt=1.0, allow_inf_nan=False)] = 0.01
    max_hypotheses: Annotated[int, Field(ge=1, le=MAX_HYPOTHESES)] = 100
    association_model: Literal["paper", "mht"] = "mht"
    missed_detection_term: bool = True
    observed_detection_rates: bool = True
    merge_distance: Annotated[float, Field(ge=0.0, le=1.0, allow_inf_nan=False)] = 0.01
    min_existence: Annotated[float, Field(gt=0.0, le=1.0)] = 0.5
    removal_existence: Annotated[float, Field(gt=0.0, lt=1.0)] = 1e-5
    label_gate: Positive = 2.0
    label_error_rate: Annotated[float, Field(gt=0.0, lt=1.0)] = 1e-3
    id_memory: Annotated[float, Field(ge=0.0, le=3600.0)] = 5.0
    gate_probability: Annotated[float, Field(gt=0.0, le=1.0, allow_inf_nan=False)] = 0.9999
    region: tuple[tuple[Coordinate, Coordinate], ...] | None = None
    default_detector: str | None = None


class MotionModelSpec(Frozen):
    """One motion model and its system noise.

    ``system_noise`` is the d x d spectral density Q_c of the white noise driving
    the model: velocity noise (m^2/s) for ``zeroth_order``, acceleration noise
    (m^2/s^3) for ``first_order``. Q(dt) is built from it in
    :mod:`semwm.filters.motion`.
    """

    motion_model: MotionOrder
    system_noise: Matrix


class KalmanFilterSpec(Frozen):
    """A Kalman filter with one motion model (paper 002 IV-B: static classes)."""

    type: Literal["kalman"] = "kalman"
    model: MotionModelSpec


class IMMFilterSpec(Frozen):
    """An interacting multiple model filter (paper 002 IV-B: moving classes).

    The common state is position and velocity. A ``zeroth_order`` model inside an
    IMM keeps the position, resets the velocity to zero and gives it the variance
    ``stationary_velocity_variance`` (m^2/s^2), so that its covariance stays
    positive definite.

    ``transition_matrix[i][j]`` is P(mode j at step k | mode i at step k-1): rows
    sum to 1. Without ``transition_period`` it applies once per prediction step
    (paper 002), so how often modes mix depends on how often scans come (five
    robots whose stamps differ by milliseconds mix five times per frame). With
    ``transition_period`` (s) it is the transition over that time, and a step of
    ``dt`` takes ``T^(dt / transition_period)`` (its eigenvalues must be positive).
    """

    type: Literal["imm"] = "imm"
    models: Annotated[tuple[MotionModelSpec, ...], Field(min_length=2)]
    transition_matrix: Matrix
    initial_mode_probabilities: tuple[Entry, ...] | None = None
    stationary_velocity_variance: Positive = 1e-4
    transition_period: Positive | None = None


FilterSpec = Annotated[KalmanFilterSpec | IMMFilterSpec, Field(discriminator="type")]


class AppearanceRelation(Frozen):
    """ "A <class> appears within ``max_distance`` of a ``target`` every 1/frequency s".

    Paper 002 eq. (4): f_new(o, h) = max over o' in h of f_presence(o, o'). As a
    disappearance relation (``disappearance``), the mirror: an object of the class
    within ``max_distance`` of a ``target`` leaves at ``frequency`` (Hz).
    """

    target: str
    max_distance: Positive
    frequency: Rate


class ClassSpec(Frozen):
    """One object class as written in a knowledge file.

    Every field but ``name`` may be left out: it is then inherited from the
    ``is_a`` parent(s) (the first parent that defines it, depth first).

    Attributes
    ----------
    detection_frequency
        f_existing (paper 002 eq. 6): how often (Hz) a known object of this class is
        detected.
    new_frequency
        The base rate (Hz) at which new objects of this class appear anywhere, the
        fallback of eq. (4) when no appearance relation applies.
    appearance
        Appearance relations (eq. 4).
    filter
        The tracking filter (Kalman or IMM) and its system noise.
    measurement_noise
        R, d x d (m^2), unless a detector overrides it for this class.
    initial_covariance
        Position covariance of a new object, d x d (m^2). Defaults to the
        measurement noise.
    initial_velocity_covariance
        Velocity covariance of a new object, d x d (m^2/s^2), for filters with
        velocity. New objects start with zero velocity (paper 002 III-A).
    max_position_variance
        P_max (paper 002 III-E): an object whose position covariance has an
        eigenvalue above this (m^2) is removed from every hypothesis.
    max_time_without_update
        Paper 000 C3: an object not updated for this long (s) is removed.
    leave_frequency
        ``mht``: the rate (Hz) at which an object of this class leaves the world
        anywhere (its existence decays at this rate even where no sensor sees it);
        default 0.01 (an average stay of 100 s). 0 means objects never leave: one
        that certainly exists then never loses existence by going unseen.
    disappearance
        ``mht``: disappearance relations, the mirror of ``appearance`` ("people leave
        through doors"): near a target the object leaves at the relation's rate.
    category
        Paper 004's object category (Definition 2). It chooses the defaults of the
        fields below (:data:`CATEGORY_DEFAULTS`); each may be set per class.
    velocity_decay
        alpha (m/s^2), filters with velocity: the speed decays as
        ``|v| <- max(0, |v| - alpha dt)`` along its direction (paper 004 IV-B, a
        passive ball rolling out); 0 keeps constant velocity.
    confidence_decay
        Paper 004 IV: the rate (1/s) at which an unseen object's confidence decays,
        ``c <- c exp(-rate dt)``.
    confidence_decay_distance
        The rate (1/m) at which it decays with the observer's motion (static
        landmarks in paper 004 IV-A-3), when scans carry the sensor pose.
    looking_decay
        The rate (1/s) that replaces ``confidence_decay`` while a scan looks at the
        object (it is in the scan's field of view, or flagged ``looking_at``) and
        does not report it: negative information (paper 004, Fig. 6).
    suspicious_confidence, invalid_confidence
        l_suspicious and l_invalid: confidence below the first is ``suspicious``,
        below the second ``invalid`` (paper 004 Fig. 5).
    detection_probability
        P_D: the probability that a scan whose field of view holds the object
        reports it (state-dependent: 0 outside the view).
    kick_probability
        Prior probability that a reported kick moved the object (``POST /actions``);
        1 - it is the "not kicked" hypothesis.
    kick_speed_spread, kick_direction_spread
        Relative standard deviation of a kick's stated speed (fraction) and standard
        deviation of its direction (degrees).
    trust_labels
        Whether a detection's label is the object's identity (paper 000 III-B).
        ``actively_controlled`` objects report themselves under their label;
        ``foreign_controlled`` ones are tracked from observation only: labels on
        their detections are dropped.
    """

    name: Name
    is_a: tuple[Name, ...] = ()
    detection_frequency: Rate | None = None
    new_frequency: Rate | None = None
    appearance: tuple[AppearanceRelation, ...] | None = None
    filter: FilterSpec | None = None
    measurement_noise: Matrix | None = None
    initial_covariance: Matrix | None = None
    initial_velocity_covariance: Matrix | None = None
    max_position_variance: Positive | None = None
    max_time_without_update: Positive | None = None
    leave_frequency: Rate | None = None
    disappearance: tuple[AppearanceRelation, ...] | None = None
    category: Category | None = None
    velocity_decay: NonNegative | None = None
    confidence_decay: NonNegative | None = None
    confidence_decay_distance: NonNegative | None = None
    looking_decay: NonNegative | None = None
    suspicious_confidence: Probability | None = None
    invalid_confidence: Probability | None = None
    detection_probability: Probability | None = None
    kick_probability: Probability | None = None
    kick_speed_spread: NonNegative | None = None
    kick_direction_spread: Annotated[float, Field(ge=0.0, le=180.0)] | None = None
    trust_labels: bool | None = None


class DetectorSpec(Frozen):
    """A detector (a sensor with its detection algorithm).

    Attributes
    ----------
    clutter_frequency
        f_clutter (paper 002 eq. 5): false detections per second.
    measurement_noise
        Per-class R overriding the class's own, class name -> d x d (m^2).
    range
        Paper 000 C2: detections farther than this (m) from the sensor position
        are not used. With ``field_of_view`` it is the detector's coverage, over
        which ``clutter_frequency`` is spread when it is smaller than the region.
    field_of_view
        Opening angle of the detector (degrees, 0 < fov <= 360), with ``range``.
    confusion_rate
        ``mht``: how often (relative to a correct report) this detector reports a
        class confusable with the true one (a sibling, or a subclass of a generic
        object). Compatible reports (the class or a superclass) count 1, classes
        with no common ancestor 0 (paper 002 eq. 8 is the limit confusion_rate = 0).
    confidence
        Paper 004: the confidence a detection of this detector gives the object it
        updates (a teammate's relayed estimate: lower than one's own camera).
    static
        The sensor stands still and sees the whole region (with ``position`` and
        ``range``: what lies within ``range`` of ``position``): every scan of it
        could have seen every object there, so not reporting one is a miss, as for a
        scan with a sensor view (docs/knowledge.md, "What semwm concludes from not
        seeing something"). Without it, a sensor's coverage is learnt from what it
        reports.
    position
        Where a ``static`` sensor stands (m), for its ``range``.
    """

    name: Name
    clutter_frequency: Rate
    measurement_noise: Mapping[str, Matrix] = Field(default_factory=dict)
    range: Positive | None = None
    field_of_view: Annotated[float, Field(gt=0.0, le=360.0)] | None = None
    confusion_rate: Annotated[float, Field(ge=0.0, le=1.0)] = 0.05
    unrelated_confusion_rate: Annotated[float, Field(ge=0.0, le=1.0)] = 0.01
    confidence: Probability = 1.0
    static: bool = False
    position: tuple[Coordinate, ...] | None = None


class KnownObject(Frozen):
    """An object known from a map, e.g. a door: always present as a target of
    appearance relations; not tracked and not part of the world output."""

    model_config = ConfigDict(frozen=True, extra="forbid", populate_by_name=True)

    cls: str = Field(alias="class")
    position: tuple[Coordinate, ...]
    name: str | None = None


class KnowledgeDocument(Frozen):
    """A knowledge base as written: world settings, classes, detectors, map."""

    world: WorldSettings = Field(default_factory=WorldSettings)
    classes: tuple[ClassSpec, ...]
    detectors: Annotated[tuple[DetectorSpec, ...], Field(min_length=1)]
    known_objects: tuple[KnownObject, ...] = ()


class ResolvedClass(Frozen):
    """A class with inheritance applied and every value checked: what the factory reads."""

    name: str
    parents: tuple[str, ...]
    ancestors: tuple[str, ...]
    detection_frequency: float
    new_frequency: float
    appearance: tuple[AppearanceRelation, ...]
    filter: FilterSpec
    measurement_noise: Matrix
    initial_covariance: Matrix
    initial_velocity_covariance: Matrix
    max_position_variance: float | None
    max_time_without_update: float | None
    leave_frequency: float
    disappearance: tuple[AppearanceRelation, ...]
    category: Category | None
    velocity_decay: float = 0.0
    confidence_decay: float = 0.1
    confidence_decay_distance: float = 0.0
    looking_decay: float = 1.0
    suspicious_confidence: float = 0.5
    invalid_confidence: float = 0.25
    detection_probability: float = 0.9
    kick_probability: float = 0.8
    kick_speed_spread: float = 0.2
    kick_direction_spread: float = 10.0
    trust_labels: bool = True


class Knowledge(Frozen):
    """Resolved knowledge: the only form the factory and the MHF see."""

    world: WorldSettings
    classes: Mapping[str, ResolvedClass]
    detectors: Mapping[str, DetectorSpec]
    known_objects: tuple[KnownObject, ...]
    document: KnowledgeDocument
    source: str | None = None

    @property
    def dimension(self) -> int:
        return self.world.dimension

    @property
    def default_detector(self) -> str:
        if self.world.default_detector is not None:
            return self.world.default_detector
        return next(iter(self.detectors))
