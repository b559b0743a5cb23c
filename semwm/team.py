"""Two-level world modelling (paper 000): local models per robot, one global team model.

Each robot keeps a local :class:`~semwm.WorldModel` of its own detections (fast,
its own clock). Every report period a :class:`LocalModel` turns its objects into
detections for the global model: class, position, the object's position
covariance as measurement noise, its label (a peer's id), ``source`` = the robot
and detector :data:`LOCAL_DETECTOR`. The global model is an ordinary
``WorldModel`` (paper 000: "the high level algorithm is identical").

A local object re-sent every period is not a new independent measurement: its
estimate holds the information sent before. What a report carries
(:class:`Strategy`):

* ``all``: every local object, its covariance as is (the naive baseline: the same
  information is counted again in every report);
* ``updated``: only objects updated by a local detection since the last report; an
  object the robot tracks (not its own pose: no label) with its covariance doubled
  (:data:`TRACKED_FACTOR`, as ``ci`` does for every object): its filtered estimate
  holds what earlier reports carried, and a laggy estimate of a turning robot sent
  as is lies outside the global gate and starts a duplicate (issue 28); the robot's
  own pose, a fresh precise self-localisation, goes as is;
* ``ci``: ``updated`` with the covariance doubled: the Kalman update with ``2 P``
  is the local half of covariance intersection with weight 1/2, a conservative
  fusion for unknown correlation;
* ``detections``: only objects updated by a local detection since the
  last report, each as the detections the local model gave it since then, combined
  (:func:`combine_detections`): the information-weighted mean of their positions, each
  moved to the report time by the object's local velocity, with covariance
  ``(sum_i R_i^-1)^-1``. Those detections were in no earlier report, so the global
  model counts nothing twice (no factor on the covariance) and, as flat, filters
  independent measurements once, not a filtered estimate again (issue 28: the global
  filter's gain on a re-sent estimate is about 0.4, so it lagged the robot's own
  estimate). An object updated without a detection found for it goes as ``updated``
  sends it;
* ``scans``: the same detections as ``detections``, uncombined: each at its own time
  with its own noise, so a report is the robot's scans since its last report reduced
  to the detections its local model gave its objects, and the global model processes
  them scan by scan, as flat does. A combined report is one scan of the robot, and one
  scan holds at most one detection of an object: where the robot's local model
  follows one real robot with two tracks that take its detections in turn (robots
  crowding), the combination sends two detections of it in one scan and the global
  model starts a false object (issue 28, bench_team seeds 12 and 14); scan by scan
  each holds one. It also sends the detections that made the robot publish an object
  (noted while the object was tentative, :data:`TENTATIVE_FLOOR`) with its first
  report, as flat has them;
* ``information``: only the information the object gained since it was last sent
  (equivalent measurement, information form): ``I = P⁻¹ - P_s⁻¹`` and
  ``z = I⁻¹ (P⁻¹ x - P_s⁻¹ x_s)``, with ``x_s`` the sent position moved on by the
  sent velocity; an object whose information did not grow (``I`` not positive
  definite) is not sent, the first report of an object is sent whole.

When a report is sent: every report period, and between periods at once when
:meth:`LocalModel.due`: an object was never sent or, with a ``drift_gate``
probability ``p`` (send-on-delta, event-triggered estimation), the global side's
view of an object has drifted out of the local estimate's ``p`` gate
(:func:`drifted`). The report is then the whole report (with ``updated``, every
object updated since it was sent), not the drifted object alone: the global model
reads a report as a scan of the robot, and one that left out objects the robot
sees would count as missing them. That view is a replica: the class's filter fed
what this robot sent of the object, as the global model feeds it (a new object at
the first position sent, then each report as a position measurement with its
covariance), predicted to now. The global model also fuses other robots' reports,
so its view is no worse than the replica's and the rule errs towards sending.

``benchmarks/bench_team.py`` measures them (docs/team.md has the figures). The
local id of each reported object travels with the report (:attr:`Report.local_ids`):
the global side keeps a robot's report on the global object its local object went
to before (:class:`Continuity`, on by default in :class:`TeamModel` and
:func:`semwm.sim.team_run.run_team`, which also default to ``scans``: together
the two-level configuration closest to flat, issue 28). :class:`LocalModel` keeps
``updated`` as its default (the service's local models).

Pure: times are arguments, nothing reads a clock.
"""

