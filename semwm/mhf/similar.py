r"""Merging hypotheses that hold the same objects with near-identical estimates.

Two hypotheses of a cluster often differ only in how one detection long ago was
explained (taken by the object, or called clutter): they hold the same objects
(lineages), and after hundreds of later detections their versions of each
object are the same estimate to within a fraction of its standard deviation.
Paper 002 merges hypotheses only when they hold the very same versions, so such
twins stay, multiply with every scan, and are carried until pruning removes
them: on a team's stream of detections of static objects the stored hypotheses
grow without bound (issue 15, the team's load).

Here two hypotheses with the same lineages merge (their probabilities add, the
more probable one's versions are kept: a standard MHT hypothesis merge) when for
every object whose versions differ, ``a`` and ``b``:

.. math::
   (\hat x_a - \hat x_b)^\top P_a^{-1} (\hat x_a - \hat x_b) \le d^2_{max}
   \quad\text{per motion model},
   \qquad |\log\det P_a - \log\det P_b| \le 0.1,

and their class, label, existence, model probabilities and class distribution
agree (existence, model and class probabilities within 0.01). ``d^2_max`` is the
world setting ``merge_distance`` (0 turns merging off; the default 0.01 is a
tenth of a standard deviation).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import cast

import numpy as np

from semwm.mhf.prune import log_add, ties_in_order
from semwm.mhf.state import Hypothesis, Track

_WIDEN = 1.0 + 1e-6  # the cheap bound's margin against rounding (it must not cut a twin)

PROBABILITY_TOLERANCE = 0.01
LOG_DET_TOLERANCE = 0.1


def same_estimate(
    a: Track, b: Track, existence_a: float, existence_b: float, max_distance: float
) -> bool:
    """Whether two versions of one object are the same estimate (module docstring)."""
    if a.key == b.key:
        return True
    if a.cls != b.cls or a.label != b.label or a.x.shape != b.x.shape:
        return False
    if abs(existence_a - existence_b) > PROBABILITY_TOLERANCE:
        return False
    if np.max(np.abs(a.mu - b.mu)) > PROBABILITY_TOLERANCE:
        return False
    if np.max(np.abs(a.class_probs - b.class_probs)) > PROBABILITY_TOLERANCE:
        return False
    delta = a.x - b.x  # (M, n)
    try:
        solved = np.linalg.solve(a.P, delta[..., None])[..., 0]
    except np.linalg.LinAlgError:
        return False
    if float(np.max(np.einsum("mi,mi->m", delta, solved))) > max_distance:
        return False
    sign_a, log_a = np.linalg.slogdet(a.P)
    sign_b, log_b = np.linalg.slogdet(b.P)
    if np.any(sign_a <= 0) or np.any(sign_b <= 0):
        return False
    return bool(np.max(np.abs(log_a - log_b)) <= LOG_DET_TOLERANCE)


def _same_pairs(
    lineages: Sequence[Sequence[Track]], existence: Mapping[int, float], max_distance: float
) -> set[tuple[int, int]]:
    """The ordered key pairs ``(a, b)``, ``a != b``, of versions of one lineage
    (``lineages``: the versions of each) that are the same estimate
    (:func:`same_estimate`), batched: every version of one state shape in one numpy
    expression, pairs kept only within one group (lineage, class, label)."""
    by_shape: dict[tuple[int, ...], tuple[list[Track], list[int]]] = {}
    group_of: dict[tuple[int, str, str | None], int] = {}
    for versions in lineages:
        for track in versions:  # lineage, class, label and state shape must agree
            gid = group_of.setdefault((track.lineage, track.cls, track.label), len(group_of))
            members, gids = by_shape.setdefault(track.x.shape, ([], []))
            members.append(track)
            gids.append(gid)
    result: set[tuple[int, int]] = set()
    for members, gids in by_shape.values():
        for chunk in _chunks(members, gids):
            result |= _same_in(chunk[0], np.asarray(chunk[1]), existence, max_distance)
    return result


_MAX_BATCH = 256  # versions compared in one expression (memory grows with its square)


def _chunks(members: list[Track], gids: list[int]) -> list[tuple[list[Track], list[int]]]:
    """``members`` in batches of whole groups of at most :data:`_MAX_BATCH` versions
    (one larger group is a batch of its own)."""
    if len(members) <= _MAX_BATCH:
        return [(members, gids)]
    by_group: dict[int, list[Track]] = {}
    for track, gid in zip(members, gids, strict=True):
        by_group.setdefault(gid, []).append(track)
    chunks: list[tuple[list[Track], list[int]]] = [([], [])]
    for gid, tracks in by_group.items():
        if chunks[-1][0] and len(chunks[-1][0]) + len(tracks) > _MAX_BATCH:
            chunks.append(([], []))
        chunks[-1][0].extend(tracks)
        chunks[-1][1].extend([gid] * len(tracks))
    return chunks


def _same_in(
    members: list[Track], gids: np.ndarray, existence: Mapping[int, float], max_distance: float
) -> set[tuple[int, int]]:
    """:func:`_same_pairs` of versions of one state shape, group ids ``gids``: only the
    pairs within one group are compared (versions of different lineages never merge)."""
    if len(members) < 2:
        return set()
    aa, bb = _pairs_within(gids)
    if aa.size == 0:
        return set()
    x = np.array([t.x for t in members])  # (V, M, n)
    P = np.array([t.P for t in members])  # (V, M, n, n)
    # A cheap necessary condition first: d2 <= max_distance needs, in the first mode,
    # |x_a - x_b|^2 <= max_distance * lambda_max(P_a) <= max_distance * trace(P_a)
    # (widened against rounding). A lineage with a hundred versions has ten thousand
    # pairs, of which about one in eight passes it.
    first = x[:, 0, :]
    gap = first[aa] - first[bb]
    reach = max_distance * np.trace(P[:, 0], axis1=1, axis2=2) * _WIDEN
    near = np.einsum("pi,pi->p", gap, gap) <= reach[aa]
    aa, bb = aa[near], bb[near]
    if aa.size == 0:
        return set()
    mu = np.array([t.mu for t in members])  # (V, M)
    probs = np.array([t.class_probs for t in members])  # (V, K)
    r = np.array([existence.get(t.key, 1.0) for t in members])
    sign, log_det = np.linalg.slogdet(P)  # (V, M)
    valid = np.all(sign > 0, axis=1)
    P_inv = np.linalg.inv(np.where(valid[:, None, None, None], P, np.eye(P.shape[-1])))
    delta = x[aa] - x[bb]  # (pairs, M, n): x_a - x_b
    d2 = np.einsum("pmi,pmij,pmj->pm", delta, P_inv[aa], delta).max(axis=1)
    same = (
        (d2 <= max_distance)
        & (np.abs(log_det[aa] - log_det[bb]).max(axis=1) <= LOG_DET_TOLERANCE)
        & (np.abs(r[aa] - r[bb]) <= PROBABILITY_TOLERANCE)
        & (np.abs(mu[aa] - mu[bb]).max(axis=1) <= PROBABILITY_TOLERANCE)
        & (np.abs(probs[aa] - probs[bb]).max(axis=1) <= PROBABILITY_TOLERANCE)
        & valid[aa]
        & valid[bb]
    )
    keys = [t.key for t in members]
    return {(keys[i], keys[j]) for i, j in zip(aa[same].tolist(), bb[same].tolist(), strict=True)}


def _pairs_within(gids: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Index pairs ``(a, b)``, ``a != b``, of entries with equal group id, ordered by
    ``a`` then ``b`` (both directions: the distance test is not symmetric)."""
    same = gids[:, None] == gids[None, :]
    np.fill_diagonal(same, False)
    aa, bb = np.nonzero(same)
    return aa, bb


