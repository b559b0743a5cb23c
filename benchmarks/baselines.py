"""Peer trackers for the benchmarks, with the world-model interface of the runner.

Every peer implements ``ingest(scan)`` and ``world(time)`` (``semwm.sim.runner.
WorldModelLike``), so :func:`semwm.sim.runner.run_scenario` feeds, times and scores
semwm and its peers identically (same scans, same truth times, same metrics).

* :class:`StoneSoupTracker`: Stone Soup's GNN (``GlobalNearestNeighbour`` +
  ``DistanceHypothesiser(Mahalanobis)``) or JPDA (``JPDA`` + ``PDAHypothesiser``,
  mixture-reduced as ``MultiTargetMixtureTracker`` does), Kalman predictor/updater
  with a constant-velocity model, ``MultiMeasurementInitiator`` and a covariance
  (+ time since update) deleter.
* :class:`FilterPyNN`: one ``filterpy.kalman.KalmanFilter`` (constant velocity) per
  object, greedy nearest-neighbour association with a Mahalanobis gate.

Noise comes from the knowledge file: measurement noise R of the detection's class
(or the detector's per-class override), process noise: the spectral density ``q``
of the class's first-order (constant-velocity) model, else of its zeroth-order one.
The tuning (:func:`tuning_from_knowledge`) is fixed and written into the results.
"""

from __future__ import annotations

import argparse
import datetime as dt
import itertools
import json
import os
import platform
import subprocess
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field
from importlib import metadata
from pathlib import Path
from typing import Any

import numpy as np

from semwm.detection import Detection
from semwm.knowledge.model import IMMFilterSpec, Knowledge
from semwm.world_types import WorldObject, WorldState

EPOCH = dt.datetime(2024, 1, 1)


class TrackerTimeout(RuntimeError):
    """A peer exceeded its wall-time budget for one run."""


@dataclass(frozen=True)
class Tuning:
    """The fixed tuning of the peers (written into the results)."""

    q: float  # CV spectral density (m^2/s^3), from the knowledge
    measurement_noise: dict[str, list[list[float]]]  # class -> R (m^2)
    detector_noise: dict[str, dict[str, list[list[float]]]]  # detector -> class -> R
    initial_velocity_variance: float  # m^2/s^2
    gate_mahalanobis: float = 3.0  # GNN / NN gate (Mahalanobis distance)
    min_points: int = 3  # MultiMeasurementInitiator / NN confirmation
    tentative_max_age_s: float = 0.5  # tentative track without update is dropped
    max_position_variance: float = 1.0  # deleter: trace(P_pos) > 2 * this
    max_time_without_update: float | None = None  # deleter (s), when the knowledge has it
    prob_detect: float = 0.9  # JPDA
    prob_gate: float = 0.9999  # JPDA
    clutter_spatial_density: float = 1e-3  # JPDA, per m^2 per scan
    extra: dict[str, Any] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


def _first_order_q(spec: Any) -> float | None:
    models = getattr(spec, "models", None) or (spec.model,)
    for m in models:
        if m.motion_model == "first_order":
            return float(np.asarray(m.system_noise)[0][0])
    return None


def clutter_area(scenario: Any) -> float:
    """The area (m^2) the peers spread one scan's clutter over: the sensor coverage of
    one source where the scenario states it (``metadata["coverage_area"]``: a robot's
    sensor disc, as its clutter is drawn), else the scenario's region."""
    coverage = scenario.metadata.get("coverage_area")
    if isinstance(coverage, int | float):
        return float(coverage)
    return float(np.prod([hi - lo for lo, hi in scenario.region]))