from __future__ import annotations

import contextlib
import json
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, replace
from enum import StrEnum

import numpy as np
from scipy.special import chdtri

from semwm.detection import BeforeHistoryError, Detection
from semwm.filters.factory import FilterFactory
from semwm.knowledge.model import DetectorSpec, Knowledge
from semwm.knowledge.resolve import resolve
from semwm.validation import DetectionInput, as_batch, parse
from semwm.world import IngestResult, WorldModel
from semwm.world_types import TENTATIVE_IDS, WorldObject, WorldState

LOCAL_DETECTOR = "local_model"
"""The global model's detector for local-model reports (few false objects left)."""


TENTATIVE_FLOOR = 1e-6
"""``scans``: the local model notes the detections of objects at least this likely to
exist, tentative ones included, so that an object's first report holds the detections
that made the robot publish it (as flat has them)."""


TRACKED_FACTOR = 2.0
"""``updated``: factor on the covariance of an object the robot tracks (unlabelled):
covariance intersection with weight 1/2, the ``ci`` factor."""


class Strategy(StrEnum):
    """What a local model sends to the global one (see the module docstring)."""

    ALL = "all"
    UPDATED = "updated"
    DETECTIONS = "detections"
    SCANS = "scans"
    CI = "ci"
    INFORMATION = "information"


_TRACKED_FACTOR_STRATEGIES = (Strategy.UPDATED, Strategy.DETECTIONS, Strategy.SCANS)
"""Strategies that send an object the robot tracks, when they send its filtered estimate,
with :data:`TRACKED_FACTOR` times its covariance."""


def global_knowledge(knowledge: Knowledge, clutter_frequency: float = 0.05) -> Knowledge:
    """``knowledge`` with the :data:`LOCAL_DETECTOR` detector added (if missing): local
    models have removed most clutter, so it has a low clutter frequency (per second)."""
    document = knowledge.document
    if any(d.name == LOCAL_DETECTOR for d in document.detectors):
        return knowledge
    detector = DetectorSpec(name=LOCAL_DETECTOR, clutter_frequency=clutter_frequency)
    document = document.model_copy(update={"detectors": (*document.detectors, detector)})
    return resolve(document, knowledge.source)


@dataclass(frozen=True)
class Report:
    """One message from a local model to the global one.

    ``detections`` is a ``POST /detections`` batch; ``local_ids[i]`` is the local id
    of ``detections[i]``'s object; ``size`` the bytes of its JSON body.
    """

    robot: str
    time: float
    detections: tuple[dict[str, object], ...]
    local_ids: tuple[int, ...]

    @property
    def body(self) -> dict[str, object]:
        return {"detections": list(self.detections)}

    @property
    def size(self) -> int:
        return len(json.dumps(self.body, separators=(",", ":")).encode())


@dataclass(frozen=True)
class _Replica:
    """The global side's view of one object from one robot's reports: the class
    filter's state ``x (1, M, n)``, ``P (1, M, n, n)``, ``mu (1, M)`` at ``time``."""

    cls: str
    time: float
    x: np.ndarray
    P: np.ndarray
    mu: np.ndarray


@dataclass(frozen=True)
class Taken:
    """A detection the local model gave an object: its time (s), position ``z`` ``(d,)``
    and noise ``R`` ``(d, d)``."""

    time: float
    z: np.ndarray
    R: np.ndarray


@dataclass(frozen=True)
class _Sent:
    time: float
    position: np.ndarray
    velocity: np.ndarray | None
    covariance: np.ndarray
    last_seen: float
    replica: _Replica | None = None


