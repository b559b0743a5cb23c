"""Merging, pruning and normalising hypotheses (paper 002 III-D, eq. (3); paper 000 C1)."""

from __future__ import annotations

import math
from collections.abc import Iterable

import numpy as np

from semwm.mhf.state import Hypothesis


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
            entry[0] = float(np.logaddexp(entry[0], log_weight))
    return merged


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
    items.sort(key=lambda item: item[0], reverse=True)
    best = items[0][0]
    if ratio > 0.0:
        floor = best + math.log(ratio)
        items = [item for item in items if item[0] >= floor]
    del items[max_hypotheses:]
    if len(items) <= 32:  # small sets: plain floats beat numpy's per-call cost
        log_total = best + math.log(math.fsum(math.exp(item[0] - best) for item in items))
    else:
        weights = np.fromiter((item[0] for item in items), dtype=float, count=len(items))
        log_total = best + math.log(float(np.exp(weights - best).sum()))
    return tuple(Hypothesis(lw - log_total, tracks, rate) for lw, tracks, rate in items)