def _twin_matrix(
    members: Sequence[Hypothesis], tracks: Mapping[int, Track], same: set[tuple[int, int]]
) -> list[list[bool]] | None:
    """For hypotheses holding the same lineages, ``twins[a][b]``: whether every version
    ``b`` holds is ``a``'s version of that object or the same estimate as it (``(a's
    key, b's key)`` in ``same``); ``None`` when no hypothesis is a twin of an earlier one
    (nothing of the group merges)."""
    lineage_order = sorted(tracks[k].lineage for k in members[0].tracks)
    column = {lineage: j for j, lineage in enumerate(lineage_order)}
    keys = np.empty((len(members), len(lineage_order)), dtype=np.int64)
    for row, h in enumerate(members):
        for key in h.tracks:
            keys[row, column[tracks[key].lineage]] = key
    distinct, local = np.unique(keys, return_inverse=True)
    local = local.reshape(keys.shape)
    count = len(distinct)
    position = {int(key): i for i, key in enumerate(distinct.tolist())}
    alike = np.eye(count, dtype=bool)  # version -> version: equal, or the same estimate
    for a, b in same:
        i, j = position.get(a), position.get(b)
        if i is not None and j is not None:
            alike[i, j] = True
    twins = alike[local[:, None, :], local[None, :, :]].all(axis=2)  # (a, b)
    if not np.triu(twins, 1).any():
        return None
    return cast(list[list[bool]], twins.tolist())


def merge_similar(
    hypotheses: Sequence[Hypothesis],
    tracks: Mapping[int, Track],
    existence: Mapping[int, float],
    max_distance: float,
) -> tuple[Hypothesis, ...]:
    """The hypotheses (most probable first, normalised) with near-identical twins merged
    into the more probable one; the same tuple when nothing merges."""
    if len(hypotheses) < 2 or max_distance <= 0.0:
        return tuple(hypotheses)
    groups: dict[frozenset[int], list[int]] = {}
    for index, h in enumerate(hypotheses):
        groups.setdefault(frozenset(tracks[k].lineage for k in h.tracks), []).append(index)
    if all(len(members) == 1 for members in groups.values()):
        return tuple(hypotheses)
    # versions of each lineage held by hypotheses that have a twin candidate
    by_lineage: dict[int, dict[int, Track]] = {}
    for members in groups.values():
        if len(members) > 1:
            for index in members:
                for key in hypotheses[index].tracks:
                    track = tracks[key]
                    by_lineage.setdefault(track.lineage, {})[key] = track
    same = _same_pairs(
        [list(v.values()) for v in by_lineage.values() if len(v) > 1], existence, max_distance
    )
    if not same:
        return tuple(hypotheses)
    weights = [h.log_weight for h in hypotheses]
    absorbed: set[int] = set()
    for members in groups.values():
        if len(members) < 2:
            continue
        twins = _twin_matrix([hypotheses[i] for i in members], tracks, same)
        if twins is None:
            continue
        kept: list[int] = []  # positions in members of the representatives so far
        for position, index in enumerate(members):  # most probable first
            for representative in kept:
                if twins[representative][position]:
                    target = members[representative]
                    weights[target] = log_add(weights[target], weights[index])
                    absorbed.add(index)
                    break
            else:
                kept.append(position)
    if not absorbed:
        return tuple(hypotheses)
    result = [
        Hypothesis(weights[i], h.tracks, h.rate)
        for i, h in enumerate(hypotheses)
        if i not in absorbed
    ]
    result.sort(key=lambda h: h.log_weight, reverse=True)
    return tuple(ties_in_order(result))