class LocalModel:
    """One robot's local world model and what it has reported.

    Parameters
    ----------
    robot
        The robot's name: the ``source`` of its reports.
    knowledge
        The local model's knowledge.
    strategy
        What a report carries (:class:`Strategy`).
    reorder_window
        Of the local :class:`WorldModel`.
    detector
        The detector reports name (``None``: the global knowledge's default).
    """

    def __init__(
        self,
        robot: str,
        knowledge: Knowledge,
        strategy: Strategy | str = Strategy.UPDATED,
        *,
        reorder_window: float = 0.0,
        detector: str | None = LOCAL_DETECTOR,
    ) -> None:
        self.robot = robot
        self.strategy = Strategy(strategy)
        self.detector = detector
        self.model = WorldModel(knowledge, reorder_window=reorder_window)
        self._filters = FilterFactory(knowledge)
        self._sent: dict[int, _Sent] = {}
        self._taken: dict[int, list[Taken]] = {}

    def ingest(self, detections: DetectionInput | Iterable[DetectionInput]) -> IngestResult:
        """The robot's own detections into its local model; with ``detections``, also
        noted per object they updated, for the next report (:meth:`_take`)."""
        batch = as_batch(detections)
        result = self.model.ingest(batch)
        if self.strategy in (Strategy.DETECTIONS, Strategy.SCANS) and batch:
            self._take(parse(batch))
        return result

    def _take(self, detections: list[Detection]) -> None:
        """Note which object each detection of the batch's latest scan updated.

        The local MHF does not say which detection its most probable hypothesis gave an
        object, so each object updated at the scan's time takes the scan's detection
        nearest its updated estimate (Mahalanobis distance with ``P + R``; a labelled
        detection the object holding its label), each detection at most once, nearest
        pairs first, published objects before tentative ones (``scans`` notes tentative
        objects too: the alternatives the MHF keeps, such as "this detection is a new
        object", are tentative objects updated at the scan as well). Detections of
        earlier times in the same batch are not noted (the object's estimate then is
        gone): such objects go as ``updated`` sends them."""
        at = max(d.time for d in detections)
        scan = [d for d in detections if d.time == at]
        default = self.model.knowledge.default_detector
        noise = [
            np.asarray(d.covariance, dtype=float)
            if d.covariance is not None
            else self._filters.measurement_noise(d.cls, d.detector or default)
            for d in scan
        ]
        taxonomy = self.model.taxonomy
        pairs: list[tuple[bool, bool, float, int, int]] = []
        candidates = (
            self.model.world(min_existence=TENTATIVE_FLOOR).objects
            if self.strategy is Strategy.SCANS
            else self.model.world().objects
        )
        for obj in candidates:
            if obj.last_seen != at:
                continue
            x, P = np.asarray(obj.position), np.asarray(obj.covariance)
            for k, (det, R) in enumerate(zip(scan, noise, strict=True)):
                if not taxonomy.compatible(obj.cls, det.cls):
                    continue
                delta = np.asarray(det.position) - x
                d2 = float(delta @ np.linalg.solve(P + R, delta))
                mismatch = det.label is None or det.label != obj.label
                pairs.append((obj.tentative, mismatch, d2, obj.id, k))
        pairs.sort()
        objects: set[int] = set()
        used: set[int] = set()
        for _, _, _, object_id, k in pairs:
            if object_id in objects or k in used:
                continue
            objects.add(object_id)
            used.add(k)
            z = np.asarray(scan[k].position, dtype=float)
            # a new list, not appended in place: a saved copy of the dict stays as it was
            self._taken[object_id] = [*self._taken.get(object_id, ()), Taken(at, z, noise[k])]

    def world(self, time: float | None = None) -> WorldState:
        return self.model.world(time=time)

    def reset(self) -> None:
        self.model.reset()
        self._sent = {}
        self._taken = {}

    def due(
        self,
        time: float | None = None,
        *,
        drift_gate: float | None = None,
        horizon: float = 0.0,
    ) -> bool:
        """Whether the robot should report at ``time`` rather than wait for its next
        periodic report: an object was never sent (the global model would learn of
        it a report period late), or, with ``drift_gate`` (a probability), an object
        updated since it was sent has drifted: the global side's view of it is
        outside the local estimate's ``drift_gate`` gate (:func:`drifted`;
        send-on-delta). With ``horizon`` (s) both are first predicted that far ahead,
        the local estimate by its velocity: a global view whose velocity is wrong
        (it learns velocity from reported positions only, so it lags an accelerating
        robot) will drift before the next periodic report, and the robot sends now
        rather than a period late. The report then sent is the whole :meth:`report`."""
        if drift_gate is not None and not 0.0 < drift_gate < 1.0:
            raise ValueError(f"drift_gate must be a probability in (0, 1); got {drift_gate}")
        state = self.model.world(time=time)
        if state.time is None:
            return False
        at = state.time
        gate = (
            float(chdtri(self.model.knowledge.world.dimension, 1.0 - drift_gate))
            if drift_gate is not None
            else None
        )
        for obj in state.objects:
            sent = self._sent.get(obj.id)
            if sent is None:
                return True
            if (
                gate is not None
                and obj.last_seen > sent.last_seen  # new information to send
                and drifted(_ahead(obj, horizon), self._global_view(sent, at + horizon), gate)
            ):
                return True
        return False

    def report(self, time: float | None = None, *, new_only: bool = False) -> Report | None:
        """The report at ``time`` (local clock; default the latest local time), or
        ``None`` when there is nothing to send. Remembers what it sent.

        ``new_only``: only objects never reported. A report with some of the robot's
        objects left out reads, to the global model, as a scan that missed them (their
        existence drops): a robot that must send between reports (:meth:`due`) sends
        the whole report."""
        state = self.model.world(time=time)
        if state.time is None:
            return None
        at = state.time
        if self.strategy is Strategy.SCANS:
            self._published()
        detections: list[dict[str, object]] = []
        ids: list[int] = []
        alive = set()
        for obj in state.objects:
            alive.add(obj.id)
            sent = self._sent.get(obj.id)
            if new_only and sent is not None:
                continue
            items = self._items(obj, sent, at)
            if not items:
                continue
            replica = sent.replica if sent is not None else None
            for item in items:
                detections.append(item)
                ids.append(obj.id)
                replica = self._replica(obj.cls, replica, item, float(item["time"]))  # type: ignore[arg-type]
            self._sent[obj.id] = _Sent(
                at,
                np.asarray(obj.position),
                np.asarray(obj.velocity) if obj.velocity is not None else None,
                np.asarray(obj.covariance),
                obj.last_seen,
                replica,
            )
        self._sent = {k: v for k, v in self._sent.items() if k in alive}
        self._taken = {k: v for k, v in self._taken.items() if k in alive}
        if not detections:
            return None
        # in time order (``scans``: the robot's scans since the last report, one by one)
        order = sorted(range(len(detections)), key=lambda i: float(detections[i]["time"]))  # type: ignore[arg-type]
        return Report(
            self.robot,
            at,
            tuple(detections[i] for i in order),
            tuple(ids[i] for i in order),
        )

    def _published(self) -> None:
        """The detections noted of objects while they were tentative go to the objects they
        were published as (they are sent with the object's first report); those of objects
        still tentative are dropped: a later report holds scans after this one only."""
        for key in [k for k in self._taken if k > TENTATIVE_IDS]:
            taken = self._taken.pop(key)
            obj = self.model.object(key)
            if obj is not None and not obj.tentative:
                self._taken[obj.id] = [*taken, *self._taken.get(obj.id, ())]

    def _replica(
        self, cls: str, replica: _Replica | None, item: dict[str, object], at: float
    ) -> _Replica:
        """``replica`` after the global model takes ``item``: a new object at its
        position (:meth:`ClassFilter.initial_states`, as the global MHF starts one), else
        predicted to ``at`` and updated with it as a position measurement."""
        z = np.asarray(item["position"], dtype=float)[None, :]
        f = self._filters.filter_for(cls)
        if replica is None or self._filters.filter_for(replica.cls).state_size != f.state_size:
            x, P, mu = f.initial_states(z)
            return _Replica(cls, at, x, P, mu)
        f = self._filters.filter_for(replica.cls)
        x, P, mu = f.predict(replica.x, replica.P, replica.mu, np.array([at - replica.time]))
        R = np.asarray(item["covariance"], dtype=float)[None, :, :]
        x, P, mu, _ = f.update(x, P, mu, z, R)
        return _Replica(replica.cls, at, x, P, mu)

    def _global_view(self, sent: _Sent, at: float) -> np.ndarray:
        """The position the global side expects at ``at`` from what was sent: the
        replica predicted (its mean, the modes combined)."""
        replica = sent.replica
        if replica is None:
            return sent.position
        f = self._filters.filter_for(replica.cls)
        x, P, mu = f.predict(replica.x, replica.P, replica.mu, np.array([at - replica.time]))
        mean, _ = f.combine(x, P, mu)
        return np.asarray(mean[0, : f.dim])

    def _items(self, obj: WorldObject, sent: _Sent | None, at: float) -> list[dict[str, object]]:
        """What a report carries of ``obj``: with ``scans``, each detection the local model
        gave it since the last report, at its own time with its own noise; else one item
        (:meth:`_item`), or none."""
        if self.strategy is Strategy.SCANS:
            if sent is not None and obj.last_seen <= sent.last_seen:
                return []
            taken = self._taken.pop(obj.id, None)
            if taken:
                return [self._detection(obj, t.time, t.z, t.R) for t in taken]
        item = self._item(obj, sent, at)
        return [item] if item is not None else []

    def _detection(
        self, obj: WorldObject, time: float, position: np.ndarray, covariance: np.ndarray
    ) -> dict[str, object]:
        """A report item for ``obj``: a detection at ``time`` for the global model."""
        item: dict[str, object] = {
            "time": time,
            "class": obj.cls,
            "position": [float(v) for v in position],
            "covariance": [[float(v) for v in row] for row in covariance],
            "source": self.robot,
        }
        if self.detector is not None:
            item["detector"] = self.detector
        if obj.label is not None:
            item["label"] = obj.label
        return item

    def _item(self, obj: WorldObject, sent: _Sent | None, at: float) -> dict[str, object] | None:
        strategy = self.strategy
        if strategy is not Strategy.ALL and sent is not None and obj.last_seen <= sent.last_seen:
            return None  # not updated since it was last sent
        position = np.asarray(obj.position)
        covariance = np.asarray(obj.covariance)
        taken = self._taken.pop(obj.id, None) if strategy is Strategy.DETECTIONS else None
        if taken:
            position, covariance = combine_detections(taken, obj.velocity, at)
        elif strategy is Strategy.CI:
            covariance = 2.0 * covariance
        elif obj.label is None and strategy in _TRACKED_FACTOR_STRATEGIES:
            covariance = TRACKED_FACTOR * covariance
        elif strategy is Strategy.INFORMATION and sent is not None:
            gained = _new_information(position, covariance, sent, at)
            if gained is None:
                return None
            position, covariance = gained
        return self._detection(obj, at, position, covariance)


