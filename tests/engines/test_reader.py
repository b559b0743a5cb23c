"""The Rust engine's reader of plain batches (``core/src/python/reader.rs``) held to the
specification's three passes (``parse``, ``check``, ``WorldModel._placed``).

Random batches mix plain detections with every way a detection can leave the common
case: a value of another type, a field the model does not know, an own covariance, an
unknown class or detector, a position off the world's dimension, near a detector's
range or the region's edge. Whatever the reader makes must be what the specification
makes, field by field; it may give a batch back (``None``) only when the batch holds
such a detection, never for a plain one.
"""

from __future__ import annotations

import math
import pickle
from typing import Any

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from semwm.detection import Detection, DetectionError, OutOfOrderError
from semwm.knowledge.loader import load_knowledge
from semwm.knowledge.shipped import shipped_knowledge_path
from semwm.mhf.core_engine import as_python
from semwm.mhf.measurement import Measurement
from semwm.mhf.state import MHFState
from semwm.sim.runner import scans
from semwm.sim.scenarios import make_scenario
from semwm.validation import as_batch, check, core_reader, parse
from semwm.world import WorldModel, _grouped

from . import needs_rust

pytestmark = needs_rust

ROBOCUP = load_knowledge(shipped_knowledge_path("robocup.yaml"))  # region, ranges, labels
SIM1 = load_knowledge(shipped_knowledge_path("sim1.yaml"))  # neither region nor ranges


def _odd(plain: Any) -> st.SearchStrategy[Any]:
    """Values a plain field never holds: of other types, or out of the model's bounds."""
    return st.sampled_from([1, True, "1.0", math.nan, math.inf, -math.inf, 2e12, [], None])


@st.composite
def detections(draw: st.DrawFn, knowledge: Any) -> tuple[Any, bool]:
    """A detection (a dict, or a ``Detection`` where it validates as one) and whether
    anything of it leaves the plain case (then the reader may give the batch back)."""
    dim = knowledge.world.dimension
    region = knowledge.world.region or [(-20.0, 20.0)] * dim
    odd = False
    edge = st.sampled_from([-1.0, 1.0]).map(float)
    near = [draw(st.floats(low, high)) for low, high in region]
    if draw(st.integers(0, 4)) == 0:  # about the region's edge, either side of its margin
        axis = draw(st.integers(0, dim - 1))
        low, high = region[axis]
        near[axis] = (high if draw(edge) > 0 else low) + draw(st.floats(-2.5, 2.5))
        odd = True
    item: dict[str, Any] = {
        # a few times shared across a batch (scans of several detections, and sources)
        "time": draw(st.one_of(st.sampled_from([0.0, -0.0, 1.5]), st.floats(-100.0, 100.0))),
        "class": draw(st.sampled_from(sorted(knowledge.classes))),
        "position": near,
    }
    detector = draw(st.sampled_from([None, *knowledge.detectors]))
    if detector is not None:
        item["detector"] = detector
    for key, values in (
        ("source", st.sampled_from([None, "r1", "r2", ""])),
        ("label", st.sampled_from([None, "me", "you"])),
        ("time_std", st.sampled_from([None, 0.0, -0.0, 0.05, 10.0])),
    ):
        if draw(st.booleans()):
            item[key] = draw(values)
    if draw(st.booleans()):  # a sensor position, within or about its detector's range
        reach = knowledge.detectors[detector or knowledge.default_detector].range or 3.0
        angle = draw(st.floats(0.0, 2 * math.pi))
        distance = draw(st.sampled_from([0.0, 0.5 * reach, reach, reach + 0.3, 2 * reach]))
        odd = odd or distance >= reach
        offset = [distance * math.cos(angle), distance * math.sin(angle), 0.0][:dim]
        item["sensor_position"] = [a - b for a, b in zip(near, offset, strict=True)]
    change = draw(st.integers(0, 30))
    if change == 1:
        item[draw(st.sampled_from(["time", "class", "position", "sensor_position"]))] = draw(
            _odd(None)
        )
    elif change == 2:
        item["position"] = [*near, 0.0] if draw(st.booleans()) else near[:1]
    elif change == 3:
        item["covariance"] = [[0.04 if i == j else 0.0 for j in range(dim)] for i in range(dim)]
    elif change == 4:
        item["class" if draw(st.booleans()) else "detector"] = "Unknown"
    elif change == 5:
        item["cls"] = item.pop("class")  # the field's name, which pydantic also takes
    elif change == 6:
        item["extra"] = 1.0
    elif change == 7:
        item["position"] = tuple(int(v) for v in near)
    elif change == 8:
        item[draw(st.sampled_from(["source", "label", "time_std"]))] = draw(_odd(None))
    odd = odd or change in range(1, 9)
    if draw(st.booleans()):
        try:
            return Detection.model_validate(item), odd
        except ValueError:
            pass
    return item, odd


