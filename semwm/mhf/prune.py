"""Merging, pruning and normalising hypotheses (paper 002 III-D, eq. (3); paper 000 C1).

Hypotheses are merged by hashing: a hypothesis is identified by the frozen set of
object versions it holds, so children with the same set meet in one dict entry
(no pairwise comparison). The per-entry arithmetic is plain ``math`` on floats:
numpy's per-call cost is larger than the work for a single pair.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from operator import itemgetter
from typing import TypeAlias, TypeVar

from semwm.mhf.state import Hypothesis

_Item: TypeAlias = tuple[float, frozenset[int], float]
"""A hypothesis being pruned: log weight, objects, rate."""
_T = TypeVar("_T", bound=_Item)

TIE = 1e-9
"""Log weights closer than this are a tie: the rounding of the arithmetic that made them
never decides (eq. 3's floor keeps what lies within it of the floor; hypotheses that
tie are ordered by the objects they hold). Two engines, or two orders of the same
sums, differ in the last bits of a weight; hypotheses equal in exact arithmetic (two
births whose weights do not depend on where they are, one at exactly alpha of the
best) would otherwise be kept or pruned, ranked first or second, by those bits."""


def log_add(a: float, b: float) -> float:
    """``log(exp(a) + exp(b))`` without overflow (``numpy.logaddexp`` for two floats)."""
    if a < b:
        a, b = b, a
    if b == -math.inf:
        return a
    return a + math.log1p(math.exp(b - a))


def merge(
    children: Iterable[tuple[frozenset[int], float, float]],
) -> dict[frozenset[int], list[float]]:
    """Merge children that hold the same objects: their probabilities add (log-sum-exp)."""
    merged: dict[frozenset[int], list[float]] = {}
    for tracks, log_weight, rate in children:
        entry = merged.get(tracks)
        if entry is None:
            merged[tracks] = [log_weight, rate]
        else:
            entry[0] = log_add(entry[0], log_weight)
    return merged


def ties_in_order(items: list[_T]) -> list[_T]:
    """``items`` (most probable first) with each run of ties (log weights within
    :data:`TIE` of the run's first) ordered by the objects they hold (their sorted
    keys), so that which of them comes first does not depend on rounding."""
    result: list[_T] = []
    i, count = 0, len(items)
    while i < count:
        j = i + 1
        while j < count and items[i][0] - items[j][0] <= TIE:
            j += 1
        if j - i > 1:
            result.extend(sorted(items[i:j], key=lambda item: sorted(item[1])))
        else:
            result.append(items[i])
        i = j
    return result


def prune(
    merged: dict[frozenset[int], list[float]], ratio: float, max_hypotheses: int
) -> tuple[Hypothesis, ...]:
    """Keep hypotheses within ``ratio`` of the best (eq. 3) and at most ``max_hypotheses``;
    normalise so that the probabilities sum to one. Most probable first.

    .. math:: p(h^i_k | z_{1:k}) \\ge \\alpha \\max_j p(h^j_k | z_{1:k})
    """
    items = [(lw, tracks, rate) for tracks, (lw, rate) in merged.items() if lw > -math.inf]
    if not items:
        raise ValueError("every hypothesis has zero probability")
    items.sort(key=itemgetter(0), reverse=True)
    best = items[0][0]
    if ratio > 0.0:
        floor = best + math.log(ratio) - TIE
        items = [item for item in items if item[0] >= floor]
    items = ties_in_order(items)
    del items[max_hypotheses:]
    exp = math.exp
    log_total = best + math.log(math.fsum([exp(lw - best) for lw, _, _ in items]))
    return tuple([Hypothesis(lw - log_total, tracks, rate) for lw, tracks, rate in items])