def _distance2(z: np.ndarray, R: np.ndarray, obj: WorldObject) -> float:
    """Squared Mahalanobis distance of ``z`` (noise ``R``) from ``obj``'s position."""
    delta = z - np.asarray(obj.position)
    return float(delta @ np.linalg.solve(np.asarray(obj.covariance) + R, delta))


def combine_detections(
    taken: Sequence[Taken], velocity: Sequence[float] | None, at: float
) -> tuple[np.ndarray, np.ndarray]:
    r"""One detection at ``at`` from the detections ``taken`` of one object: each position
    moved to ``at`` by the object's ``velocity`` (m/s; ``None``: not moved), combined
    by their information (the least-squares position, independent noises):

    .. math:: C = \Big(\sum_i R_i^{-1}\Big)^{-1}, \qquad
       z = C \sum_i R_i^{-1} \big(z_i + v\,(t - t_i)\big)

    Returns ``z`` ``(d,)`` and ``C`` ``(d, d)``."""
    v = np.zeros_like(taken[0].z) if velocity is None else np.asarray(velocity, dtype=float)
    information = np.zeros((len(v), len(v)))
    weighted = np.zeros(len(v))
    for t in taken:
        R_inv = np.linalg.inv(t.R)
        information += R_inv
        weighted += R_inv @ (t.z + v * (at - t.time))
    C = np.linalg.inv(information)
    return C @ weighted, (C + C.T) / 2.0