def _specification(
    model: WorldModel, batch: list[Any], first_seq: int
) -> tuple[list[Measurement], list[int]] | None:
    """The specification's measurements used and the indices of those it ignores
    (``None``: refused)."""
    try:
        parsed = parse(as_batch(batch))
        measurements = check(parsed, model.knowledge, model._mhf.factory, first_seq)
    except DetectionError:
        return None
    used, skipped = model._placed(parsed, measurements)
    return used, [why.index for why in skipped]


def _same(read: Measurement, expected: Measurement) -> None:
    for name, a, b in zip(Measurement._fields, read, expected, strict=True):
        assert type(a) is type(b), name
        if isinstance(a, np.ndarray):
            assert a.dtype == b.dtype and a.shape == b.shape, name
            assert np.array_equal(a, b), name
        else:
            assert a == b, name
    assert read.R is expected.R  # the pair's shared noise, read once by the core


@pytest.mark.parametrize("knowledge", [ROBOCUP, SIM1], ids=["robocup", "sim1"])
@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=st.data())
def test_the_reader_makes_what_the_specification_makes(knowledge: Any, data: Any) -> None:
    model = WorldModel(knowledge, engine="rust")
    reader = _reader(model)
    drawn = data.draw(st.lists(detections(knowledge), min_size=1, max_size=4))
    batch = [item for item, _ in drawn]
    first_seq = data.draw(st.integers(0, 10**6))
    answer = reader.read(batch, first_seq)
    expected = _specification(model, batch, first_seq)
    if answer is None:
        assert any(odd for _, odd in drawn), f"a plain batch was given back: {batch}"
        return
    count, scans, unplaced = answer
    read = _in_batch_order(scans)
    assert expected is not None, "the reader took a batch the specification refuses"
    used, ignored = expected
    # the reader leaves out exactly what the specification ignores (WorldModel._ignored
    # then says why, detection by detection)
    assert unplaced == ignored, f"left {unplaced}, the specification ignores {ignored}"
    assert not unplaced or any(odd for _, odd in drawn), f"a plain detection left: {batch}"
    used = [m for m in used if m.seq - first_seq not in unplaced]
    assert count == len(read) == len(used)
    for a, b in zip(read, used, strict=True):
        _same(a, b)
    _same_scans(scans, read)
    for scan in scans.values():
        _rows_say_the_values(model, scan)


def test_a_batch_of_many_scans_is_grouped_as_the_specification_groups_it() -> None:
    """A batch of more scans than the reader looks through one by one (it then keeps a
    table of them): each detection joins the scan of its time and source wherever it
    comes in the batch, before the table is made, while it is made and after."""
    model = WorldModel(SIM1, engine="rust")
    reader = _reader(model)
    keys = [(float(t), source) for t in range(12) for source in ("r1", "r2")]
    order = np.random.default_rng(5).permutation(np.repeat(np.arange(len(keys)), 3))
    cls = sorted(SIM1.classes)[0]
    batch = [
        {
            "time": keys[k][0],
            "class": cls,
            "position": [1.0 + 0.001 * i] * SIM1.world.dimension,
            "source": keys[k][1],
        }
        for i, k in enumerate(order)
    ]
    answer = reader.read(batch, 7)
    assert answer is not None
    count, scans, unplaced = answer
    assert (count, len(scans), unplaced) == (len(batch), len(keys), [])
    expected = _specification(model, batch, 7)
    assert expected is not None and expected[1] == []
    read = _in_batch_order(scans)
    for a, b in zip(read, expected[0], strict=True):
        _same(a, b)
    _same_scans(scans, read)


def _reader(model: WorldModel) -> Any:
    assert model._mhf._core is not None
    return core_reader(model.knowledge, model._mhf.factory, model._mhf._core)


