"""The expansion of one scan (step 5 of :mod:`semwm.mhf.filter`: ``_product``,
``_expand``, ``_split``, ``_certain_update``, merging and pruning) in Rust
(``core/src/expansion.rs``, ``core/src/hypotheses.rs``) against the Python methods, its
specification, on random clusters and options (``hypothesis``): both association
models, labels and the copies that give a label up, presence (eq. 4), births, settled
updates, eq. (3)'s ratio and n_hyp,max. The same clusters in the same order, the same
hypotheses (key sets equal, log weights and rates within 1e-12), the same versions made
with the same keys, existence and labels, or the same error."""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass
from functools import cache

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from semwm import _core
from semwm.knowledge.loader import load_knowledge
from semwm.knowledge.shipped import shipped_knowledge_path
from semwm.mhf.association import DetectionOptions, SettledUpdate
from semwm.mhf.filter import MultipleHypothesisFilter, _ClusterBook, _TrackTable
from semwm.mhf.measurement import Measurement
from semwm.mhf.prune import merge, prune
from semwm.mhf.state import Cluster, MHFState, Track

from . import needs_rust
from .scan_expander import ScanExpander

pytestmark = needs_rust

TOL = 1e-12
_ZERO = np.zeros(2)
_LABELS = st.sampled_from([None, None, "a", "b"])
_WEIGHTS = st.floats(-12.0, 0.0)
_RATES = st.floats(0.1, 5.0)


@cache
def _filter(model: str) -> MultipleHypothesisFilter:
    knowledge = load_knowledge(shipped_knowledge_path("sim1.yaml"))
    world = knowledge.world.model_copy(update={"association_model": model})
    return MultipleHypothesisFilter(knowledge.model_copy(update={"world": world}))


def _track(key: int, rate: float, label: str | None) -> Track:
    return Track(
        key, key, "Cup", label, _ZERO[None], np.eye(2)[None], np.ones(1), 0.0, 0.0, 0.0, rate, _ZERO
    )


def _measurement(label: str | None) -> Measurement:
    return Measurement(0, 1.0, "Cup", _ZERO, np.eye(2), "camera", None, label, 1.0)


@dataclass
class Case:
    model: str
    ratio: float
    max_hypotheses: int
    log_label_error: float
    state: MHFState
    options: list[DetectionOptions | SettledUpdate]
    next_key: int