def tuning_from_knowledge(knowledge: Knowledge, *, scan_rate: float, area: float) -> Tuning:
    """The peers' tuning for ``knowledge``: same R and q as semwm's classes."""
    qs: list[float] = []
    zeroth: list[float] = []
    ivv: list[float] = []
    mpv: list[float] = []
    mtwu: list[float] = []
    noise: dict[str, list[list[float]]] = {}
    for name, c in knowledge.classes.items():
        if c.new_frequency <= 0.0:
            continue  # known-only classes (e.g. the Door)
        noise[name] = np.asarray(c.measurement_noise).tolist()
        q = _first_order_q(c.filter)
        if q is not None:
            qs.append(q)
        else:
            first = c.filter.models[0] if isinstance(c.filter, IMMFilterSpec) else c.filter.model
            zeroth.append(float(np.asarray(first.system_noise)[0][0]))
        ivv.append(float(np.asarray(c.initial_velocity_covariance)[0][0]))
        if c.max_position_variance is not None:
            mpv.append(float(c.max_position_variance))
        if c.max_time_without_update is not None:
            mtwu.append(float(c.max_time_without_update))
    detector_noise = {
        d: {k: np.asarray(v).tolist() for k, v in spec.measurement_noise.items()}
        for d, spec in knowledge.detectors.items()
        if spec.measurement_noise
    }
    clutter = sum(float(spec.clutter_frequency) for spec in knowledge.detectors.values())
    return Tuning(
        q=max(qs) if qs else (max(zeroth) if zeroth else 1e-4),
        measurement_noise=noise,
        detector_noise=detector_noise,
        initial_velocity_variance=max(ivv) if ivv and max(ivv) > 0 else 1.0,
        max_position_variance=max(mpv) if mpv else 1.0,
        max_time_without_update=min(mtwu) if mtwu else None,
        clutter_spatial_density=max(clutter / max(scan_rate, 1e-9) / area, 1e-6),
    )


def _noise(tuning: Tuning, d: Detection) -> np.ndarray:
    per_detector = tuning.detector_noise.get(d.detector or "", {})
    if d.cls in per_detector:
        return np.asarray(per_detector[d.cls], dtype=float)
    if d.cls in tuning.measurement_noise:
        return np.asarray(tuning.measurement_noise[d.cls], dtype=float)
    # a generic label (e.g. "Robot", "Can"): the largest R of the classes
    return max((np.asarray(r) for r in tuning.measurement_noise.values()), key=lambda r: r[0][0])


def _cv(dt_s: float, q: float) -> tuple[np.ndarray, np.ndarray]:
    """F and Q of a 2D constant-velocity model, state [x, vx, y, vy] (Stone Soup order)."""
    f1 = np.array([[1.0, dt_s], [0.0, 1.0]])
    q1 = q * np.array([[dt_s**3 / 3, dt_s**2 / 2], [dt_s**2 / 2, dt_s]])
    F = np.kron(np.eye(2), f1)
    Q = np.kron(np.eye(2), q1)
    return F, Q


def _world_object(
    oid: int, cls: str, x: np.ndarray, P: np.ndarray, last: float, created: float
) -> WorldObject:
    pos = (float(x[0]), float(x[2]))
    cov = ((float(P[0, 0]), float(P[0, 2])), (float(P[2, 0]), float(P[2, 2])))
    return WorldObject(
        id=oid,
        cls=cls,
        label=None,
        position=pos,
        velocity=(float(x[1]), float(x[3])),
        covariance=cov,
        existence=1.0,
        last_seen=last,
        created=created,
        mode_probabilities=None,
    )


# --------------------------------------------------------------------------- Stone Soup