def _in_batch_order(scans: dict[Any, Any]) -> list[Measurement]:
    return sorted((m for scan in scans.values() for m in scan), key=lambda m: m.seq)


def _same_scans(scans: dict[Any, Any], read: list[Measurement]) -> None:
    """The reader's scans are :func:`semwm.world._grouped`'s: the same keys, of the same
    types, in the same order, each holding the same measurements in batch order (the
    same values each time they are read)."""
    expected, _ = _grouped(read, None)
    assert list(scans) == list(expected)
    assert [tuple(map(type, key)) for key in scans] == [tuple(map(type, k)) for k in expected]
    for key, group in expected.items():
        assert len(scans[key]) == len(group)
        assert [m.seq for m in scans[key]] == [m.seq for m in group]
        assert all(a is b for a, b in zip(scans[key], group, strict=True))


def _rows_say_the_values(model: WorldModel, scan: Any) -> None:
    """The core's rows of a scan (what the engine takes without its values) are what
    its ``Measurement`` values say, field by field."""
    core = model._mhf._core
    assert core is not None
    detectors = list(model.knowledge.detectors)
    rows = scan.rows()
    assert len(rows) == len(scan)
    for row, m in zip(rows, scan, strict=True):
        seq, time, cls, z, r, detector, source, label, clutter, sensor, time_std = row
        assert (seq, time, core.names[cls], detectors[detector]) == (
            m.seq, m.time, m.cls, m.detector,
        )  # fmt: skip
        assert z == m.z.tolist() and r == m.R.ravel().tolist()
        assert (source, label, clutter, time_std) == (
            m.source or "", m.label, m.clutter_rate, m.time_std,
        )  # fmt: skip
        assert sensor == (None if m.sensor is None else m.sensor.tolist())


def test_a_plain_batch_of_either_form_is_read() -> None:
    """Dicts from the wire and ``Detection`` values alike; a label of a foreign class
    is dropped as ``check`` drops it (paper 004: tracked from observation only)."""
    model = WorldModel(ROBOCUP, engine="rust")
    reader = _reader(model)
    batch: list[Any] = [
        {"time": 1.0, "class": "Opponent", "position": [1.0, 2.0], "label": "o7"},
        Detection.model_validate(
            {"time": 1.0, "class": "Peer", "position": [0.5, 0.5], "label": "me",
             "detector": "self_localization", "sensor_position": [0.5, 0.4]}
        ),
    ]  # fmt: skip
    answer = reader.read(batch, 7)
    assert answer is not None
    count, scans, unplaced = answer
    read = _in_batch_order(scans)
    assert count == 2 and unplaced == []
    assert list(scans) == [(1.0, "")] and scans[1.0, ""] == read  # one scan, no source
    assert [m.seq for m in read] == [7, 8]
    assert [m.label for m in read] == [None, "me"]
    assert read[1].detector == "self_localization" and read[0].detector == "omnivision"
    expected = _specification(model, batch, 7)
    assert expected is not None
    for a, b in zip(read, expected[0], strict=True):
        _same(a, b)


