"""What crosses into the core and back: a scan's measurements are read whatever the
layout of their arrays, a row that is not a measurement is a ``ValueError`` naming its
index (never a panic), and the published world's version references pickle as their
tracks (a snapshot holds them)."""

from __future__ import annotations

import pickle

import numpy as np
import pytest

from semwm.knowledge.loader import load_knowledge
from semwm.knowledge.shipped import shipped_knowledge_path
from semwm.mhf.core_engine import CoreState, track_of
from semwm.mhf.state import Track
from semwm.world import WorldModel

from . import needs_rust

pytestmark = needs_rust

BATCH = [
    {"time": 0.0, "class": "Cup", "position": [1.0, 2.0], "source": "r1"},
    {"time": 0.0, "class": "Cup", "position": [3.0, 1.0], "source": "r1"},
]


LATER = [{**d, "time": 0.1} for d in BATCH]


def _model() -> WorldModel:
    """A model that has seen :data:`BATCH`: :data:`LATER` updates its objects."""
    model = WorldModel(load_knowledge(shipped_knowledge_path("sim1.yaml")), engine="rust")
    model.ingest(BATCH)
    return model


def _scan(model: WorldModel, measurements: list[object]) -> list[tuple[object, ...]]:
    core = model._mhf._core
    assert core is not None
    after = core.engine.process_measurements(core.to_core(model._state), measurements)
    keys, _, _ = after.entries()
    return [
        (t.lineage, t.cls, t.x.tolist(), t.P.tolist())
        for t in core.tracks_of(CoreState(after, core), keys)
    ]


def test_arrays_of_any_layout_are_read_as_their_values() -> None:
    model = _model()
    measurements = model.validate(LATER)
    plain = _scan(model, list(measurements))
    strided = []
    for m in measurements:
        z = np.repeat(m.z, 2)[::2]  # a view with a stride of two
        # column-major and not symmetric: read in memory order, it would be its transpose
        R = np.asfortranarray(m.R + np.array([[0.0, 1e-3], [0.0, 0.0]]))
        assert not z.flags.c_contiguous and not R.flags.c_contiguous
        strided.append(m._replace(z=z, R=R))
    expected = [
        m._replace(R=np.ascontiguousarray(s.R)) for m, s in zip(measurements, strided, strict=True)
    ]
    assert _scan(model, strided) == _scan(model, expected)
    assert _scan(model, strided) != plain  # the off-diagonal noise was read, in its place


@pytest.mark.parametrize(
    ("change", "message"),
    [
        (lambda m: m[:5], r"measurements\[1\]: not a Measurement: 5 fields, not 11"),
        (lambda m: m._replace(cls="Spoon"), r"measurements\[1\]: unknown class .Spoon."),
        (lambda m: m._replace(detector="lidar"), r"measurements\[1\]: unknown detector"),
        (lambda m: m._replace(z=[1.0, 2.0]), r"measurements\[1\]: not a Measurement"),
        (lambda m: m._replace(z=np.array([1, 2])), r"measurements\[1\]: not a Measurement"),
        (lambda m: m._replace(z=np.zeros(3)), r"measurements\[1\]: expected z of 2"),
        (lambda m: m._replace(seq=-1), r"measurements\[1\]: not a Measurement"),
        (lambda m: m._replace(source=3), r"measurements\[1\]: not a Measurement"),
        (lambda m: "Cup", r"measurements\[1\]: not a Measurement"),
    ],
)
def test_a_row_that_is_not_a_measurement_is_refused_by_index(change, message) -> None:  # type: ignore[no-untyped-def]
    model = _model()
    first, second = model.validate(LATER)
    with pytest.raises(ValueError, match=message):
        _scan(model, [first, change(second)])


def test_published_version_references_pickle_as_their_tracks() -> None:
    model = _model()
    model.ingest(LATER)
    published = model._published
    assert published and all(type(v).__name__ == "VersionRef" for v in published.values())
    assert "VersionRef(lineage=" in repr(next(iter(published.values())))
    back = pickle.loads(pickle.dumps(published))
    assert back.keys() == published.keys()
    for object_id, ref in published.items():
        track = back[object_id]
        assert isinstance(track, Track)  # the core state lives in this process only
        assert (track.lineage, track.cls, track.key) == (ref.lineage, ref.cls, ref.key)
        assert track.x.tolist() == track_of(ref).x.tolist()