class StoneSoupTracker:
    """Stone Soup GNN or JPDA, fed one scan at a time (``mode``: ``gnn``/``jpda``)."""

    def __init__(self, tuning: Tuning, mode: str = "gnn", *, time_limit: float = 120.0) -> None:
        import time as clock

        from stonesoup.dataassociator.neighbour import GlobalNearestNeighbour
        from stonesoup.dataassociator.probability import JPDA
        from stonesoup.deleter.error import CovarianceBasedDeleter
        from stonesoup.deleter.multi import CompositeDeleter
        from stonesoup.deleter.time import UpdateTimeDeleter
        from stonesoup.hypothesiser.distance import DistanceHypothesiser
        from stonesoup.hypothesiser.probability import PDAHypothesiser
        from stonesoup.initiator.simple import MultiMeasurementInitiator
        from stonesoup.measures import Mahalanobis
        from stonesoup.models.measurement.linear import LinearGaussian
        from stonesoup.models.transition.linear import (
            CombinedLinearGaussianTransitionModel,
            ConstantVelocity,
        )
        from stonesoup.predictor.kalman import KalmanPredictor
        from stonesoup.types.state import GaussianState
        from stonesoup.updater.kalman import KalmanUpdater

        self._clock = clock.perf_counter
        self._start = self._clock()
        self.time_limit = time_limit
        self.tuning = tuning
        self.mode = mode
        self._LinearGaussian = LinearGaussian
        self.transition = CombinedLinearGaussianTransitionModel(
            [ConstantVelocity(tuning.q), ConstantVelocity(tuning.q)]
        )
        default_r = _noise(tuning, Detection(time=0.0, cls="?", position=(0.0, 0.0)))
        self._default_model = LinearGaussian(ndim_state=4, mapping=(0, 2), noise_covar=default_r)
        self._models: dict[tuple[str, str], Any] = {}
        self.predictor = KalmanPredictor(self.transition)
        self.updater = KalmanUpdater(self._default_model)
        gnn_hyp = DistanceHypothesiser(
            self.predictor, self.updater, Mahalanobis(), missed_distance=tuning.gate_mahalanobis
        )
        if mode == "gnn":
            self.associator: Any = GlobalNearestNeighbour(gnn_hyp)
        elif mode == "jpda":
            self.associator = JPDA(
                PDAHypothesiser(
                    self.predictor,
                    self.updater,
                    clutter_spatial_density=tuning.clutter_spatial_density,
                    prob_detect=tuning.prob_detect,
                    prob_gate=tuning.prob_gate,
                )
            )
        else:
            raise ValueError(mode)
        thresh = 2.0 * tuning.max_position_variance
        deleters: list[Any] = [CovarianceBasedDeleter(covar_trace_thresh=thresh, mapping=[0, 2])]
        if tuning.max_time_without_update:
            deleters.append(UpdateTimeDeleter(dt.timedelta(seconds=tuning.max_time_without_update)))
        self.deleter = (
            CompositeDeleter(deleters, intersect=False) if len(deleters) > 1 else deleters[0]
        )
        v = tuning.initial_velocity_variance
        self.initiator = MultiMeasurementInitiator(
            prior_state=GaussianState(np.zeros((4, 1)), np.diag([0.0, v, 0.0, v])),
            measurement_model=None,
            deleter=UpdateTimeDeleter(dt.timedelta(seconds=tuning.tentative_max_age_s)),
            data_associator=GlobalNearestNeighbour(gnn_hyp),
            updater=self.updater,
            min_points=tuning.min_points,
        )
        self.tracks: set[Any] = set()
        self._ids: dict[Any, int] = {}
        self._cls: dict[Any, str] = {}
        self._created: dict[Any, float] = {}
        self._counter = itertools.count(1)

    def _model(self, d: Detection) -> Any:
        key = (d.detector or "", d.cls)
        model = self._models.get(key)
        if model is None:
            model = self._LinearGaussian(
                ndim_state=4, mapping=(0, 2), noise_covar=_noise(self.tuning, d)
            )
            self._models[key] = model
        return model

    def ingest(self, scan: Sequence[Detection]) -> None:
        from stonesoup.functions import gm_reduce_single
        from stonesoup.types.array import StateVectors
        from stonesoup.types.detection import Detection as SSDetection
        from stonesoup.types.prediction import GaussianStatePrediction
        from stonesoup.types.update import GaussianStateUpdate

        if self._clock() - self._start > self.time_limit:
            raise TrackerTimeout(f"{self.mode} exceeded {self.time_limit} s")
        if not scan:
            return
        t = scan[0].time
        stamp = EPOCH + dt.timedelta(seconds=t)
        dets = {
            SSDetection(
                np.array([[d.position[0]], [d.position[1]]]),
                timestamp=stamp,
                measurement_model=self._model(d),
                metadata={"cls": d.cls},
            )
            for d in scan
        }
        associations = self.associator.associate(self.tracks, dets, stamp)
        unassociated = set(dets)
        if self.mode == "gnn":
            for track, hyp in associations.items():
                if hyp:
                    track.append(self.updater.update(hyp))
                    unassociated.discard(hyp.measurement)
                    self._cls[track] = hyp.measurement.metadata["cls"]
                else:
                    track.append(hyp.prediction)
        else:
            for track, multi in associations.items():
                states, weights = [], []
                for hyp in multi:
                    states.append(self.updater.update(hyp) if hyp else hyp.prediction)
                    weights.append(hyp.probability)
                means = StateVectors([s.state_vector for s in states])
                covars = np.stack([s.covar for s in states], axis=2)
                mean, covar = gm_reduce_single(means, covars, np.asarray(weights, dtype=float))
                missed = next(h.weight for h in multi if not h)
                best = max((h for h in multi if h), key=lambda h: h.weight, default=None)
                if best is not None and best.weight > missed:
                    track.append(GaussianStateUpdate(mean, covar, multi, stamp))
                    self._cls[track] = best.measurement.metadata["cls"]
                else:
                    track.append(GaussianStatePrediction(mean, covar, stamp))
                for hyp in multi:
                    if hyp and hyp.weight > missed:
                        unassociated.discard(hyp.measurement)
        self.tracks -= self.deleter.delete_tracks(self.tracks)
        new = self.initiator.initiate(unassociated, stamp)
        for track in new:
            self._ids[track] = next(self._counter)
            self._created[track] = t
            last = track.states[-1]
            hyp = getattr(last, "hypothesis", None)
            meas = getattr(hyp, "measurement", None)
            self._cls[track] = meas.metadata["cls"] if meas is not None else "?"
        self.tracks |= new

    def world(self, time: float | None = None) -> WorldState:
        objects = []
        for track in self.tracks:
            state = track.state
            x = np.asarray(state.state_vector, dtype=float).ravel()
            P = np.asarray(state.covar, dtype=float)
            last = (state.timestamp - EPOCH).total_seconds()
            if time is not None and time > last:
                F, Q = _cv(time - last, self.tuning.q)
                x, P = F @ x, F @ P @ F.T + Q
            objects.append(
                _world_object(
                    self._ids.setdefault(track, next(self._counter)),
                    self._cls.get(track, "?"),
                    x,
                    P,
                    last,
                    self._created.get(track, last),
                )
            )
        return WorldState(time, tuple(objects))