@pytest.mark.parametrize(
    ("reorder_window", "hold", "most"),
    [(0.0, 0.0, 1000), (0.5, 0.0, 1000), (0.5, 0.0, 3), (0.5, 0.15, 1000)],
    ids=["now", "replay", "short-log", "hold"],
)
def test_models_with_and_without_the_reader_agree(
    reorder_window: float, hold: float, most: int
) -> None:
    """The same batches, plain or not (ignored detections, refused batches), give the
    same answers and the same world with the reader as through the specification;
    with a reorder window, late batches replay the logged scans the reader read, and a
    hold keeps them pending (their values are then read: ``semwm._core.Scan``). A batch
    the reader reads whole into one scan takes ``WorldModel._ingest_scan``: the same
    reorder log, replay floor and times as the general path's."""
    rng = np.random.default_rng(3)
    fast, spec = (
        WorldModel(ROBOCUP, engine="rust", reorder_window=reorder_window, hold=hold)
        for _ in range(2)
    )
    spec._reader = None
    placed: list[bool] = []  # per batch with detections the reader left: all ignored?
    apart = fast._ignored_apart

    def counted(batch: list[Any], indices: list[int]) -> Any:
        answer = apart(batch, indices)
        placed.append(answer is not None)
        return answer

    fast._ignored_apart = counted  # type: ignore[method-assign]
    fast.max_reorder_scans = spec.max_reorder_scans = most
    for step in range(40):
        late = reorder_window > 0 and rng.random() < 0.3
        time = max(0.0, step * 0.1 - (float(rng.uniform(0.05, 0.3)) if late else 0.0))
        batch: list[dict[str, Any]] = []
        for _ in range(int(rng.integers(1, 5))):
            item: dict[str, Any] = {
                "time": time,
                "class": str(rng.choice(["Ball", "Opponent", "Peer"])),
                # the region is [-9, 9] x [-6, 6]: some within its margin, some beyond
                "position": [float(rng.uniform(-12, 12)), float(rng.uniform(-7, 7))],
                "source": "r1" if step == 0 else str(rng.choice(["r1", "r2"])),
            }
            if rng.random() < 0.1:
                item["class"] = "Unknown"
            if rng.random() < 0.3:  # seen from about its detector's range of 5 m, either side
                away = float(rng.uniform(4.6, 7.0))
                x, y = item["position"]
                item["sensor_position"] = [x - away, y]
            batch.append(item)
        outcomes = []
        for model in (fast, spec):
            try:
                outcomes.append(model.ingest(batch))
            except (DetectionError, OutOfOrderError) as error:  # refused: nothing changed
                outcomes.append(str(error))
        assert outcomes[0] == outcomes[1]
        assert [e.key for e in fast._log] == [e.key for e in spec._log]
        assert fast._replay_floor == spec._replay_floor
        assert (fast._newest, fast._earliest, fast._seq) == (
            spec._newest,
            spec._earliest,
            spec._seq,
        )
        assert fast._ids == spec._ids and list(fast._published) == list(spec._published)
        a, b = fast.world(), spec.world()
        assert [(o.id, o.cls) for o in a.objects] == [(o.id, o.cls) for o in b.objects]
        for x, y in zip(a.objects, b.objects, strict=True):
            assert np.array_equal(x.position, y.position)
    assert fast.replayed_scans == spec.replayed_scans
    # batches with detections out of the region or beyond reach (some within the
    # margin: used): read by the reader, which leaves out just those ignored
    assert placed and all(placed), placed
    if reorder_window > 0 and hold == 0:
        assert fast.replayed_scans > 0  # the late batches were replays
    if most < 10:
        assert fast._replay_floor is not None  # the short log dropped scans
    if hold > 0:
        assert fast.pending_scans == spec.pending_scans


def test_a_scan_reads_as_its_measurements_once() -> None:
    """A scan's values are made once (the same objects on every read), pickle as the
    tuple of them, and another engine takes the scan by its values."""
    model, other = WorldModel(SIM1, engine="rust"), WorldModel(SIM1, engine="rust")
    batch = [
        {"time": 2.0, "class": cls, "position": [x, 1.0], "source": "cam"}
        for x, cls in ((0.5, "Cup"), (1.5, "Table"), (3.0, "Cup"))
    ]
    answer = _reader(model).read(batch, 0)
    assert answer is not None
    (key, scan), *rest = answer[1].items()
    assert key == (2.0, "cam") and not rest and len(scan) == 3
    assert scan[0] is scan[0] and list(scan)[2] is scan[-1] and scan[1:] == list(scan)[1:]
    copied = pickle.loads(pickle.dumps(scan))
    assert type(copied) is tuple and len(copied) == 3
    for a, b in zip(copied, scan, strict=True):
        _same_values(a, b)
    assert other._mhf._core is not None and model._mhf._core is not None
    states = []
    for measurements in (scan, list(scan)):
        empty = MHFState.empty()
        state, _ = other._mhf._core.process_and_advance(empty, other._book, measurements, None)
        states.append(as_python(state))
    assert [t.lineage for t in states[0].tracks.values()] == [0, 1, 2]
    for a, b in zip(states[0].tracks.values(), states[1].tracks.values(), strict=True):
        assert (a.key, a.cls) == (b.key, b.cls) and np.array_equal(a.x, b.x)


def _same_values(a: Measurement, b: Measurement) -> None:
    for name, x, y in zip(Measurement._fields, a, b, strict=True):
        assert np.array_equal(x, y) if isinstance(x, np.ndarray) else x == y, name