@st.composite
def _cases(draw: st.DrawFn, model: str) -> Case:
    n = draw(st.integers(1, 6))
    tracks = {k: _track(k, draw(_RATES), draw(_LABELS)) for k in range(n)}
    if model == "paper":
        groups = [list(range(n))]
    else:
        owner = [draw(st.integers(0, n - 1)) for _ in range(n)]
        groups = [[k for k in range(n) if owner[k] == g] for g in range(n)]
    clusters = []
    certain = model == "mht" and draw(st.booleans())  # some objects alone and certain
    for group in groups:
        if not group:
            continue
        if certain and len(group) == 1:
            (k,) = group
            clusters.append(
                Cluster.of(prune(merge([(frozenset({k}), 0.0, tracks[k].rate)]), 0.0, 1))
            )
            continue
        weights: dict[frozenset[int], float] = {}
        for _ in range(draw(st.integers(1, 4))):
            chosen = frozenset(k for k in group if draw(st.booleans()))
            weights.setdefault(chosen, draw(_WEIGHTS))
        children = ((ks, w, sum(tracks[k].rate for k in sorted(ks))) for ks, w in weights.items())
        clusters.append(Cluster.of(prune(merge(children), 0.0, len(weights))))
    existence = {k: draw(st.floats(0.05, 1.0)) for k in range(n)}
    state = MHFState(tuple(clusters), tracks, 0.0, n, existence)
    next_key = n
    options: list[DetectionOptions | SettledUpdate] = []
    named: set[int] = set()
    labelled = False
    for _ in range(draw(st.integers(1, 4))):
        if model == "mht" and draw(st.booleans()):  # sure of one object: a certain update?
            k = draw(st.integers(0, n - 1))
            updated = _track(next_key, draw(_RATES), tracks[k].label)
            new_track = _track(next_key + 1, draw(_RATES), None)
            next_key += 2
            named.add(k)
            options.append(
                DetectionOptions(
                    _measurement(None),
                    0.5,
                    -30.0,
                    new_track,
                    0.3,
                    -30.0,
                    {},
                    {k: (updated, 0.0, updated.rate - tracks[k].rate)},
                )
            )
            continue
        label = draw(_LABELS)
        labelled |= label is not None
        clutter_rate = draw(st.sampled_from([0.0, 0.5, 2.0]))
        log_clutter = math.log(clutter_rate) + draw(_WEIGHTS) if clutter_rate else -math.inf
        new_rate = draw(st.sampled_from([0.0, 0.3, 1.0]))
        new_log = draw(_WEIGHTS) if new_rate else -math.inf
        presence = {
            k: (draw(_RATES), draw(_WEIGHTS))
            for k in draw(st.sets(st.integers(0, n - 1), max_size=2))
        }
        existing = {}
        for k in draw(st.lists(st.integers(0, n - 1), max_size=3, unique=True)):
            updated = _track(next_key, draw(_RATES), label or tracks[k].label)
            next_key += 1
            log_num = draw(st.one_of(_WEIGHTS, st.just(-math.inf)))
            existing[k] = (updated, log_num, updated.rate - tracks[k].rate)
        named |= set(existing) | set(presence)
        new_track = _track(next_key, draw(_RATES), label)
        next_key += 1
        options.append(
            DetectionOptions(
                _measurement(label),
                clutter_rate,
                log_clutter,
                new_track,
                new_rate,
                new_log,
                presence,
                existing,
            )
        )
    if model == "mht" and not labelled:  # SettledUpdate: objects alone and certain
        for cluster in clusters:
            (key,) = cluster.keys if len(cluster.keys) == 1 else (None,)
            if key is None or len(cluster.hypotheses) > 1 or key in named:
                continue
            if draw(st.booleans()):
                updated = _track(next_key, draw(_RATES), tracks[key].label)
                next_key += 1
                at = draw(st.integers(0, len(options)))
                options.insert(at, SettledUpdate(_measurement(None), key, updated))
    return Case(
        model,
        draw(st.sampled_from([0.0, 1e-3, 0.1, 0.5])),
        draw(st.sampled_from([1, 2, 3, 100])),
        math.log(draw(st.sampled_from([0.01, 0.2]))),
        state,
        options,
        next_key,
    )


def _run(case: Case, engine: str) -> tuple[object, ...]:
    """The scan's clusters and track table with one engine, or the error it raised."""
    mhf = copy.copy(_filter(case.model))
    mhf.ratio = case.ratio
    mhf.log_ratio = math.log(case.ratio) if case.ratio > 0.0 else -math.inf
    mhf.max_hypotheses = case.max_hypotheses
    mhf.associator = copy.copy(mhf.associator)
    mhf.associator.log_label_error = case.log_label_error
    table = _TrackTable(case.state)
    table.next_key = case.next_key  # the keys the options took
    try:
        if engine == "rust":
            expander = ScanExpander(
                case.ratio, case.max_hypotheses, case.model, case.log_label_error
            )
            clusters = _rust_expand(mhf, expander, case, table)
        else:
            clusters = mhf._expand_scan(case.state.clusters, case.options, table)
    except ValueError as error:
        return ("ValueError", str(error))
    tracks = {k: (t.label, t.lineage, t.rate) for k, t in table.tracks.items()}
    return (clusters, tracks, table.existence, table.fresh, table.next_key)


def _rust_expand(
    mhf: MultipleHypothesisFilter, expander: ScanExpander, case: Case, table: _TrackTable
) -> tuple[Cluster, ...]:
    """The scan's options from the first on in the core, the first option's versions in
    the table first (as ``_expand_scan``'s loop adds them before the algebra)."""
    book = _ClusterBook(case.state.clusters)
    if case.options:
        first = case.options[0]
        if isinstance(first, DetectionOptions):
            if not mhf.mht:
                table.add(first.new_track, fresh=True)
            for old_key, (updated, _, _) in first.existing.items():
                table.add(updated, origin=old_key, fresh=True)
        expander.expand(book, case.options, 0, table)
    return book.clusters()