# --------------------------------------------------------------------------- FilterPy NN


class _NNTrack:
    __slots__ = ("cls", "created", "hits", "id", "kf", "last", "time")

    def __init__(self, kf: Any, oid: int, cls: str, t: float) -> None:
        self.kf, self.id, self.cls = kf, oid, cls
        self.hits, self.last, self.created, self.time = 1, t, t, t


class FilterPyNN:
    """One FilterPy constant-velocity Kalman filter per object, greedy nearest
    neighbour (Mahalanobis, gated), confirmation after ``min_points`` hits."""

    def __init__(self, tuning: Tuning) -> None:
        self.tuning = tuning
        self.tracks: list[_NNTrack] = []
        self._counter = itertools.count(1)
        self._H = np.array([[1.0, 0.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0]])

    def _new(self, d: Detection) -> _NNTrack:
        from filterpy.kalman import KalmanFilter

        kf = KalmanFilter(dim_x=4, dim_z=2)
        kf.H = self._H.copy()
        R = _noise(self.tuning, d)
        v = self.tuning.initial_velocity_variance
        kf.x = np.array([d.position[0], 0.0, d.position[1], 0.0])
        kf.P = np.diag([R[0, 0], v, R[1, 1], v])
        return _NNTrack(kf, next(self._counter), d.cls, d.time)

    def ingest(self, scan: Sequence[Detection]) -> None:
        if not scan:
            return
        t = scan[0].time
        tun = self.tuning
        for tr in self.tracks:
            if t > tr.time:
                tr.kf.F, tr.kf.Q = _cv(t - tr.time, tun.q)
                tr.kf.predict()
                tr.time = t
        gate2 = tun.gate_mahalanobis**2
        pairs: list[tuple[float, int, int]] = []
        for j, d in enumerate(scan):
            z = np.asarray(d.position[:2], dtype=float)
            R = _noise(tun, d)
            for i, tr in enumerate(self.tracks):
                y = z - self._H @ tr.kf.x
                S = self._H @ tr.kf.P @ self._H.T + R
                m2 = float(y @ np.linalg.solve(S, y))
                if m2 < gate2:
                    pairs.append((m2, i, j))
        pairs.sort()
        used_t: set[int] = set()
        used_d: set[int] = set()
        for _, i, j in pairs:
            if i in used_t or j in used_d:
                continue
            used_t.add(i)
            used_d.add(j)
            tr, d = self.tracks[i], scan[j]
            tr.kf.update(np.asarray(d.position[:2], dtype=float), R=_noise(tun, d))
            tr.hits += 1
            tr.last = t
            tr.cls = d.cls
        keep = []
        for tr in self.tracks:
            P = tr.kf.P
            if P[0, 0] + P[2, 2] > 2.0 * tun.max_position_variance:
                continue
            if tr.hits < tun.min_points and t - tr.last > tun.tentative_max_age_s:
                continue
            if tun.max_time_without_update and t - tr.last > tun.max_time_without_update:
                continue
            keep.append(tr)
        self.tracks = keep
        for j, d in enumerate(scan):
            if j not in used_d:
                self.tracks.append(self._new(d))

    def world(self, time: float | None = None) -> WorldState:
        objects = []
        for tr in self.tracks:
            if tr.hits < self.tuning.min_points:
                continue
            x, P = tr.kf.x, tr.kf.P
            if time is not None and time > tr.time:
                F, Q = _cv(time - tr.time, self.tuning.q)
                x, P = F @ x, F @ P @ F.T + Q
            objects.append(_world_object(tr.id, tr.cls, x, P, tr.last, tr.created))
        return WorldState(time, tuple(objects))


