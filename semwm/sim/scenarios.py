"""Scenario generators: the papers' simulations and a benchmark grid.

Every generator is pure: it takes a :class:`numpy.random.Generator` and size
parameters and returns a :class:`Scenario` (truth frames, detections sorted by
time, the shipped knowledge file it is meant for). Class and detector names are
those of the shipped knowledge files (``knowledge/*.yaml``).

* :func:`sim1`: paper 002 V-A, a static table with cups and cans seen by a camera.
* :func:`sim2`: paper 002 V-B (Fig. 2), a person walking around a 10 x 8 m room.
* :func:`robocup`: paper 000, two teams on a 12 x 18 m field, peers reporting their
  own labeled positions and observing every robot within 5 m.
* :func:`grid`: a static grid of objects all detected in every frame (benchmarks).

Harder variants for the world-quality benchmark (issue 9, ``benchmarks/bench_quality.py``):

* :func:`tabletop_wrong_labels`: an independent table top whose objects are first
  reported under a wrong sibling class.
* :func:`corner_occlusion`: a person hidden for 2-4 s while turning a corner of the room.
* :func:`door_exits`: several people entering and leaving the room through its door.
* :func:`datasheet`: people and boxes appearing in and leaving a sensor's field of view,
  meant for a knowledge file written only from the sensor's datasheet.
* :func:`patrol`: a robot patrolling a warehouse with a short-range detector: pallets
  and people out of view most of the time (a datasheet-only knowledge file).
* :func:`leftbehind`: a robot patrolling a room leaves objects on shelves and tables
  behind (out of view about 60 s, then seen again); some are picked up in view, some
  out of view; a fixed second camera elsewhere (issue 28).
* :func:`region_edge`: 3-D objects on the region's edge: a table top on its floor,
  books against its side wall, a sign on its back wall (issue 28).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np
from scipy.interpolate import CubicSpline

from semwm.detection import Detection

Region = tuple[tuple[float, float], ...]


@dataclass(frozen=True)
class TruthObject:
    """A real object at one time: its true id, class, position (m), velocity (m/s),
    label (an identity it reports itself, e.g. a peer robot's id) and whether a
    sensor could see it then (``False`` during an occlusion)."""

    id: str
    cls: str
    position: tuple[float, ...]
    velocity: tuple[float, ...]
    label: str | None = None
    visible: bool = True

    def to_dict(self) -> dict[str, object]:
        return {
            "id": self.id,
            "class": self.cls,
            "position": list(self.position),
            "velocity": list(self.velocity),
            "label": self.label,
            "visible": self.visible,
        }


@dataclass(frozen=True)
class TruthFrame:
    """Every real object at ``time`` (s)."""

    time: float
    objects: tuple[TruthObject, ...]

    def to_dict(self) -> dict[str, object]:
        return {"time": self.time, "objects": [o.to_dict() for o in self.objects]}


@dataclass(frozen=True)
class Scenario:
    """A generated scenario.

    Attributes
    ----------
    truth
        Truth frames, increasing in time: the times the world is evaluated at.
    detections
        Every detection, sorted by time; one scan = equal time and source.
    knowledge_file
        File name of the shipped knowledge the scenario is meant for.
    region
        One ``(min, max)`` pair per axis (m).
    metadata
        Scenario-specific facts for plots and tests: ``gospa_c`` (the cut-off
        distance that suits the scenario), ``moments`` (sim2), ``door`` and so on.
    """

    name: str
    truth: list[TruthFrame]
    detections: list[Detection]
    knowledge_file: str
    duration: float
    region: Region
    seed: int | None = None
    metadata: dict[str, object] = field(default_factory=dict)


def _frame_times(rate: float, duration: float) -> np.ndarray:
    if rate <= 0.0 or duration <= 0.0:
        raise ValueError(
            f"rate and duration must be positive; got rate={rate}, duration={duration}"
        )
    count = int(np.floor(duration * rate + 1e-9)) + 1
    return np.round(np.arange(count) / rate, 9)


def _uniform(rng: np.random.Generator, region: Region, n: int) -> np.ndarray:
    low = np.array([r[0] for r in region])
    high = np.array([r[1] for r in region])
    result: np.ndarray = low + rng.random((n, len(region))) * (high - low)
    return result


def _pos(values: np.ndarray) -> tuple[float, ...]:
    return tuple(round(float(v), 6) for v in values)


# --------------------------------------------------------------------------- sim1

SIM1_REGION: Region = ((0.0, 4.0), (0.0, 3.0))
SIM1_OBJECTS: tuple[tuple[str, str, tuple[float, float]], ...] = (
    ("table", "Table", (2.0, 1.5)),
    ("cup1", "Cup", (1.4, 1.2)),
    ("cup2", "Cup", (2.6, 1.9)),
    ("cokecan", "CokeCan", (1.8, 1.9)),
    ("beercan", "BeerCan", (2.5, 1.1)),
)
SIM1_CLASSES = ("Can", "CokeCan", "BeerCan", "Cup", "Table")
_SIM1_WRONG = {"Cup": "Table", "CokeCan": "Cup", "BeerCan": "Cup", "Table": "Cup"}


def sim1(
    rng: np.random.Generator,
    *,
    duration: float = 20.0,
    frame_rate: float = 2.5,
    detection_probability: float = 0.8,
    table_detection_probability: float = 0.2,
    generic_label_rate: float = 0.3,
    wrong_label_rate: float = 0.03,
    clutter_rate: float = 0.5,
    noise: float = 0.05,
    table_noise: float = 0.1,
    seed: int | None = None,
) -> Scenario:
    """Paper 002 simulation 1: a static table with two cups, a CokeCan and a BeerCan.

    A camera (``source="camera"``, detector ``camera``) takes a scan every
    ``1/frame_rate`` s. Each can and cup is seen with ``detection_probability``
    (2 Hz at the defaults, the knowledge's ``detection_frequency``), the table
    with ``table_detection_probability`` (0.5 Hz); positions carry Gaussian noise
    (``noise``, ``table_noise``: standard deviations, m, as in ``sim1.yaml``). A
    CokeCan or BeerCan detection carries the generic label ``Can`` with
    probability ``generic_label_rate``; any detection carries a wrong, taxonomy-
    incompatible label (a Cup labelled Table, a can labelled Cup, ...) with
    probability ``wrong_label_rate``. Clutter: Poisson, ``clutter_rate`` per
    second, uniform over the region and over the classes.
    """
    times = _frame_times(frame_rate, duration)
    truth_objects = tuple(TruthObject(oid, cls, pos, (0.0, 0.0)) for oid, cls, pos in SIM1_OBJECTS)
    truth = [TruthFrame(float(t), truth_objects) for t in times]
    detections: list[Detection] = []
    wrong: list[dict[str, object]] = []
    for t in times:
        for oid, cls, pos in SIM1_OBJECTS:
            is_table = cls == "Table"
            if rng.random() >= (table_detection_probability if is_table else detection_probability):
                continue
            sigma = table_noise if is_table else noise
            position = np.asarray(pos) + rng.normal(0.0, sigma, 2)
            label = cls
            if cls in ("CokeCan", "BeerCan") and rng.random() < generic_label_rate:
                label = "Can"
            if rng.random() < wrong_label_rate:
                label = _SIM1_WRONG[cls]
                wrong.append({"time": float(t), "object": oid, "class": label})
            detections.append(
                Detection(
                    time=float(t),
                    cls=label,
                    position=_pos(position),
                    source="camera",
                    detector="camera",
                )
            )
        n_clutter = rng.poisson(clutter_rate / frame_rate)
        for position in _uniform(rng, SIM1_REGION, n_clutter):
            cls = SIM1_CLASSES[int(rng.integers(len(SIM1_CLASSES)))]
            detections.append(
                Detection(
                    time=float(t),
                    cls=cls,
                    position=_pos(position),
                    source="camera",
                    detector="camera",
                )
            )
    return Scenario(
        name="sim1",
        truth=truth,
        detections=detections,
        knowledge_file="sim1.yaml",
        duration=float(times[-1]),
        region=SIM1_REGION,
        seed=seed,
        metadata={"gospa_c": 0.5, "wrong_labels": wrong},
    )


# --------------------------------------------------------------------------- sim2

SIM2_REGION: Region = ((0.0, 10.0), (0.0, 8.0))
SIM2_DOOR = (0.5, 7.5)
"""The known Door of ``knowledge/sim2.yaml``."""
SIM2_WAYPOINTS = (
    (0.5, 7.9),  # in the doorway
    (1.1, 6.6),
    (1.3, 4.5),
    (1.7, 2.3),
    (3.2, 1.2),
    (5.5, 1.0),
    (7.6, 1.3),
    (8.8, 2.6),
    (8.9, 4.6),
    (8.1, 6.3),
    (6.2, 6.9),
    (4.0, 6.9),
    (2.1, 6.8),
    (0.9, 7.1),
    (0.5, 7.9),  # back in the doorway
)
SIM2_FALSE_PAIR = ((6.5, 4.2, 0.0), (6.6, 4.3, 0.3))
"""The clustered false detections of point E: (x, y, time after E)."""


def _arc_length_path(
    waypoints: Sequence[tuple[float, float]], speed: float
) -> tuple[Callable[[np.ndarray], np.ndarray], Callable[[np.ndarray], np.ndarray], float]:
    """A smooth curve through ``waypoints`` walked at constant ``speed``.

    Returns position(s) and velocity(s) as functions of the time since the start,
    and the walk's duration.
    """
    points = np.asarray(waypoints, dtype=float)
    chord = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(points, axis=0), axis=1))])
    spline = CubicSpline(chord, points, bc_type="natural")
    fine = np.linspace(0.0, chord[-1], 4000)
    arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(spline(fine), axis=0), axis=1))])
    length = float(arc[-1])

    def parameter(t: np.ndarray) -> np.ndarray:
        result: np.ndarray = np.interp(np.clip(t * speed, 0.0, length), arc, fine)
        return result

    def position(t: np.ndarray) -> np.ndarray:
        return np.asarray(spline(parameter(t)))

    def velocity(t: np.ndarray) -> np.ndarray:
        tangent = np.asarray(spline(parameter(t), 1))
        norm = np.linalg.norm(tangent, axis=-1, keepdims=True)
        result: np.ndarray = speed * tangent / np.maximum(norm, 1e-12)
        return result

    return position, velocity, length / speed


def sim2(
    rng: np.random.Generator,
    *,
    rate: float = 10.0,
    speed: float = 1.0,
    detection_probability: float = 0.9,
    clutter_rate: float = 0.5,
    noise: float = 0.15,
    enter_time: float = 1.0,
    linger: float = 6.0,
    occlusion: float = 1.5,
    seed: int | None = None,
) -> Scenario:
    """Paper 002 simulation 2 (Fig. 2): one person in a 10 x 8 m room.

    The person enters through the door (upper-left corner, the Door of
    ``sim2.yaml`` at (0.5, 7.5)) at ``enter_time``, walks anti-clockwise around
    the room on a smooth curve at ``speed`` (m/s), and leaves through the door;
    the run goes on ``linger`` s after it left. A person detector
    (``person_detector``, ``source="camera"``) scans at ``rate`` Hz: the person is
    seen with ``detection_probability`` and noise ``noise`` (m, std), except
    during two occlusions of ``occlusion`` s, between moments A and B (in the
    lower-left bend) and C and D (in the upper-right bend). False detections:
    Poisson, ``clutter_rate`` per second, uniform over the room; and, seed-
    independently, two false detections close together in space and time at
    moment E (``SIM2_FALSE_PAIR``), away from the person, so that a false person
    track can be born and must later be removed by the uncertainty threshold.

    ``metadata["moments"]`` gives the times of A-E and F, the time by which the
    false track of E is expected to be gone (E + 6 s: with the knowledge's
    first-order noise its position variance passes ``max_position_variance``
    well before); ``metadata["false_pair"]`` gives the E detections.
    """
    position, velocity, walk = _arc_length_path(SIM2_WAYPOINTS, speed)
    duration = enter_time + walk + linger
    times = _frame_times(rate, duration)
    leave_time = enter_time + walk
    moments = {
        "A": enter_time + 0.27 * walk,
        "C": enter_time + 0.60 * walk,
        "E": enter_time + 0.45 * walk,
    }
    moments["B"] = moments["A"] + occlusion
    moments["D"] = moments["C"] + occlusion
    moments["F"] = moments["E"] + 6.0
    moments = {k: round(v, 3) for k, v in sorted(moments.items())}

    def occluded(t: float) -> bool:
        return moments["A"] <= t < moments["B"] or moments["C"] <= t < moments["D"]

    truth: list[TruthFrame] = []
    detections: list[Detection] = []
    false_pair = [(float(x), float(y), round(moments["E"] + dt, 3)) for x, y, dt in SIM2_FALSE_PAIR]
    pending = list(false_pair)
    for t in times:
        t = float(t)
        objects: tuple[TruthObject, ...] = ()
        if enter_time <= t <= leave_time:
            p = position(np.asarray(t - enter_time))
            v = velocity(np.asarray(t - enter_time))
            visible = not occluded(t)
            objects = (TruthObject("person", "Person", _pos(p), _pos(v), visible=visible),)
            if visible and rng.random() < detection_probability:
                detections.append(
                    Detection(
                        time=t,
                        cls="Person",
                        position=_pos(p + rng.normal(0.0, noise, 2)),
                        source="camera",
                        detector="person_detector",
                    )
                )
        truth.append(TruthFrame(t, objects))
        for xy in _uniform(rng, SIM2_REGION, rng.poisson(clutter_rate / rate)):
            detections.append(
                Detection(
                    time=t,
                    cls="Person",
                    position=_pos(xy),
                    source="camera",
                    detector="person_detector",
                )
            )
        while pending and pending[0][2] <= t + 1e-9:
            x, y, _ = pending.pop(0)
            detections.append(
                Detection(
                    time=t,
                    cls="Person",
                    position=(x, y),
                    source="camera",
                    detector="person_detector",
                )
            )
    return Scenario(
        name="sim2",
        truth=truth,
        detections=detections,
        knowledge_file="sim2.yaml",
        duration=float(times[-1]),
        region=SIM2_REGION,
        seed=seed,
        metadata={
            "gospa_c": 2.0,
            "moments": moments,
            "door": SIM2_DOOR,
            "enter_time": enter_time,
            "leave_time": round(leave_time, 3),
            "false_pair": [list(p) for p in false_pair],
        },
    )


# --------------------------------------------------------------------------- robocup

ROBOCUP_REGION: Region = ((-9.0, 9.0), (-6.0, 6.0))
ROBOT_RADIUS = 0.25


def _start_stop_paths(
    rng: np.random.Generator,
    n: int,
    steps: int,
    dt: float,
    max_speed: float,
    acceleration: float = 3.0,
) -> tuple[np.ndarray, np.ndarray]:
    """Start-stop motion: each robot drives to a random goal at a random cruise
    speed (at most ``max_speed``) with bounded acceleration, waits, and repeats.

    Returns positions and velocities, shape ``(steps, n, 2)``.
    """
    margin = 0.5
    region = tuple((lo + margin, hi - margin) for lo, hi in ROBOCUP_REGION)
    position = _uniform(rng, region, n)
    velocity = np.zeros((n, 2))
    goal = _uniform(rng, region, n)
    cruise = rng.uniform(0.3 * max_speed, max_speed, n)
    wait = np.zeros(n)
    positions = np.zeros((steps, n, 2))
    velocities = np.zeros((steps, n, 2))
    for k in range(steps):
        positions[k], velocities[k] = position, velocity
        for i in range(n):
            if wait[i] > 0.0:
                wait[i] -= dt
                desired = np.zeros(2)
            else:
                offset = goal[i] - position[i]
                distance = float(np.linalg.norm(offset))
                if distance < 0.1:
                    wait[i] = rng.uniform(0.3, 1.5)
                    goal[i] = _uniform(rng, region, 1)[0]
                    cruise[i] = rng.uniform(0.3 * max_speed, max_speed)
                    desired = np.zeros(2)
                else:
                    # slow down to stop at the goal: v^2 = 2 a d
                    speed = min(cruise[i], np.sqrt(2.0 * acceleration * distance))
                    desired = offset / distance * speed
            change = desired - velocity[i]
            norm = float(np.linalg.norm(change))
            if norm > acceleration * dt:
                change *= acceleration * dt / norm
            velocity[i] = velocity[i] + change
            position[i] = position[i] + velocity[i] * dt
    return positions, velocities


def _occluded(observer: np.ndarray, target: int, others: np.ndarray) -> bool:
    """Whether ``others[target]`` hides behind a closer robot seen from ``observer``:
    the closer robot's disc (radius ``ROBOT_RADIUS``) covers the bearing line."""
    offsets = others - observer
    distances = np.linalg.norm(offsets, axis=1)
    d_t = distances[target]
    direction = offsets[target] / max(d_t, 1e-9)
    for j in range(len(others)):
        if j == target or distances[j] >= d_t or distances[j] < 1e-9:
            continue
        along = float(offsets[j] @ direction)
        if along <= 0.0:
            continue
        across = abs(float(offsets[j, 0] * direction[1] - offsets[j, 1] * direction[0]))
        if across < ROBOT_RADIUS:
            return True
    return False


def robocup(
    rng: np.random.Generator,
    *,
    n_peers: int = 5,
    n_opponents: int = 5,
    duration: float = 10.0,
    rate: float = 30.0,
    truth_rate: float = 10.0,
    sensor_range: float = 5.0,
    noise: float = 0.3,
    self_noise: float = 0.1,
    dropout: float = 0.1,
    clutter_rate: float = 1.0,
    max_speed: float = 4.0,
    seed: int | None = None,
) -> Scenario:
    """Paper 000: a RoboCup MSL match on the 12 x 18 m field.

    ``n_peers`` peers (``peer1``...) and ``n_opponents`` opponents (``opp1``...)
    move start-stop up to ``max_speed`` m/s. At ``rate`` Hz every peer sends one
    scan (``source`` = its id, ``sensor_position`` = its position): its own
    position (class ``Peer``, detector ``self_localization``, label = its id,
    noise ``self_noise``) and every other robot within ``sensor_range`` m (class
    ``Robot``: the omnivision camera cannot tell peers from opponents; detector
    ``omnivision``, noise ``noise``), except robots hidden behind a closer one
    and random dropouts (probability ``dropout``); plus clutter, Poisson,
    ``clutter_rate`` per second per peer, uniform in its sensor disc on the
    field. Truth frames at ``truth_rate`` Hz.
    """
    if n_peers < 1 or n_opponents < 0:
        raise ValueError(f"need n_peers >= 1, n_opponents >= 0; got {n_peers}, {n_opponents}")
    dt = 1.0 / rate
    times = _frame_times(rate, duration)
    n = n_peers + n_opponents
    positions, velocities = _start_stop_paths(rng, n, len(times), dt, max_speed)
    ids = [f"peer{i + 1}" for i in range(n_peers)] + [f"opp{i + 1}" for i in range(n_opponents)]
    classes = ["Peer"] * n_peers + ["Opponent"] * n_opponents
    truth_every = max(1, round(rate / truth_rate))
    truth: list[TruthFrame] = []
    detections: list[Detection] = []
    low = np.array([r[0] for r in ROBOCUP_REGION])
    high = np.array([r[1] for r in ROBOCUP_REGION])
    hidden = 0
    for k, t in enumerate(times):
        t = float(t)
        here = positions[k]
        if k % truth_every == 0:
            truth.append(
                TruthFrame(
                    t,
                    tuple(
                        TruthObject(
                            ids[i],
                            classes[i],
                            _pos(here[i]),
                            _pos(velocities[k, i]),
                            label=ids[i] if i < n_peers else None,
                        )
                        for i in range(n)
                    ),
                )
            )
        for p in range(n_peers):
            observer = here[p]
            sensor = _pos(observer)
            detections.append(
                Detection(
                    time=t,
                    cls="Peer",
                    position=_pos(observer + rng.normal(0.0, self_noise, 2)),
                    source=ids[p],
                    detector="self_localization",
                    label=ids[p],
                    sensor_position=sensor,
                )
            )
            for j in range(n):
                if j == p or np.linalg.norm(here[j] - observer) > sensor_range:
                    continue
                if _occluded(observer, j, here):
                    hidden += 1
                    continue
                if rng.random() < dropout:
                    continue
                detections.append(
                    Detection(
                        time=t,
                        cls="Robot",
                        position=_pos(here[j] + rng.normal(0.0, noise, 2)),
                        source=ids[p],
                        detector="omnivision",
                        sensor_position=sensor,
                    )
                )
            for _ in range(rng.poisson(clutter_rate * dt)):
                radius = sensor_range * np.sqrt(rng.random())
                angle = rng.uniform(0.0, 2.0 * np.pi)
                xy = np.clip(
                    observer + radius * np.array([np.cos(angle), np.sin(angle)]), low, high
                )
                detections.append(
                    Detection(
                        time=t,
                        cls="Robot",
                        position=_pos(xy),
                        source=ids[p],
                        detector="omnivision",
                        sensor_position=sensor,
                    )
                )
    return Scenario(
        name="robocup",
        truth=truth,
        detections=detections,
        knowledge_file="robocup.yaml",
        duration=float(times[-1]),
        region=ROBOCUP_REGION,
        seed=seed,
        metadata={
            "gospa_c": 2.0,
            "n_peers": n_peers,
            "n_opponents": n_opponents,
            "occluded_detections": hidden,
            "sensor_range": sensor_range,
            "coverage_area": float(np.pi * sensor_range**2),  # one observer's clutter disc
        },
    )


# --------------------------------------------------------------------------- grid


def grid(
    rng: np.random.Generator,
    *,
    n_objects: int = 25,
    duration: float = 5.0,
    rate: float = 10.0,
    spacing: float = 2.0,
    noise: float = 0.05,
    seed: int | None = None,
) -> Scenario:
    """A benchmark: ``n_objects`` static ``Thing`` objects on a square grid
    ``spacing`` m apart, every one detected in every frame at ``rate`` Hz with
    noise ``noise`` (m), no clutter (knowledge: ``knowledge/grid.yaml``)."""
    if n_objects < 1:
        raise ValueError(f"n_objects must be at least 1; got {n_objects}")
    side = int(np.ceil(np.sqrt(n_objects)))
    cells = [(spacing * (i % side), spacing * (i // side)) for i in range(n_objects)]
    extent = spacing * side
    region: Region = ((-spacing, extent), (-spacing, extent))
    truth_objects = tuple(
        TruthObject(f"thing{i + 1}", "Thing", xy, (0.0, 0.0)) for i, xy in enumerate(cells)
    )
    times = _frame_times(rate, duration)
    truth = [TruthFrame(float(t), truth_objects) for t in times]
    detections = [
        Detection(
            time=float(t),
            cls="Thing",
            position=_pos(np.asarray(xy) + rng.normal(0.0, noise, 2)),
            source="camera",
            detector="camera",
        )
        for t in times
        for xy in cells
    ]
    return Scenario(
        name="grid",
        truth=truth,
        detections=detections,
        knowledge_file="grid.yaml",
        duration=float(times[-1]),
        region=region,
        seed=seed,
        metadata={"gospa_c": 1.0, "n_objects": n_objects},
    )


# --------------------------------------------------------------------------- harder variants

TABLETOP_CLASSES = ("CokeCan", "BeerCan", "Cup")
"""Classes of :func:`tabletop_wrong_labels` (``knowledge/sim1.yaml``'s taxonomy)."""
TABLETOP_CONFUSIONS: dict[str, tuple[str, ...]] = {
    "CokeCan": ("BeerCan",),
    "BeerCan": ("CokeCan",),
    "Cup": ("CokeCan", "BeerCan"),
}
"""The wrong class a detector reports for each true class: the sibling (the other
can under ``Can``), for a cup one of the cans (siblings at the top level)."""
TABLETOP_SUPERCLASS = {"CokeCan": "Can", "BeerCan": "Can"}


def _separated_points(
    rng: np.random.Generator, region: Region, n: int, min_distance: float, margin: float
) -> np.ndarray:
    """``n`` uniform points inside ``region`` shrunk by ``margin``, pairwise at least
    ``min_distance`` apart (rejection sampling, bounded)."""
    if n == 0:
        return np.zeros((0, len(region)))
    inner: Region = tuple((lo + margin, hi - margin) for lo, hi in region)
    points: list[np.ndarray] = []
    for _ in range(1000 * n):
        candidate = _uniform(rng, inner, 1)[0]
        if all(np.linalg.norm(candidate - q) >= min_distance for q in points):
            points.append(candidate)
            if len(points) == n:
                return np.asarray(points)
    raise ValueError(
        f"cannot place {n} points {min_distance} m apart in {region} with margin {margin}"
    )


def tabletop_wrong_labels(
    rng: np.random.Generator,
    *,
    n_objects: tuple[int, int] = (4, 8),
    duration: float = 20.0,
    frame_rate: float = 2.5,
    detection_probability: float = 0.8,
    wrong_first: tuple[int, int] = (1, 3),
    wrong_later_rate: float = 0.05,
    superclass_rate: float = 0.15,
    clutter_rate: float = 0.5,
    noise: float = 0.05,
    min_separation: float = 0.4,
    placed_within: float = 5.0,
    seed: int | None = None,
) -> Scenario:
    """A table top whose objects are first reported under a wrong sibling class.

    Tests class lock-in, issue 9 item 4 ("a CokeCan first reported twice as
    BeerCan becomes a BeerCan object ... and starts a second object 5 cm away"),
    on a generator independent of :func:`sim1`'s code and layout.

    Between ``n_objects[0]`` and ``n_objects[1]`` static objects (the first a
    CokeCan, the second a BeerCan, the others drawn from ``TABLETOP_CLASSES``) are
    put at random places on the table (``SIM1_REGION``, at least
    ``min_separation`` m apart and 0.3 m from the edge), each at a random time in
    ``[0, placed_within]`` s (the truth holds it from then on). A camera
    (``camera``) scans at ``frame_rate`` Hz and sees each object with
    ``detection_probability``, noise ``noise`` (m, std). The first
    ``wrong_first[0]``..``wrong_first[1]`` detections of each object carry a wrong
    class (``TABLETOP_CONFUSIONS``); later ones are wrong with probability
    ``wrong_later_rate``, a can's report is its superclass ``Can`` with probability
    ``superclass_rate``, else the true class. Clutter: Poisson, ``clutter_rate``
    per second, uniform over the table and the classes. Knowledge:
    ``knowledge/sim1.yaml``.
    """
    low, high = n_objects
    n = int(rng.integers(low, high + 1))
    classes = ["CokeCan", "BeerCan"] + [
        TABLETOP_CLASSES[int(i)] for i in rng.integers(len(TABLETOP_CLASSES), size=n - 2)
    ]
    places = _separated_points(rng, SIM1_REGION, n, min_separation, 0.3)
    times = _frame_times(frame_rate, duration)
    placed = rng.uniform(0.0, placed_within, n)
    n_wrong = rng.integers(wrong_first[0], wrong_first[1] + 1, n)
    objects = [
        TruthObject(f"{cls.lower()}{i + 1}", cls, _pos(places[i]), (0.0, 0.0))
        for i, cls in enumerate(classes)
    ]
    seen = [0] * n
    truth: list[TruthFrame] = []
    detections: list[Detection] = []
    wrong: list[dict[str, object]] = []
    report_classes = (*TABLETOP_CLASSES, "Can")
    for t in times:
        t = float(t)
        present = [i for i in range(n) if placed[i] <= t]
        truth.append(TruthFrame(t, tuple(objects[i] for i in present)))
        for i in present:
            if rng.random() >= detection_probability:
                continue
            cls = classes[i]
            label = cls
            if seen[i] < n_wrong[i] or rng.random() < wrong_later_rate:
                options = TABLETOP_CONFUSIONS[cls]
                label = options[int(rng.integers(len(options)))]
                wrong.append({"time": t, "object": objects[i].id, "class": label})
            elif cls in TABLETOP_SUPERCLASS and rng.random() < superclass_rate:
                label = TABLETOP_SUPERCLASS[cls]
            seen[i] += 1
            detections.append(
                Detection(
                    time=t,
                    cls=label,
                    position=_pos(places[i] + rng.normal(0.0, noise, 2)),
                    source="camera",
                    detector="camera",
                )
            )
        for position in _uniform(rng, SIM1_REGION, rng.poisson(clutter_rate / frame_rate)):
            detections.append(
                Detection(
                    time=t,
                    cls=report_classes[int(rng.integers(len(report_classes)))],
                    position=_pos(position),
                    source="camera",
                    detector="camera",
                )
            )
    return Scenario(
        name="tabletop_wrong_labels",
        truth=truth,
        detections=detections,
        knowledge_file="sim1.yaml",
        duration=float(times[-1]),
        region=SIM1_REGION,
        seed=seed,
        metadata={
            "gospa_c": 0.5,
            "wrong_labels": wrong,
            "wrong_first": [int(k) for k in n_wrong],
            "placed": [round(float(p), 3) for p in placed],
        },
    )


def _walk(
    waypoints: Sequence[tuple[float, float]], speed: float, start: float, times: np.ndarray
) -> tuple[np.ndarray, np.ndarray, float]:
    """A smooth walk through ``waypoints`` at ``speed`` (m/s) starting at ``start`` (s).

    Returns the positions and velocities at ``times``, shape ``(len(times), 2)`` (the
    walker stands still at the first waypoint before ``start`` and at the last once
    there), and the time it arrives.
    """
    position, velocity, walk = _arc_length_path(waypoints, speed)
    since = np.clip(times - start, 0.0, walk)
    moving = ((times >= start) & (times <= start + walk))[:, None]
    return position(since), np.where(moving, velocity(since), 0.0), start + walk


def _inside(position: np.ndarray, region: Region) -> bool:
    return all(lo <= float(v) <= hi for v, (lo, hi) in zip(position, region, strict=True))


def _person_detection(
    rng: np.random.Generator, t: float, position: np.ndarray, noise: float
) -> Detection:
    return Detection(
        time=t,
        cls="Person",
        position=_pos(position + rng.normal(0.0, noise, 2)),
        source="camera",
        detector="person_detector",
    )


def _room_clutter(rng: np.random.Generator, t: float, expected: float) -> list[Detection]:
    return [
        Detection(
            time=t, cls="Person", position=_pos(xy), source="camera", detector="person_detector"
        )
        for xy in _uniform(rng, SIM2_REGION, rng.poisson(expected))
    ]


def corner_occlusion(
    rng: np.random.Generator,
    *,
    rate: float = 10.0,
    speed: tuple[float, float] = (0.8, 1.3),
    detection_probability: float = 0.9,
    clutter_rate: float = 0.5,
    noise: float = 0.15,
    occlusion: tuple[float, float] = (2.0, 4.0),
    enter_time: float = 1.0,
    linger: float = 5.0,
    seed: int | None = None,
) -> Scenario:
    """A person turns two corners of the room and is hidden for 2-4 s at each.

    Tests issue 9 item 6 ("lost after an occlusion at a corner: the prediction runs
    outside the room, the object is dropped ... found again only 13 s later").

    In sim2's room (``SIM2_REGION``, door at ``SIM2_DOOR``, knowledge
    ``knowledge/sim2.yaml``) a person enters through the door at ``enter_time``,
    walks down the left wall, turns the lower-left corner, walks along the bottom
    wall, turns the lower-right corner and walks up to a random point where they
    stay for ``linger`` s until the end. Wall distances (0.7-1.2 m), corner places
    and the walking speed (``speed``, m/s) are random. At each corner the person is
    hidden (truth ``visible=False``, no detection) for a duration drawn from
    ``occlusion`` (s), starting 0.3-1.0 s before the corner: a constant-velocity
    prediction leaves the room within about a second. Otherwise the person
    detector (10 Hz) sees them with ``detection_probability`` and noise ``noise``;
    clutter Poisson ``clutter_rate`` per second over the room.
    ``metadata["occlusions"]`` lists the hidden intervals, ``metadata["corners"]``
    the corner points.
    """
    left = rng.uniform(0.7, 1.2)
    bottom = rng.uniform(0.7, 1.2)
    right = rng.uniform(6.5, 9.0)
    end_y = rng.uniform(3.5, 6.0)
    walker_speed = rng.uniform(*speed)
    door_x, door_y = SIM2_DOOR[0], 7.9
    waypoints = (
        (door_x, door_y),
        (left, 6.6),
        (left, 4.0),
        (left, 2.0),
        (left, bottom),
        (2.5, bottom),
        (right - 1.5, bottom),
        (right, bottom),
        (right, 2.0),
        (right, end_y),
    )
    _, _, arrive = _walk(waypoints, walker_speed, enter_time, np.zeros(1))
    times = _frame_times(rate, arrive + linger)
    positions, velocities, _ = _walk(waypoints, walker_speed, enter_time, times)
    fine = np.arange(enter_time, arrive, 0.01)
    along, _, _ = _walk(waypoints, walker_speed, enter_time, fine)
    corners = [(left, bottom), (right, bottom)]
    occlusions: list[tuple[float, float]] = []
    for corner in corners:
        distances = np.linalg.norm(along - np.asarray(corner), axis=1)
        t_corner = float(fine[int(np.argmin(distances))])
        start = t_corner - rng.uniform(0.3, 1.0)
        occlusions.append((round(start, 3), round(start + rng.uniform(*occlusion), 3)))
    truth: list[TruthFrame] = []
    detections: list[Detection] = []
    for t, p, v in zip(times, positions, velocities, strict=True):
        t = float(t)
        objects: tuple[TruthObject, ...] = ()
        if t >= enter_time:
            visible = not any(a <= t < b for a, b in occlusions)
            objects = (TruthObject("person", "Person", _pos(p), _pos(v), visible=visible),)
            if visible and rng.random() < detection_probability:
                detections.append(_person_detection(rng, t, p, noise))
        truth.append(TruthFrame(t, objects))
        detections.extend(_room_clutter(rng, t, clutter_rate / rate))
    return Scenario(
        name="corner_occlusion",
        truth=truth,
        detections=detections,
        knowledge_file="sim2.yaml",
        duration=float(times[-1]),
        region=SIM2_REGION,
        seed=seed,
        metadata={
            "gospa_c": 2.0,
            "door": SIM2_DOOR,
            "occlusions": [list(o) for o in occlusions],
            "corners": [[round(x, 3), round(y, 3)] for x, y in corners],
            "speed": round(float(walker_speed), 3),
        },
    )


def door_exits(
    rng: np.random.Generator,
    *,
    n_people: tuple[int, int] = (3, 5),
    duration: float = 60.0,
    rate: float = 10.0,
    speed: tuple[float, float] = (0.7, 1.3),
    detection_probability: float = 0.9,
    clutter_rate: float = 0.5,
    noise: float = 0.15,
    seed: int | None = None,
) -> Scenario:
    """People enter and leave the room through its door, several over the run.

    Tests issue 9 item 5 ("a person who walks out through the door is published
    1.8 m outside a 4 m room") and the issue's "leaving and appearing": the world
    must not show anyone outside the room once they left.

    Between ``n_people[0]`` and ``n_people[1]`` people (``person1``...) each come in
    from outside (0.5, 8.6), through the doorway (0.5, 7.9) next to sim2's Door,
    walk to 1-3 random points of the room at a random ``speed`` (m/s), walk back
    and leave the same way. Entry times are drawn over the first half of the run,
    so walks overlap. The truth holds a person only while inside the room
    (``SIM2_REGION``); the person detector (10 Hz, inside the room only) sees them
    with ``detection_probability`` and noise ``noise``; clutter Poisson
    ``clutter_rate`` per second over the room. Knowledge ``knowledge/sim2.yaml``.
    ``metadata["visits"]`` gives each person's entry and exit times (the exit
    may be after the end of the run).
    """
    n = int(rng.integers(n_people[0], n_people[1] + 1))
    outside = (SIM2_DOOR[0], 8.6)
    doorway = (SIM2_DOOR[0], 7.9)
    hall = (1.2, 6.8)
    times = _frame_times(rate, duration)
    walkers: list[tuple[np.ndarray, np.ndarray, float, float]] = []
    entries = np.sort(rng.uniform(1.0, max(1.0, 0.5 * duration), n))
    for entry in entries:
        stops = _uniform(rng, ((1.5, 9.0), (1.0, 6.5)), int(rng.integers(1, 4)))
        waypoints = (
            outside,
            doorway,
            hall,
            *((float(x), float(y)) for x, y in stops),
            hall,
            doorway,
            outside,
        )
        positions, velocities, arrive = _walk(
            waypoints, float(rng.uniform(*speed)), float(entry), times
        )
        walkers.append((positions, velocities, float(entry), arrive))
    truth: list[TruthFrame] = []
    detections: list[Detection] = []
    visits: list[list[float | None]] = [[None, None] for _ in range(n)]
    for k, t in enumerate(times):
        t = float(t)
        objects = []
        for i, (positions, velocities, entry, arrive) in enumerate(walkers):
            if not entry <= t <= arrive:
                continue
            p, v = positions[k], velocities[k]
            if not _inside(p, SIM2_REGION):
                continue
            visits[i][0] = t if visits[i][0] is None else visits[i][0]
            visits[i][1] = t
            objects.append(TruthObject(f"person{i + 1}", "Person", _pos(p), _pos(v)))
            if rng.random() < detection_probability:
                detections.append(_person_detection(rng, t, p, noise))
        truth.append(TruthFrame(t, tuple(objects)))
        detections.extend(_room_clutter(rng, t, clutter_rate / rate))
    return Scenario(
        name="door_exits",
        truth=truth,
        detections=detections,
        knowledge_file="sim2.yaml",
        duration=float(times[-1]),
        region=SIM2_REGION,
        seed=seed,
        metadata={
            "gospa_c": 2.0,
            "door": SIM2_DOOR,
            "visits": visits,
            "walk_ends": [round(a, 3) for _, _, _, a in walkers],
        },
    )


DATASHEET_REGION: Region = ((0.0, 12.0), (0.0, 8.0))
"""The field of view of :func:`datasheet`'s sensor (m)."""


def _border_point(rng: np.random.Generator, region: Region, side: int) -> np.ndarray:
    (x0, x1), (y0, y1) = region
    u = rng.random()
    corners = {
        0: (x0 + u * (x1 - x0), y0),
        1: (x1, y0 + u * (y1 - y0)),
        2: (x0 + u * (x1 - x0), y1),
        3: (x0, y0 + u * (y1 - y0)),
    }
    return np.asarray(corners[side])


def datasheet(
    rng: np.random.Generator,
    *,
    duration: float = 60.0,
    rate: float = 10.0,
    recall: float = 0.9,
    false_positives_per_frame: float = 0.2,
    noise: float = 0.1,
    person_rate: float = 0.1,
    n_boxes: tuple[int, int] = (2, 4),
    speed: tuple[float, float] = (0.8, 1.5),
    seed: int | None = None,
) -> Scenario:
    """People crossing and boxes put down and picked up in one sensor's field of view.

    Tests issue 9 items 1 and 3 (a knowledge file a user writes from documented
    rates keeps the world empty; the birth/pruning cliff): the sensor is the one
    ``benchmarks/knowledge/datasheet.yaml`` describes from its datasheet only.

    An overhead detector (``overhead``, ``source="overhead"``) with a 12 x 8 m field
    of view (``DATASHEET_REGION``) runs at ``rate`` Hz with ``recall`` (probability
    of detecting an object in view per frame), ``false_positives_per_frame``
    (Poisson, uniform over the view, class Person or Box) and position noise
    ``noise`` (m, std). People arrive as a Poisson process (``person_rate`` Hz),
    each entering the view at a random point of its border and walking straight
    to a random point of another side at ``speed`` m/s; the truth holds them while
    in view. Between ``n_boxes[0]`` and ``n_boxes[1]`` boxes are put down at random
    places at a random time in the first half of the run and picked up 10-30 s
    later (possibly after the end).
    """
    times = _frame_times(rate, duration)
    people: list[tuple[float, np.ndarray, np.ndarray]] = []  # start time, start, velocity
    t_next = float(rng.exponential(1.0 / person_rate))
    while t_next < duration:
        side = int(rng.integers(4))
        other = (side + int(rng.integers(1, 4))) % 4
        start = _border_point(rng, DATASHEET_REGION, side)
        goal = _border_point(rng, DATASHEET_REGION, other)
        direction = (goal - start) / max(float(np.linalg.norm(goal - start)), 1e-9)
        people.append((t_next, start, direction * rng.uniform(*speed)))
        t_next += float(rng.exponential(1.0 / person_rate))
    n = int(rng.integers(n_boxes[0], n_boxes[1] + 1))
    box_places = _separated_points(rng, DATASHEET_REGION, n, 1.0, 0.5)
    box_down = rng.uniform(0.0, 0.5 * duration, n)
    box_up = box_down + rng.uniform(10.0, 30.0, n)
    truth: list[TruthFrame] = []
    detections: list[Detection] = []

    def seen(t: float, cls: str, position: np.ndarray) -> None:
        if rng.random() < recall:
            detections.append(
                Detection(
                    time=t,
                    cls=cls,
                    position=_pos(position + rng.normal(0.0, noise, 2)),
                    source="overhead",
                    detector="overhead",
                )
            )

    for t in times:
        t = float(t)
        objects: list[TruthObject] = []
        for i, (start_time, start, velocity) in enumerate(people):
            p = start + velocity * (t - start_time)
            if t < start_time or not _inside(p, DATASHEET_REGION):
                continue
            objects.append(TruthObject(f"person{i + 1}", "Person", _pos(p), _pos(velocity)))
            seen(t, "Person", p)
        for i in range(n):
            if box_down[i] <= t < box_up[i]:
                objects.append(TruthObject(f"box{i + 1}", "Box", _pos(box_places[i]), (0.0, 0.0)))
                seen(t, "Box", box_places[i])
        truth.append(TruthFrame(t, tuple(objects)))
        for xy in _uniform(rng, DATASHEET_REGION, rng.poisson(false_positives_per_frame)):
            detections.append(
                Detection(
                    time=t,
                    cls=("Person", "Box")[int(rng.integers(2))],
                    position=_pos(xy),
                    source="overhead",
                    detector="overhead",
                )
            )
    return Scenario(
        name="datasheet",
        truth=truth,
        detections=detections,
        knowledge_file="datasheet.yaml",
        duration=float(times[-1]),
        region=DATASHEET_REGION,
        seed=seed,
        metadata={
            "gospa_c": 1.0,
            "knowledge_dir": "benchmarks/knowledge",
            "people": [round(s, 3) for s, _, _ in people],
            "boxes": [
                [round(float(a), 3), round(float(b), 3)]
                for a, b in zip(box_down, box_up, strict=True)
            ],
        },
    )


# --------------------------------------------------------------------------- patrol

PATROL_REGION: Region = ((0.0, 30.0), (0.0, 20.0))
"""The warehouse floor of :func:`patrol` (m)."""
PATROL_LOOP: tuple[tuple[float, float], ...] = ((4.0, 4.0), (26.0, 4.0), (26.0, 16.0), (4.0, 16.0))
"""The corners of the patrolling robot's closed route (m)."""


def _loop_position(corners: np.ndarray, distance: float) -> np.ndarray:
    """The point ``distance`` (m) along the closed polygon ``corners``, shape ``(n, 2)``."""
    closed = np.vstack([corners, corners[:1]])
    lengths = np.linalg.norm(np.diff(closed, axis=0), axis=1)
    ends = np.cumsum(lengths)
    s = distance % float(ends[-1])
    i = int(np.searchsorted(ends, s, side="right"))
    u = (s - (ends[i] - lengths[i])) / lengths[i]
    return np.asarray(closed[i] + u * (closed[i + 1] - closed[i]))


def patrol(
    rng: np.random.Generator,
    *,
    duration: float = 90.0,
    rate: float = 10.0,
    recall: float = 0.85,
    false_positives_per_frame: float = 0.3,
    noise: float = 0.08,
    sensor_range: float = 6.0,
    robot_speed: float = 1.0,
    n_pallets: int = 10,
    n_people: int = 3,
    walking_speed: tuple[float, float] = (0.8, 1.4),
    seed: int | None = None,
) -> Scenario:
    """A robot patrols a warehouse with a 360-degree detector of limited range.

    A harder variant nobody tuned for: the sensor moves, so most of the world is out
    of view most of the time. ``benchmarks/knowledge/patrol.yaml`` is written from
    the detector's datasheet only.

    The robot drives the closed route :data:`PATROL_LOOP` at ``robot_speed`` m/s on
    the 30 x 20 m floor (:data:`PATROL_REGION`). Its detector (``scanner``,
    ``source="robot"``, ``sensor_position`` = the robot's position) runs at
    ``rate`` Hz and reports each object within ``sensor_range`` m with probability
    ``recall`` and position noise ``noise`` (m, std), plus
    ``false_positives_per_frame`` false reports (Poisson, uniform over the part of
    its disc on the floor, class Pallet or Person). ``n_pallets`` pallets stand
    still at least 1.5 m apart; ``n_people`` people walk from one random point to
    the next at a speed in ``walking_speed`` (m/s) and wait 0-4 s at each. The
    truth holds every object in every frame, seen or not; ``metadata["first_seen"]``
    gives the time each object was first reported.
    """
    if n_pallets < 0 or n_people < 0:
        raise ValueError(f"need n_pallets >= 0, n_people >= 0; got {n_pallets}, {n_people}")
    times = _frame_times(rate, duration)
    dt = 1.0 / rate
    corners = np.asarray(PATROL_LOOP, dtype=float)
    pallets = _separated_points(rng, PATROL_REGION, n_pallets, 1.5, 1.0)
    walkable: Region = ((1.0, 29.0), (1.0, 19.0))
    people = _uniform(rng, walkable, n_people)
    goals = _uniform(rng, walkable, n_people)
    speeds = rng.uniform(*walking_speed, n_people)
    waits = np.zeros(n_people)
    ids = [f"pallet{i + 1}" for i in range(n_pallets)] + [f"person{i + 1}" for i in range(n_people)]
    classes = ["Pallet"] * n_pallets + ["Person"] * n_people
    first_seen: dict[str, float] = {}
    truth: list[TruthFrame] = []
    detections: list[Detection] = []
    for t in times:
        t = float(t)
        velocities = np.zeros((n_people, 2))
        for i in range(n_people):
            if waits[i] > 0.0:
                waits[i] -= dt
                continue
            offset = goals[i] - people[i]
            distance = float(np.linalg.norm(offset))
            if distance < 0.2:
                waits[i] = rng.uniform(0.0, 4.0)
                goals[i] = _uniform(rng, walkable, 1)[0]
                continue
            velocities[i] = offset / distance * speeds[i]
            people[i] = people[i] + velocities[i] * dt
        positions = np.vstack([pallets, people])
        speeds_now = np.vstack([np.zeros((n_pallets, 2)), velocities])
        truth.append(
            TruthFrame(
                t,
                tuple(
                    TruthObject(ids[k], classes[k], _pos(positions[k]), _pos(speeds_now[k]))
                    for k in range(len(ids))
                ),
            )
        )
        robot = _loop_position(corners, robot_speed * t)
        sensor = _pos(robot)
        for k in range(len(ids)):
            if np.linalg.norm(positions[k] - robot) > sensor_range or rng.random() >= recall:
                continue
            first_seen.setdefault(ids[k], t)
            detections.append(
                Detection(
                    time=t,
                    cls=classes[k],
                    position=_pos(positions[k] + rng.normal(0.0, noise, 2)),
                    source="robot",
                    detector="scanner",
                    sensor_position=sensor,
                )
            )
        for _ in range(rng.poisson(false_positives_per_frame)):
            radius = sensor_range * np.sqrt(rng.random())
            angle = rng.uniform(0.0, 2.0 * np.pi)
            xy = robot + radius * np.array([np.cos(angle), np.sin(angle)])
            if not _inside(xy, PATROL_REGION):
                continue
            detections.append(
                Detection(
                    time=t,
                    cls=("Pallet", "Person")[int(rng.integers(2))],
                    position=_pos(xy),
                    source="robot",
                    detector="scanner",
                    sensor_position=sensor,
                )
            )
    return Scenario(
        name="patrol",
        truth=truth,
        detections=detections,
        knowledge_file="patrol.yaml",
        duration=float(times[-1]),
        region=PATROL_REGION,
        seed=seed,
        metadata={
            "gospa_c": 1.0,
            "knowledge_dir": "benchmarks/knowledge",
            "sensor_range": sensor_range,
            "coverage_area": float(np.pi * sensor_range**2),
            "static_ids": ids[:n_pallets],
            "first_seen": {k: round(v, 6) for k, v in first_seen.items()},
        },
    )


# --------------------------------------------------------------------------- leftbehind

LEFTBEHIND_REGION: Region = ((0.0, 12.0), (0.0, 8.0))
"""The room of :func:`leftbehind` (m)."""
LEFTBEHIND_LOOP: tuple[tuple[float, float], ...] = (
    (2.5, 2.5),
    (9.5, 2.5),
    (9.5, 5.5),
    (2.5, 5.5),
)
"""The corners of the robot's closed route, driven counter-clockwise (m): 2.5 m from
every wall, 20 m around."""
LEFTBEHIND_CLASSES = ("Cup", "Bottle", "Book")
"""Classes of :func:`leftbehind` (``benchmarks/knowledge/leftbehind.yaml``)."""
LEFTBEHIND_CAM2_POSE = (0.3, 7.7, -math.pi / 4.0)
"""The fixed camera ``cam2``: in the room's top-left corner, looking diagonally into
the room (x, y in m, heading in rad counter-clockwise from the x axis)."""


def in_sector(
    points: np.ndarray,
    origin: Sequence[float] | np.ndarray,
    heading: float,
    reach: float,
    fov_deg: float,
) -> np.ndarray:
    """Whether each point ``(N, 2)`` lies in the disc sector of radius ``reach`` (m) and
    opening ``fov_deg`` (degrees) around ``heading`` (rad) at ``origin``: ``(N,)``."""
    offset = np.asarray(points, dtype=float)[:, :2] - np.asarray(origin, dtype=float)[:2]
    distance = np.linalg.norm(offset, axis=1)
    bearing = np.arctan2(offset[:, 1], offset[:, 0]) - heading
    bearing = (bearing + np.pi) % (2.0 * np.pi) - np.pi
    result: np.ndarray = (distance <= reach) & (np.abs(bearing) <= math.radians(fov_deg) / 2.0)
    return result


def _loop_pose(corners: np.ndarray, distance: float, look: float) -> tuple[float, float, float]:
    """Position and camera heading ``distance`` (m) along the closed route: the direction
    of travel turned by ``look`` (rad)."""
    here = _loop_position(corners, distance)
    ahead = _loop_position(corners, distance + 1e-3)
    travel = math.atan2(float(ahead[1] - here[1]), float(ahead[0] - here[0]))
    heading = (travel + look + math.pi) % (2.0 * math.pi) - math.pi
    return float(here[0]), float(here[1]), heading


def _intervals(times: np.ndarray, flags: np.ndarray) -> list[tuple[float, float]]:
    """``[first, last]`` times of each run of consecutive true ``flags``."""
    runs: list[tuple[float, float]] = []
    start: float | None = None
    previous = 0.0
    for t, flag in zip(times.tolist(), flags.tolist(), strict=True):
        if flag and start is None:
            start = t
        if not flag and start is not None:
            runs.append((start, previous))
            start = None
        previous = t
    if start is not None:
        runs.append((start, float(times[-1])))
    return runs


def _wall_place(rng: np.random.Generator, region: Region) -> tuple[np.ndarray, str]:
    """A place on a shelf (0.25-0.35 m from a wall) or a table (0.5-0.8 m) along one of
    the room's walls, at least 1 m from a corner."""
    (x0, x1), (y0, y1) = region
    wall = int(rng.integers(4))
    furniture = "shelf" if rng.random() < 0.5 else "table"
    depth = rng.uniform(0.25, 0.35) if furniture == "shelf" else rng.uniform(0.5, 0.8)
    if wall in (0, 2):  # bottom, top
        along = rng.uniform(x0 + 1.0, x1 - 1.0)
        return np.array([along, y0 + depth if wall == 0 else y1 - depth]), furniture
    along = rng.uniform(y0 + 1.0, y1 - 1.0)
    return np.array([x0 + depth if wall == 3 else x1 - depth, along]), furniture


def _sector_points(
    rng: np.random.Generator,
    origin: Sequence[float],
    heading: float,
    reach: float,
    fov_deg: float,
    n: int,
) -> list[np.ndarray]:
    """``n`` points uniform over a disc sector (:func:`in_sector`'s), those inside the
    room kept (the random numbers are drawn for all ``n``)."""
    half = math.radians(fov_deg) / 2.0
    points = []
    for _ in range(n):
        radius = reach * math.sqrt(rng.random())
        angle = heading + rng.uniform(-half, half)
        xy = np.asarray(origin[:2], dtype=float) + radius * np.array(
            [math.cos(angle), math.sin(angle)]
        )
        if _inside(xy, LEFTBEHIND_REGION):
            points.append(xy)
    return points


def leftbehind(
    rng: np.random.Generator,
    *,
    poses: bool = True,
    duration: float = 200.0,
    rate: float = 10.0,
    recall: float = 0.8,
    false_positives_per_frame: float = 0.2,
    noise: float = 0.05,
    sensor_range: float = 4.0,
    field_of_view: float = 90.0,
    look: float = -math.pi / 4.0,
    robot_speed: float = 0.3,
    cam2_rate: float = 5.0,
    cam2_recall: float = 0.8,
    cam2_false_positives_per_frame: float = 0.1,
    cam2_range: float = 5.0,
    cam2_field_of_view: float = 90.0,
    n_objects: tuple[int, int] = (8, 11),
    n_removed_in_view: int = 2,
    n_removed_out_of_view: int = 2,
    n_put_down: tuple[int, int] = (1, 2),
    truth_rate: float = 5.0,
    seed: int | None = None,
) -> Scenario:
    """A robot patrols a room and leaves objects behind: seen, out of view about 60 s,
    seen again (issue 28: what the world concludes from not seeing something).

    The robot drives the closed route :data:`LEFTBEHIND_LOOP` counter-clockwise at
    ``robot_speed`` m/s (a lap of about 67 s at 0.3 m/s) in the 12 x 8 m room
    (:data:`LEFTBEHIND_REGION`). Its camera (``source="robot"``, detector ``camera``)
    looks ``look`` rad off the direction of travel (default 45 degrees to the right,
    towards the walls), runs at ``rate`` Hz and reports each object in its view (a
    disc sector of radius ``sensor_range`` m and opening ``field_of_view`` degrees)
    with probability ``recall``, position noise ``noise`` (m, std), plus
    ``false_positives_per_frame`` false reports (Poisson, uniform over the part of
    its view inside the room, a random class). A fixed camera ``cam2`` (detector
    ``cam2``) at :data:`LEFTBEHIND_CAM2_POSE` watches the room's top-left part the
    same way at ``cam2_rate`` Hz (``cam2_recall``, ``cam2_false_positives_per_frame``,
    ``cam2_range``, ``cam2_field_of_view``).

    Between ``n_objects[0]`` and ``n_objects[1]`` static objects (Cup, Bottle, Book)
    stand on shelves and tables along the walls, at least 1 m apart, each placed so
    that the robot's camera sees it at least twice in the run. ``n_removed_in_view``
    of them are picked up while in the robot's view (at 1-2.5 s into a view interval
    of at least 5 s, not the object's first; else 1 s into to 2 s before the end of
    one of at least 3 s), ``n_removed_out_of_view`` while out of
    it (in the middle of a gap between two view intervals); ``n_put_down[0]`` to
    ``n_put_down[1]`` new objects are put down while out of view (and seen later).

    ``poses``: with ``True`` every detection carries ``sensor_position`` (the robot's
    position, cam2's); ``metadata["poses"]`` always holds the robot's
    ``[time, x, y, heading]`` at every scan in ``metadata["robot_poses"]``;
    ``metadata["sensor_views"]`` (= ``poses``) says whether a runner should also pass
    them, and cam2's, as sensor views (:func:`semwm.sim.leftbehind.with_sensor_views`).

    Ground truth about views in ``metadata["objects"]``, per object id: ``class``,
    ``position``, ``placed`` / ``removed`` (s; ``None``: from the start / never),
    ``removed_in_view`` (bool or ``None``), ``view_intervals`` (``[first, last]`` scan
    times the object is truly in the robot's view while present), ``robot_detections``
    and ``cam2_detections`` (counts), and ``cam2_view`` (ever in cam2's view).
    """
    if min(n_removed_in_view, n_removed_out_of_view, n_put_down[0]) < 0:
        raise ValueError("the numbers of removed and put-down objects must be >= 0")
    times = _frame_times(rate, duration)
    corners = np.asarray(LEFTBEHIND_LOOP, dtype=float)
    robot = [_loop_pose(corners, robot_speed * float(t), look) for t in times]
    robot_xy = np.array([(x, y) for x, y, _ in robot])
    cam2_xy = np.asarray(LEFTBEHIND_CAM2_POSE[:2])
    cam2_times = _frame_times(cam2_rate, duration)

    def view_flags(place: np.ndarray) -> np.ndarray:
        offset = place[None, :] - robot_xy
        distance = np.linalg.norm(offset, axis=1)
        bearing = np.arctan2(offset[:, 1], offset[:, 0]) - np.array([h for _, _, h in robot])
        bearing = (bearing + np.pi) % (2.0 * np.pi) - np.pi
        flags: np.ndarray = (distance <= sensor_range) & (
            np.abs(bearing) <= math.radians(field_of_view) / 2.0
        )
        return flags

    n_total = int(rng.integers(n_objects[0], n_objects[1] + 1))
    n_new = int(rng.integers(n_put_down[0], n_put_down[1] + 1))
    places: list[np.ndarray] = []
    furniture: list[str] = []
    flags: list[np.ndarray] = []
    for _ in range(1000 * (n_total + n_new)):
        place, kind = _wall_place(rng, LEFTBEHIND_REGION)
        if any(np.linalg.norm(place - q) < 1.0 for q in places):
            continue
        f = view_flags(place)
        if len(_intervals(times, f)) < 3:
            continue
        places.append(place)
        furniture.append(kind)
        flags.append(f)
        if len(places) == n_total + n_new:
            break
    else:
        raise ValueError(f"cannot place {n_total + n_new} objects the robot sees three times")
    count = len(places)
    classes = [
        LEFTBEHIND_CLASSES[int(i)] for i in rng.integers(len(LEFTBEHIND_CLASSES), size=count)
    ]
    ids = [f"{cls.lower()}{k + 1}" for k, cls in enumerate(classes)]
    placed = [0.0] * count
    removed: list[float | None] = [None] * count
    removed_in_view: list[bool | None] = [None] * count
    step = 1.0 / rate
    # put down while out of view: in the middle of a gap between the 1st and 2nd view
    for k in range(n_total, count):
        runs = _intervals(times, flags[k])
        gap = (runs[0][1], runs[1][0])
        placed[k] = round(
            float(rng.uniform(gap[0] + 0.4 * (gap[1] - gap[0]), gap[0] + 0.6 * (gap[1] - gap[0]))),
            3,
        )
    order = [int(k) for k in rng.permutation(n_total)]
    chosen_in: list[int] = []
    # picked up 1-2.5 s into a view of at least 5 s; if too few objects have one (a
    # fast robot), 1 s to 2 s before the end of a view of at least 3 s
    for shortest in (5.0, 3.0):
        for k in order:
            if len(chosen_in) == n_removed_in_view:
                break
            runs = [r for r in _intervals(times, flags[k])[1:] if r[1] - r[0] >= shortest]
            if k in chosen_in or not runs:
                continue
            start, end = runs[int(rng.integers(len(runs)))]
            latest = 2.5 if shortest == 5.0 else end - start - 2.0
            removed[k] = round(start + float(rng.uniform(1.0, latest)), 3)
            removed_in_view[k] = True
            chosen_in.append(k)
    chosen_out = 0
    for k in order:
        if chosen_out == n_removed_out_of_view:
            break
        if k in chosen_in:
            continue
        runs = _intervals(times, flags[k])
        j = int(rng.integers(1, len(runs) - 1)) if len(runs) > 2 else 0
        gap = (runs[j][1], runs[j + 1][0])
        removed[k] = round(
            float(rng.uniform(gap[0] + 0.4 * (gap[1] - gap[0]), gap[0] + 0.6 * (gap[1] - gap[0]))),
            3,
        )
        removed_in_view[k] = False
        chosen_out += 1

    def present(k: int, t: float) -> bool:
        gone = removed[k]
        return placed[k] <= t + 1e-9 and (gone is None or t < gone - 1e-9)

    cam2_view = [
        bool(
            in_sector(p[None, :], cam2_xy, LEFTBEHIND_CAM2_POSE[2], cam2_range, cam2_field_of_view)[
                0
            ]
        )
        for p in places
    ]
    robot_count = [0] * count
    cam2_count = [0] * count
    detections: list[Detection] = []
    cam2_set = set(np.round(cam2_times, 9).tolist())
    robot_sensor = None
    for i, t in enumerate(times.tolist()):
        x, y, heading = robot[i]
        robot_sensor = (round(x, 6), round(y, 6)) if poses else None
        for k in range(count):
            if not (flags[k][i] and present(k, t)) or rng.random() >= recall:
                continue
            robot_count[k] += 1
            detections.append(
                Detection(
                    time=t,
                    cls=classes[k],
                    position=_pos(places[k] + rng.normal(0.0, noise, 2)),
                    source="robot",
                    detector="camera",
                    sensor_position=robot_sensor,
                )
            )
        for xy in _sector_points(
            rng,
            (x, y),
            heading,
            sensor_range,
            field_of_view,
            rng.poisson(false_positives_per_frame),
        ):
            detections.append(
                Detection(
                    time=t,
                    cls=LEFTBEHIND_CLASSES[int(rng.integers(len(LEFTBEHIND_CLASSES)))],
                    position=_pos(xy),
                    source="robot",
                    detector="camera",
                    sensor_position=robot_sensor,
                )
            )
        if round(t, 9) not in cam2_set:
            continue
        cam2_sensor = _pos(cam2_xy) if poses else None
        for k in range(count):
            if not (cam2_view[k] and present(k, t)) or rng.random() >= cam2_recall:
                continue
            cam2_count[k] += 1
            detections.append(
                Detection(
                    time=t,
                    cls=classes[k],
                    position=_pos(places[k] + rng.normal(0.0, noise, 2)),
                    source="cam2",
                    detector="cam2",
                    sensor_position=cam2_sensor,
                )
            )
        for xy in _sector_points(
            rng,
            LEFTBEHIND_CAM2_POSE[:2],
            LEFTBEHIND_CAM2_POSE[2],
            cam2_range,
            cam2_field_of_view,
            rng.poisson(cam2_false_positives_per_frame),
        ):
            detections.append(
                Detection(
                    time=t,
                    cls=LEFTBEHIND_CLASSES[int(rng.integers(len(LEFTBEHIND_CLASSES)))],
                    position=_pos(xy),
                    source="cam2",
                    detector="cam2",
                    sensor_position=cam2_sensor,
                )
            )
    truth = [
        TruthFrame(
            float(t),
            tuple(
                TruthObject(ids[k], classes[k], _pos(places[k]), (0.0, 0.0))
                for k in range(count)
                if present(k, float(t))
            ),
        )
        for t in _frame_times(truth_rate, duration)
    ]

    def present_runs(k: int) -> list[list[float]]:
        alive = np.array([present(k, float(t)) for t in times])
        return [[round(a, 6), round(b, 6)] for a, b in _intervals(times, flags[k] & alive)]

    objects = {
        ids[k]: {
            "class": classes[k],
            "position": list(_pos(places[k])),
            "furniture": furniture[k],
            "placed": placed[k] if k >= n_total else None,
            "removed": removed[k],
            "removed_in_view": removed_in_view[k],
            "view_intervals": present_runs(k),
            "all_view_intervals": [
                [round(a, 6), round(b, 6)] for a, b in _intervals(times, flags[k])
            ],
            "robot_detections": robot_count[k],
            "cam2_detections": cam2_count[k],
            "cam2_view": cam2_view[k],
        }
        for k in range(count)
    }
    return Scenario(
        name="leftbehind",
        truth=truth,
        detections=detections,
        knowledge_file="leftbehind.yaml",
        duration=float(times[-1]),
        region=LEFTBEHIND_REGION,
        seed=seed,
        metadata={
            "gospa_c": 1.0,
            "knowledge_dir": "benchmarks/knowledge",
            "poses": poses,
            "sensor_views": poses,
            "scan_step": step,
            "sensor_range": sensor_range,
            "field_of_view": field_of_view,
            "coverage_area": float(np.pi * sensor_range**2 * field_of_view / 360.0),
            "cam2_pose": list(LEFTBEHIND_CAM2_POSE),
            "cam2_range": cam2_range,
            "cam2_field_of_view": cam2_field_of_view,
            "cam2_times": [round(float(t), 6) for t in cam2_times],
            "robot_poses": [
                [round(float(t), 6), round(x, 6), round(y, 6), round(h, 6)]
                for t, (x, y, h) in zip(times, robot, strict=True)
            ],
            "objects": objects,
        },
    )


# --------------------------------------------------------------------------- region_edge

EDGE_ROOM: Region = ((0.0, 4.0), (0.0, 3.0), (0.0, 2.5))
"""The room of :func:`region_edge` (m, 3-D): a side wall at x = 4, a back wall at y = 3."""
EDGE_TABLE_TOP = 0.74
"""Height of the table top (m): where ``benchmarks/knowledge/region_edge.yaml``'s region
starts (the area the robot works in: above the table)."""
EDGE_CLASSES = ("Table", "Cup", "Book", "Sign")


def region_edge(
    rng: np.random.Generator,
    *,
    duration: float = 20.0,
    rate: float = 5.0,
    recall: float = 0.8,
    table_recall: float = 0.4,
    clutter_rate: float = 0.5,
    noise: float = 0.05,
    table_noise: float = 0.1,
    n_cups: tuple[int, int] = (2, 3),
    n_books: tuple[int, int] = (2, 3),
    seed: int | None = None,
) -> Scenario:
    """Objects on the region's edge (issue 28: the region is a soft fact), in 3-D.

    A fixed camera (``camera``) watches a room corner (:data:`EDGE_ROOM`) whose working
    region (``benchmarks/knowledge/region_edge.yaml``) starts at the table top's height
    :data:`EDGE_TABLE_TOP` and ends at the side wall x = 4 and the back wall y = 3. Its
    edge passes through the objects: the Table is reported at the centre of its top
    (z = 0.74, on the region's floor), ``n_cups`` Cups stand on it (centres 5 cm above
    it: one sigma of the noise), ``n_books`` Books stand on shelves against the side
    wall (centres 0-8 cm from it), and a Sign hangs on the back wall (centre on it).

    The camera scans at ``rate`` Hz and reports each object with ``recall``
    (the Table with ``table_recall``), isotropic noise ``noise`` (``table_noise``) m;
    clutter: Poisson, ``clutter_rate`` per second, uniform over the room (below the
    table top too: the knowledge's region leaves it out) and the classes.
    """
    (_, x1), (y0, y1), _ = EDGE_ROOM
    table = np.array([rng.uniform(1.2, 2.3), rng.uniform(0.9, 1.6), EDGE_TABLE_TOP])
    objects: list[tuple[str, str, np.ndarray]] = [("table", "Table", table)]
    cups = _separated_points(
        rng, ((-0.5, 0.5), (-0.35, 0.35)), int(rng.integers(n_cups[0], n_cups[1] + 1)), 0.25, 0.0
    )
    for i, (dx, dy) in enumerate(cups):
        objects.append((f"cup{i + 1}", "Cup", table + np.array([dx, dy, 0.05])))
    n = int(rng.integers(n_books[0], n_books[1] + 1))
    along = _separated_points(rng, ((y0 + 0.4, y1 - 0.4),), n, 0.5, 0.0)
    for i, (y,) in enumerate(along):
        shelf = (0.45, 1.05, 1.65)[int(rng.integers(3))]
        objects.append(
            (f"book{i + 1}", "Book", np.array([x1 - rng.uniform(0.0, 0.08), y, shelf + 0.12]))
        )
    objects.append(("sign", "Sign", np.array([rng.uniform(1.0, 3.0), y1, rng.uniform(1.5, 2.0)])))
    times = _frame_times(rate, duration)
    truth_objects = tuple(TruthObject(i, c, _pos(p), (0.0, 0.0, 0.0)) for i, c, p in objects)
    truth = [TruthFrame(float(t), truth_objects) for t in times]
    detections: list[Detection] = []
    for t in times:
        t = float(t)
        for _, cls, place in objects:
            is_table = cls == "Table"
            if rng.random() >= (table_recall if is_table else recall):
                continue
            sigma = table_noise if is_table else noise
            detections.append(
                Detection(
                    time=t,
                    cls=cls,
                    position=_pos(place + rng.normal(0.0, sigma, 3)),
                    source="camera",
                    detector="camera",
                )
            )
        for xyz in _uniform(rng, EDGE_ROOM, rng.poisson(clutter_rate / rate)):
            detections.append(
                Detection(
                    time=t,
                    cls=EDGE_CLASSES[int(rng.integers(len(EDGE_CLASSES)))],
                    position=_pos(xyz),
                    source="camera",
                    detector="camera",
                )
            )
    return Scenario(
        name="region_edge",
        truth=truth,
        detections=detections,
        knowledge_file="region_edge.yaml",
        duration=float(times[-1]),
        region=EDGE_ROOM,
        seed=seed,
        metadata={
            "gospa_c": 0.5,
            "knowledge_dir": "benchmarks/knowledge",
            "on_edge": {i: c for i, c, _ in objects},
        },
    )


SCENARIOS: dict[str, Callable[..., Scenario]] = {
    "sim1": sim1,
    "sim2": sim2,
    "robocup": robocup,
    "grid": grid,
    "tabletop_wrong_labels": tabletop_wrong_labels,
    "corner_occlusion": corner_occlusion,
    "door_exits": door_exits,
    "datasheet": datasheet,
    "patrol": patrol,
    "leftbehind": leftbehind,
    "region_edge": region_edge,
}
"""Generators by name, as ``semwm simulate NAME`` knows them."""


def make_scenario(name: str, seed: int = 0, **sizes: object) -> Scenario:
    """The scenario ``name`` generated with ``numpy.random.default_rng(seed)``."""
    try:
        generator = SCENARIOS[name]
    except KeyError:
        raise ValueError(
            f"unknown scenario {name!r}; known scenarios: {', '.join(SCENARIOS)}"
        ) from None
    return generator(np.random.default_rng(seed), seed=seed, **sizes)
