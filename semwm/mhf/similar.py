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

import numpy as np

from semwm.mhf.prune import log_add
from semwm.mhf.state import Hypothesis, Track

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
    weights = [h.log_weight for h in hypotheses]
    absorbed: set[int] = set()
    for members in groups.values():
        kept: list[tuple[int, dict[int, Track]]] = []  # representative, lineage -> version
        for index in members:  # most probable first
            h = hypotheses[index]
            versions = {tracks[k].lineage: tracks[k] for k in h.tracks}
            for representative, held in kept:
                if all(
                    same_estimate(
                        held[lineage],
                        version,
                        existence.get(held[lineage].key, 1.0),
                        existence.get(version.key, 1.0),
                        max_distance,
                    )
                    for lineage, version in versions.items()
                    if held[lineage].key != version.key
                ):
                    weights[representative] = log_add(weights[representative], weights[index])
                    absorbed.add(index)
                    break
            else:
                kept.append((index, versions))
    if not absorbed:
        return tuple(hypotheses)
    result = [
        Hypothesis(weights[i], h.tracks, h.rate)
        for i, h in enumerate(hypotheses)
        if i not in absorbed
    ]
    result.sort(key=lambda h: h.log_weight, reverse=True)
    return tuple(result)