def _ahead(obj: WorldObject, horizon: float) -> WorldObject:
    """``obj`` moved on ``horizon`` s by its velocity (its covariance kept)."""
    if horizon <= 0.0 or obj.velocity is None:
        return obj
    position = np.asarray(obj.position) + horizon * np.asarray(obj.velocity)
    return replace(obj, position=tuple(float(v) for v in position))


def drifted(obj: WorldObject, expected: np.ndarray, gate: float) -> bool:
    r"""Whether the position the global side expects of ``obj`` is outside the local
    estimate's gate (send-on-delta):

    .. math:: (x - \hat x_g)^\top P^{-1} (x - \hat x_g) > \gamma

    with ``(x, P)`` the local position estimate, ``\hat x_g`` = ``expected`` (the
    replica of what was sent, predicted to now: module docstring) and ``γ`` =
    ``gate``, the chi-square quantile of a probability (:meth:`LocalModel.due`'s
    ``drift_gate``)."""
    delta = np.asarray(obj.position) - expected
    P = np.asarray(obj.covariance)
    return float(delta @ np.linalg.solve(P, delta)) > gate


def _new_information(
    x: np.ndarray, P: np.ndarray, sent: _Sent, at: float
) -> tuple[np.ndarray, np.ndarray] | None:
    """The equivalent measurement of what ``(x, P)`` knows beyond ``sent`` (information
    form), or ``None`` when it knows nothing more."""
    x_s = sent.position
    if sent.velocity is not None:
        x_s = x_s + sent.velocity * (at - sent.time)
    info = np.linalg.inv(P)
    info_s = np.linalg.inv(sent.covariance)
    gained = info - info_s
    gained = (gained + gained.T) / 2.0
    if float(np.linalg.eigvalsh(gained)[0]) <= 1e-9 * float(np.trace(info)):
        return None
    R = np.linalg.inv(gained)
    z = R @ (info @ x - info_s @ x_s)
    return z, (R + R.T) / 2.0