# --------------------------------------------------------------------------- machine


def _version(name: str) -> str | None:
    try:
        return metadata.version(name)
    except metadata.PackageNotFoundError:
        return None


def _commit() -> str | None:
    try:
        out = subprocess.run(
            ["git", "rev-parse", "HEAD"],
            capture_output=True,
            text=True,
            check=True,
            cwd=Path(__file__).resolve().parent,
        )
        return out.stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return None


def machine_info() -> dict[str, Any]:
    return {
        "platform": platform.platform(),
        "processor": platform.processor() or platform.machine(),
        "cpu_count": os.cpu_count(),
        "python": platform.python_version(),
        "date": dt.datetime.now(dt.UTC).isoformat(timespec="seconds"),
        "commit": _commit(),
        # the other work on the machine: 1, 5 and 15 minute load averages now
        "load_average": [round(x, 2) for x in os.getloadavg()],
        "versions": {n: _version(n) for n in ("semwm", "stonesoup", "filterpy", "numpy", "scipy")},
    }


def fmt(value: Any, digits: int = 3) -> str:
    """A table cell: ``—`` for missing values, floats to ``digits`` significant digits."""
    if value is None:
        return "—"
    if isinstance(value, float):
        return f"{value:.{digits}g}"
    return str(value)


BENCHMARKS = Path(__file__).resolve().parent
RESULTS = BENCHMARKS / "results"
"""The committed results (``NAME.json``, ``NAME.md``): written only with ``--update-results``."""
OUT = BENCHMARKS / "out"
"""Where a benchmark run writes by default (git-ignored)."""


def add_output_arguments(parser: argparse.ArgumentParser) -> None:
    """``--update-results``: the flag every benchmark command takes."""
    parser.add_argument(
        "--update-results",
        action="store_true",
        help="write the committed benchmarks/results/ and re-render benchmarks/README.md "
        "(default: write to benchmarks/out/, untracked)",
    )


def write_results(
    directory: Path,
    name: str,
    doc: dict[str, Any],
    markdown: str,
    quick: bool,
    *,
    update_results: bool = False,
) -> Path:
    """Write ``NAME[_quick].json`` and ``.md`` and print the table; returns the folder.

    The files go to :data:`OUT` (untracked) unless ``update_results``: then to
    ``directory`` (the committed results, :data:`RESULTS`), and benchmarks/README.md
    is re-rendered from the committed results (``benchmarks/render_tables.py``).
    """
    target = directory if update_results else OUT
    target.mkdir(parents=True, exist_ok=True)
    suffix = "_quick" if quick else ""
    (target / f"{name}{suffix}.json").write_text(json.dumps(doc, indent=2) + "\n")
    (target / f"{name}{suffix}.md").write_text(markdown)
    print(markdown)
    print(f"wrote {target / name}{suffix}.json and .md")
    if update_results:
        import render_tables  # beside this file

        render_tables.main([])
    return target