def _assert_same(case: Case) -> None:
    expected = _run(case, "python")
    got = _run(case, "rust")
    if expected[0] == "ValueError" or got[0] == "ValueError":
        assert got == expected
        return
    clusters, tracks, existence, fresh, next_key = got
    e_clusters, e_tracks, e_existence, e_fresh, e_next_key = expected
    assert (tracks, fresh, next_key) == (e_tracks, e_fresh, e_next_key)
    assert existence.keys() == e_existence.keys()
    assert all(abs(existence[k] - e_existence[k]) <= TOL for k in existence)
    assert [c.keys for c in clusters] == [c.keys for c in e_clusters]
    for cluster, e_cluster in zip(clusters, e_clusters, strict=True):
        assert [h.tracks for h in cluster.hypotheses] == [h.tracks for h in e_cluster.hypotheses]
        for h, e in zip(cluster.hypotheses, e_cluster.hypotheses, strict=True):
            assert abs(h.log_weight - e.log_weight) <= TOL
            assert abs(h.rate - e.rate) <= TOL


@settings(max_examples=600, deadline=None)
@given(_cases("mht"))
def test_expansion_of_a_scan_mht(case: Case) -> None:
    _assert_same(case)


@settings(max_examples=300, deadline=None)
@given(_cases("paper"))
def test_expansion_of_a_scan_paper(case: Case) -> None:
    _assert_same(case)


@settings(max_examples=300, deadline=None)
@given(
    st.lists(
        st.tuples(
            st.frozensets(st.integers(0, 6), max_size=4),
            st.one_of(_WEIGHTS, st.just(-math.inf)),
            _RATES,
        ),
        min_size=1,
        max_size=12,
    ),
    st.sampled_from([0.0, 1e-3, 0.1, 0.9]),
    st.integers(1, 6),
)
def test_merge_and_prune(
    children: list[tuple[frozenset[int], float, float]], ratio: float, max_hypotheses: int
) -> None:
    """``merge`` then ``prune`` (eq. 3, n_hyp,max): the same hypotheses in the same order,
    or the same error when none has a probability."""
    try:
        expected = prune(merge(children), ratio, max_hypotheses)
    except ValueError as error:
        with pytest.raises(ValueError, match=str(error)):
            _merge_prune(children, ratio, max_hypotheses)
        return
    got = _merge_prune(children, ratio, max_hypotheses)
    assert [h.tracks for h in got] == [h.tracks for h in expected]
    assert all(abs(g.log_weight - e.log_weight) <= TOL for g, e in zip(got, expected, strict=True))
    assert [h.rate for h in got] == [h.rate for h in expected]


@dataclass
class _Kept:
    tracks: frozenset[int]
    log_weight: float
    rate: float


def _merge_prune(
    children: list[tuple[frozenset[int], float, float]], ratio: float, max_hypotheses: int
) -> list[_Kept]:
    sizes, keys, weights, rates = _core.merge_prune(
        [len(c[0]) for c in children],
        [k for c in children for k in c[0]],
        [c[1] for c in children],
        [c[2] for c in children],
        ratio,
        max_hypotheses,
    )
    result = []
    at = 0
    for size, weight, rate in zip(sizes, weights, rates, strict=True):
        result.append(_Kept(frozenset(keys[at : at + size]), weight, rate))
        at += size
    return result


def test_bad_arrays_are_a_value_error_naming_the_argument() -> None:
    expansion = _core.ScanExpansion(0.01, 10, "mht", math.log(0.01))
    empty: tuple[list[int], list[int], list[float]] = ([], [], [])
    with pytest.raises(ValueError, match="track_rates"):
        expansion.scan(
            (0, 0, 0), ([1], [], []), ([], [], [], [], [], []), ([], [], [], []), empty, empty
        )
    with pytest.raises(ValueError, match="hypothesis_keys"):
        expansion.scan(
            (5, 5, 1),
            ([1], [1.0], [None]),
            ([0], [1], [2], [1], [0.0], [1.0]),
            ([], [], [], []),
            empty,
            empty,
        )
    with pytest.raises(ValueError, match="object version"):  # a version not given
        expansion.scan(
            (5, 7, 1),
            ([], [], []),
            ([0], [1], [1], [1], [0.0], [1.0]),
            ([1], [None], [1, 6], [0.0] * 5),
            ([0], [], []),
            ([0], [], []),
        )
    with pytest.raises(ValueError, match="association_model"):
        _core.ScanExpansion(0.01, 10, "jpda", 0.0)