CONTINUITY_PROBABILITY = 0.99
"""The probability whose chi-square quantile a report of a robot's local object is
brought within, against the global object it went to before (:class:`Continuity`)."""


CONTINUITY_MEMORY = 10.0
"""s: :class:`Continuity` forgets a local object not reported for this long (local ids
are not reused: the local model dropped it, or it will be noted again when it comes
back), so its memory holds what robots report now, not every object ever reported."""


CONTINUITY_PATIENCE = 1
"""How many reports in a row of one local object :class:`Continuity` widens: one that
stays off the global object longer is another object."""


class Continuity:
    r"""The global side's memory of which global object each robot's local object went
    to, and a report widened so that it goes there again.

    The global MHF associates every report afresh: a robot's estimate that strays
    (a turn, a few stray detections combined) falls outside the gate of the global
    object it has fed so far and starts a duplicate, which the robot's later reports
    keep alive (issue 28). The local id travels with the report
    (:attr:`Report.local_ids`): :meth:`note` remembers, after the global model took a
    report, which global object each ``(robot, local id)`` updated; :meth:`widen`,
    before the next report is taken, widens the measurement noise of a report outside
    the ``probability`` gate of that object along the offset only, just enough to
    bring it to the gate's edge (Sherman-Morrison):

    .. math:: R' = R + \Big(\frac{1}{\gamma} - \frac{1}{q}\Big)\,\delta\delta^\top,
       \qquad q = \delta^\top (P_g + R)^{-1} \delta > \gamma,
       \qquad \delta^\top (P_g + R')^{-1} \delta = \gamma

    with ``δ`` the report's position minus the global object's, ``P_g`` its position
    covariance, ``γ`` the chi-square quantile of ``probability``. The report then fits
    the object it fed before, weighted less along the offset it disagrees in. Only a
    report no other global object could take is widened (none within the ``others``
    gate, the global model's ``gate_probability``): there the MHF's alternative is a
    new object, the duplicate; among close objects it decides as before, and a
    memory that went stale where robots crowd (local or global ids swapped) does not
    pull a report away from the object that fits it. At most ``patience`` reports in a
    row of one local object are widened: one still off at its next report is another
    object (two robots close together), not forced onto the first. Nothing in the MHF
    changes, so both engines run it.

    Parameters
    ----------
    dimension
        The world's dimension (the chi-square quantiles' degrees of freedom).
    probability
        The gate a widened report is brought to the edge of.
    others
        The gate within which another global object could take a report (the global
        knowledge's ``gate_probability``); ``None``: widen whatever the others.
    patience
        Widened reports in a row per local object.

    memory
        s after its last report that a local object is forgotten
        (:data:`CONTINUITY_MEMORY`).

    The memory holds one entry per local object reported within ``memory`` s of the
    newest report (local ids are not reused); older ones are dropped as reports come.
    """

    def __init__(
        self,
        dimension: int,
        probability: float = CONTINUITY_PROBABILITY,
        others: float | None = 0.9999,
        patience: int = CONTINUITY_PATIENCE,
        memory: float = CONTINUITY_MEMORY,
    ) -> None:
        for name, value in (("probability", probability), ("others", others)):
            if value is not None and not 0.0 < value < 1.0:
                raise ValueError(f"{name} must be a probability in (0, 1); got {value}")
        self.gate = float(chdtri(dimension, 1.0 - probability))
        self.others_gate = float(chdtri(dimension, 1.0 - others)) if others is not None else None
        self.patience = patience
        self.memory = memory
        self._global: dict[tuple[str, int], int] = {}
        self._reported: dict[tuple[str, int], float] = {}  # time of its last report
        self._run: dict[tuple[str, int], int] = {}  # widened reports in a row
        self.widened = 0
        """Reports widened so far."""

    def ingest(
        self,
        model: WorldModel,
        robot: str,
        detections: Sequence[Detection],
        local_ids: Sequence[int],
    ) -> IngestResult:
        """The global ``model`` takes one report of ``robot`` (``detections`` with their
        ``local_ids``) scan by scan, in time order (a ``scans`` report holds several):
        each scan widened (:meth:`widen`) against the model at its time, then noted
        (:meth:`note`). Raises what :meth:`WorldModel.ingest` raises (nothing of that
        scan is noted then; the report's earlier scans stay applied)."""
        if len(local_ids) != len(detections):
            raise ValueError(
                f"need one local id per detection; got {len(local_ids)} for {len(detections)}"
            )
        if not detections:
            return model.ingest([])
        times = sorted({d.time for d in detections})
        if len(times) > 1:  # a report of several scans (``scans``): one at a time
            applied = ignored = 0
            result = None
            for t in times:
                part = [i for i, d in enumerate(detections) if d.time == t]
                result = self.ingest(
                    model, robot, [detections[i] for i in part], [local_ids[i] for i in part]
                )
                applied += result.applied
                ignored += result.ignored
            assert result is not None
            return replace(result, applied=applied, ignored=ignored)
        at = detections[0].time
        before = WorldState(time=at, objects=())
        if model.latest_time is not None:
            # older than the history: the ingest refuses it
            with contextlib.suppress(BeforeHistoryError):
                before = model.world(time=at)
        scan = self.widen(robot, detections, local_ids, before)
        result = model.ingest(scan)
        self.note(robot, scan, local_ids, before, model.world(time=at))
        self._forget(robot, local_ids, at)
        return result

    def __len__(self) -> int:
        """Local objects remembered."""
        return len(self._global)

    def _forget(self, robot: str, local_ids: Sequence[int], at: float) -> None:
        """Note that ``robot`` reported ``local_ids`` at ``at``, and drop the local objects
        not reported for :attr:`memory` s (about once per ``memory`` of reports)."""
        for local_id in local_ids:
            self._reported[(robot, local_id)] = at
        newest = max(self._reported.values(), default=at)
        oldest = min(self._reported.values(), default=at)
        if newest - oldest <= 2.0 * self.memory:  # amortised: at most every memory s
            return
        for key, last in list(self._reported.items()):
            if newest - last > self.memory:
                del self._reported[key]
                self._global.pop(key, None)
                self._run.pop(key, None)

    def widen(
        self,
        robot: str,
        detections: Sequence[Detection],
        local_ids: Sequence[int],
        world: WorldState,
    ) -> list[Detection]:
        """``detections`` (one report of ``robot``), each one whose local object went to a
        global object of ``world`` (the global model at the report's time, before it
        takes the report) that it lies outside the gate of, and that no other object of
        ``world`` could take (``others`` gate), widened towards it."""
        objects = {o.id: o for o in world.objects}
        result = []
        for det, local_id in zip(detections, local_ids, strict=True):
            known = self._global.get((robot, local_id))
            obj = objects.get(known) if known is not None else None
            if obj is None or det.covariance is None:
                result.append(det)
                continue
            z = np.asarray(det.position)
            R = np.asarray(det.covariance, dtype=float)
            delta = z - np.asarray(obj.position)
            q = float(delta @ np.linalg.solve(np.asarray(obj.covariance) + R, delta))
            key = (robot, local_id)
            if q <= self.gate:
                self._run.pop(key, None)
                result.append(det)
                continue
            if self._run.get(key, 0) >= self.patience or (
                self.others_gate is not None
                and any(
                    _distance2(z, R, other) <= self.others_gate
                    for other in world.objects
                    if other.id != obj.id
                )
            ):
                result.append(det)
                continue
            R = R + (1.0 / self.gate - 1.0 / q) * np.outer(delta, delta)
            covariance = tuple(tuple(float(v) for v in row) for row in (R + R.T) / 2.0)
            result.append(det.model_copy(update={"covariance": covariance}))
            self._run[key] = self._run.get(key, 0) + 1
            self.widened += 1
        return result

    def note(
        self,
        robot: str,
        detections: Sequence[Detection],
        local_ids: Sequence[int],
        before: WorldState,
        after: WorldState,
    ) -> None:
        """Remember which global object each of ``detections`` (one report of ``robot``,
        as the global model took it) updated. ``before`` and ``after``: the global model
        at the report's time before and after it took the report. An object last seen at
        the report's time took the detection whose Kalman update of its ``before``
        version comes nearest its ``after`` version (a new object: nearest the
        detection), Mahalanobis distance with its ``after`` covariance, within the gate;
        nearest pairs first, each object and detection once. A detection that updated
        none (a tentative new object, clutter) keeps what was remembered."""
        prior = {o.id: o for o in before.objects}
        pairs: list[tuple[float, int, int]] = []
        for obj in after.objects:
            if not detections or obj.last_seen != detections[0].time:
                continue
            x, P = np.asarray(obj.position), np.asarray(obj.covariance)
            old = prior.get(obj.id)
            for k, det in enumerate(detections):
                z = np.asarray(det.position)
                if old is None:
                    expected = z
                else:
                    x_b, P_b = np.asarray(old.position), np.asarray(old.covariance)
                    R = np.asarray(det.covariance, dtype=float) if det.covariance else 0.0
                    # x+ = x + P (P + R)^-1 (z - x): the Kalman update of a position
                    expected = x_b + P_b @ np.linalg.solve(P_b + R, z - x_b)
                delta = x - expected
                d2 = float(delta @ np.linalg.solve(P, delta))
                if d2 <= self.gate:
                    pairs.append((d2, k, obj.id))
        pairs.sort()
        used: set[int] = set()
        done: set[int] = set()
        for _, k, object_id in pairs:
            if k in done or object_id in used:
                continue
            done.add(k)
            used.add(object_id)
            self._global[(robot, local_ids[k])] = object_id


