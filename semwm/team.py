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
* ``updated``: only objects updated by a local detection since the last report;
* ``ci``: ``updated`` with the covariance doubled: the Kalman update with ``2 P``
  is the local half of covariance intersection with weight 1/2, a conservative
  fusion for unknown correlation;
* ``information``: only the information the object gained since it was last sent
  (equivalent measurement, information form): ``I = P⁻¹ - P_s⁻¹`` and
  ``z = I⁻¹ (P⁻¹ x - P_s⁻¹ x_s)``, with ``x_s`` the sent position moved on by the
  sent velocity; an object whose information did not grow (``I`` not positive
  definite) is not sent, the first report of an object is sent whole.

When a report is sent (:meth:`LocalModel.report`): every report period, the
objects updated since they were last sent; between periods, at once, the objects
never sent and, with a ``drift_gate`` probability ``p`` (send-on-delta,
event-triggered estimation), the objects whose last sent estimate, predicted to
now as the global model predicts it, has drifted out of the local estimate's ``p``
gate (:func:`drifted`).

``benchmarks/bench_team.py`` measures them (docs/team.md has the figures); the
local id of each reported object travels with the report as a hint
(:attr:`Report.local_ids`) but the global MHF does not use it for association.

Pure: times are arguments, nothing reads a clock.
"""

from __future__ import annotations

import json
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from enum import StrEnum

import numpy as np
from scipy.special import chdtri

from semwm.knowledge.model import DetectorSpec, Knowledge
from semwm.knowledge.resolve import resolve
from semwm.validation import DetectionInput
from semwm.world import IngestResult, WorldModel
from semwm.world_types import WorldObject, WorldState

LOCAL_DETECTOR = "local_model"
"""The global model's detector for local-model reports (few false objects left)."""


class Strategy(StrEnum):
    """What a local model sends to the global one (see the module docstring)."""

    ALL = "all"
    UPDATED = "updated"
    CI = "ci"
    INFORMATION = "information"


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
class _Sent:
    time: float
    position: np.ndarray
    velocity: np.ndarray | None
    covariance: np.ndarray
    last_seen: float


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
        self._sent: dict[int, _Sent] = {}

    def ingest(self, detections: DetectionInput | Iterable[DetectionInput]) -> IngestResult:
        return self.model.ingest(detections)

    def world(self, time: float | None = None) -> WorldState:
        return self.model.world(time=time)

    def reset(self) -> None:
        self.model.reset()
        self._sent = {}

    def report(
        self,
        time: float | None = None,
        *,
        new_only: bool = False,
        drift_gate: float | None = None,
    ) -> Report | None:
        """The report at ``time`` (local clock; default the latest local time), or
        ``None`` when there is nothing to send. Remembers what it sent.

        ``new_only``: only objects never reported (a robot sends a new object at once
        rather than at its next report: the global model would otherwise learn of it
        a report period late) and, with ``drift_gate``, objects updated since they
        were sent whose sent estimate has drifted out of the local estimate's
        ``drift_gate`` gate (:func:`drifted`): the global model's view of them is
        wrong beyond the local uncertainty, so they are sent at once too."""
        if drift_gate is not None and not 0.0 < drift_gate < 1.0:
            raise ValueError(f"drift_gate must be a probability in (0, 1); got {drift_gate}")
        state = self.model.world(time=time)
        if state.time is None:
            return None
        at = state.time
        gate = (
            float(chdtri(self.model.knowledge.world.dimension, 1.0 - drift_gate))
            if drift_gate is not None
            else None
        )
        detections: list[dict[str, object]] = []
        ids: list[int] = []
        alive = set()
        for obj in state.objects:
            alive.add(obj.id)
            sent = self._sent.get(obj.id)
            if new_only and sent is not None:
                if gate is None or obj.last_seen <= sent.last_seen:
                    continue
                if not drifted(obj, sent, at, gate):
                    continue
            item = self._item(obj, sent, at)
            if item is None:
                continue
            detections.append(item)
            ids.append(obj.id)
            self._sent[obj.id] = _Sent(
                at,
                np.asarray(obj.position),
                np.asarray(obj.velocity) if obj.velocity is not None else None,
                np.asarray(obj.covariance),
                obj.last_seen,
            )
        self._sent = {k: v for k, v in self._sent.items() if k in alive}
        if not detections:
            return None
        return Report(self.robot, at, tuple(detections), tuple(ids))

    def _item(self, obj: WorldObject, sent: _Sent | None, at: float) -> dict[str, object] | None:
        strategy = self.strategy
        if strategy is not Strategy.ALL and sent is not None and obj.last_seen <= sent.last_seen:
            return None  # not updated since it was last sent
        position = np.asarray(obj.position)
        covariance = np.asarray(obj.covariance)
        if strategy is Strategy.CI:
            covariance = 2.0 * covariance
        elif strategy is Strategy.INFORMATION and sent is not None:
            gained = _new_information(position, covariance, sent, at)
            if gained is None:
                return None
            position, covariance = gained
        item: dict[str, object] = {
            "time": at,
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


def drifted(obj: WorldObject, sent: _Sent, at: float, gate: float) -> bool:
    r"""Whether the estimate ``sent`` of ``obj``, predicted to ``at`` as the global
    model sees it, is outside the local estimate's gate (send-on-delta).

    .. math::

        \hat x_s(t) = x_s + v_s (t - t_s), \qquad
        (x - \hat x_s(t))^\top P^{-1} (x - \hat x_s(t)) > \gamma

    with ``(x, P)`` the local position estimate at ``t`` = ``at``, ``x_s, v_s`` the
    position and velocity sent at ``t_s`` (``v_s = 0`` for classes without velocity:
    their motion model keeps the position) and ``γ`` = ``gate``, the chi-square
    quantile of a probability (:meth:`LocalModel.report`'s ``drift_gate``)."""
    predicted = sent.position
    if sent.velocity is not None:
        predicted = predicted + sent.velocity * (at - sent.time)
    delta = np.asarray(obj.position) - predicted
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


class TeamModel:
    """Local models per robot and the global team model (paper 000).

    Parameters
    ----------
    knowledge
        Knowledge of the local models; the global one gets :func:`global_knowledge`.
    strategy
        What local reports carry.
    """

    def __init__(
        self,
        knowledge: Knowledge,
        strategy: Strategy | str = Strategy.UPDATED,
        *,
        reorder_window: float = 0.0,
    ) -> None:
        self.knowledge = knowledge
        self.strategy = Strategy(strategy)
        self.locals: dict[str, LocalModel] = {}
        self.global_model = WorldModel(global_knowledge(knowledge), reorder_window=reorder_window)
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
            self.global_model.ingest(list(report.detections))
            self.messages += 1
            self.bytes += report.size
            sent += len(report.detections)
        return sent

    def world(self, time: float | None = None) -> WorldState:
        """The global model's world."""
        return self.global_model.world(time=time)