def _said(model: WorldModel, time: float, source: str | None = None) -> str:
    """What ``model`` answers one detection at ``time``: its result, or why it refused."""
    item: dict[str, Any] = {"time": time, "class": "Ball", "position": [1.0, 2.0]}
    if source is not None:
        item["source"] = source
    try:
        return repr(model.ingest([item]))
    except OutOfOrderError as error:
        return str(error)


def test_the_one_scan_path_refuses_what_the_general_path_refuses() -> None:
    """``WorldModel._ingest_scan`` checks a batch's time as ``_ingest`` does: older than
    the reorder window allows, or at the replay floor a knowledge change sets."""
    outcomes: list[list[str]] = []
    for reader in (True, False):
        model = WorldModel(ROBOCUP, engine="rust")
        if not reader:
            model._reader = None
        # 1.05: older than the latest, and no reorder window
        said = [_said(model, time) for time in (1.0, 1.1, 1.05, 1.2)]
        model.replace_knowledge(ROBOCUP)  # the reorder window restarts at 1.2
        said.append(_said(model, 1.2, "r1"))  # after (1.2, "") in key order: taken
        # at the floor: refused (the first scan after the change took the general path:
        # the state is now the new engine's, and this one takes the one-scan path)
        said.append(_said(model, 1.2))
        said.append(_said(model, 1.3))
        outcomes.append(said)
    assert outcomes[0] == outcomes[1]
    assert sum("older than" in line for line in outcomes[0]) == 2, outcomes[0]


@pytest.mark.parametrize("seed", [0, 1])
def test_the_paper_model_takes_the_one_scan_path_and_its_queries_the_core(seed: int) -> None:
    """Under ``paper`` a scan read whole takes ``WorldModel._ingest_scan`` too, its
    confidence book left as it was (``_step`` keeps none under ``paper``), and a query
    is answered in the core (``Engine.world_at``): the same answers, logs and ids as
    the general path, and the same worlds (now, past and ahead) as the Python engine's."""
    world = ROBOCUP.world.model_copy(update={"association_model": "paper"})
    paper = ROBOCUP.model_copy(update={"world": world})
    fast, general = (WorldModel(paper, engine="rust", reorder_window=0.5) for _ in range(2))
    python = WorldModel(paper, engine="python", reorder_window=0.5)
    general._ingest_scan = lambda read, size: None  # type: ignore[method-assign]
    taken: list[bool] = []
    one_scan = fast._ingest_scan

    def watched(read: Any, size: int) -> Any:
        done = one_scan(read, size)
        taken.append(done is not None)
        return done

    fast._ingest_scan = watched  # type: ignore[method-assign]
    queried: list[Any] = []
    core_world = fast._core_world

    def asked(*args: Any) -> Any:
        queried.append(args[2])
        return core_world(*args)

    fast._core_world = asked  # type: ignore[method-assign]
    frames = 0
    for batch in scans(make_scenario("robocup", seed, duration=2.0).detections):
        time, frames = batch[0].time, frames + 1
        book = fast._book
        outcomes = [repr(model.ingest(batch)) for model in (fast, general, python)]
        assert outcomes[0] == outcomes[1] == outcomes[2]
        assert fast._book is book  # paper: no confidences
        assert [e.key for e in fast._log] == [e.key for e in general._log]
        assert fast._ids == general._ids and list(fast._published) == list(general._published)
        for at in (time, time - 0.25, time + 0.5):
            a, b = fast.world(at), python.world(at)
            assert [(o.id, o.cls, o.label) for o in a.objects] == [
                (o.id, o.cls, o.label) for o in b.objects
            ]
            for x, y in zip(a.objects, b.objects, strict=True):
                assert abs(x.existence - y.existence) <= 1e-12
                assert np.allclose(x.position, y.position, rtol=0, atol=1e-9)
                assert np.allclose(x.covariance, y.covariance, rtol=0, atol=1e-9)
    assert frames > 100 and sum(taken) > 0.9 * frames, (frames, sum(taken))
    # every query in the core but those before the first scan (nothing to ask)
    assert len(queried) > 2.5 * frames and min(queried) >= 0.0
    assert len(fast.world().objects) >= 4
    assert fast.hypothesis_count > 1  # hypotheses, not one certain world