class TeamModel:
    """Local models per robot and the global team model (paper 000).

    Parameters
    ----------
    knowledge
        Knowledge of the local models; the global one gets :func:`global_knowledge`.
    strategy
        What local reports carry (default ``scans``).
    continuity
        A probability: the global model keeps a robot's report on the global object
        its local object went to before (:class:`Continuity`; default
        :data:`CONTINUITY_PROBABILITY`); ``None``: every report is associated afresh.
    """

    def __init__(
        self,
        knowledge: Knowledge,
        strategy: Strategy | str = Strategy.SCANS,
        *,
        reorder_window: float = 0.0,
        continuity: float | None = CONTINUITY_PROBABILITY,
    ) -> None:
        self.knowledge = knowledge
        self.strategy = Strategy(strategy)
        self.locals: dict[str, LocalModel] = {}
        self.global_model = WorldModel(global_knowledge(knowledge), reorder_window=reorder_window)
        self.continuity = (
            Continuity(knowledge.world.dimension, continuity, knowledge.world.gate_probability)
            if continuity is not None
            else None
        )
        self.messages = 0
        self.bytes = 0

    def local(self, robot: str) -> LocalModel:
        """Robot ``robot``'s local model (created on first use)."""
        model = self.locals.get(robot)
        if model is None:
            model = self.locals[robot] = LocalModel(robot, self.knowledge, self.strategy)
        return model

    def ingest_local(
        self, robot: str, detections: DetectionInput | Iterable[DetectionInput]
    ) -> IngestResult:
        return self.local(robot).ingest(detections)

    def exchange(self, time: float | None = None, robots: Sequence[str] | None = None) -> int:
        """Every (or the named) local model reports at ``time``; the global model takes
        the reports in time order. Returns the detections sent."""
        reports = [
            r
            for name in (robots if robots is not None else sorted(self.locals))
            if (r := self.local(name).report(time)) is not None
        ]
        reports.sort(key=lambda r: (r.time, r.robot))
        sent = 0
        for report in reports:
            if self.continuity is not None:
                detections = [Detection.model_validate(d) for d in report.detections]
                self.continuity.ingest(
                    self.global_model, report.robot, detections, report.local_ids
                )
            else:
                self.global_model.ingest(list(report.detections))
            self.messages += 1
            self.bytes += report.size
            sent += len(report.detections)
        return sent

    def world(self, time: float | None = None) -> WorldState:
        """The global model's world."""
        return self.global_model.world(time=time)
