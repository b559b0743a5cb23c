"""Candidate pairs of nearby points from a k-d tree, instead of every pair.

Gating a scan (:mod:`semwm.mhf.association`) and finding the lineages that are one
object (:meth:`semwm.world.WorldModel._same_objects`) test a cheap distance bound on
pairs of points. Over every pair that costs O(N^2) time and memory: at 1,000 objects
a (1000, 1000, d) difference array per scan, most of the scan's time. A k-d tree
(:class:`scipy.spatial.cKDTree`) finds the pairs within a radius in O(N log N). The
radii here are slightly widened, so the pairs returned are a superset of those that
pass the exact bound; callers apply the exact bound to them, so the outcome is the
same pairs in the same (row-major) order as the dense test.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
from scipy.spatial import cKDTree

from semwm.filters.motion import FloatArray

IndexArray = npt.NDArray[np.intp]

DENSE_PAIRS = 4096
"""Up to this many pairs the dense test is cheaper than building a tree."""

_WIDEN = 1.0 + 1e-9  # radii widened against rounding at the boundary


def within(
    points: FloatArray, centres: FloatArray, radius: FloatArray
) -> tuple[IndexArray, IndexArray]:
    """Pairs ``(p, c)`` with ``|points[p] - centres[c]| <= radius[c]`` (a superset, see
    the module docstring), sorted by ``p`` then ``c``: the order of ``np.nonzero`` on a
    ``(P, C)`` mask."""
    tree = cKDTree(points)
    found = tree.query_ball_point(centres, radius * _WIDEN + 1e-12)
    counts = np.fromiter((len(f) for f in found), dtype=np.intp, count=len(found))
    if not counts.sum():
        empty = np.empty(0, dtype=np.intp)
        return empty, empty
    cc = np.repeat(np.arange(len(found), dtype=np.intp), counts)
    pp = np.fromiter((p for f in found for p in f), dtype=np.intp, count=int(counts.sum()))
    order = np.lexsort((cc, pp))
    return pp[order], cc[order]


def close_pairs(points: FloatArray, radius: FloatArray) -> tuple[IndexArray, IndexArray]:
    """Pairs ``(a, b)``, ``a < b``, with ``|points[a] - points[b]| <= max(radius[a],
    radius[b])`` (a superset), sorted by ``a`` then ``b``."""
    aa, bb = within(points, points, radius)
    lo, hi = np.minimum(aa, bb), np.maximum(aa, bb)
    keep = lo < hi
    if not keep.any():
        return lo[keep], hi[keep]
    pairs = np.unique(np.stack([lo[keep], hi[keep]], axis=1), axis=0)  # sorted rows
    return pairs[:, 0], pairs[:, 1]


def usable(*arrays: FloatArray) -> bool:
    """Whether a tree can hold these (every value finite)."""
    return all(bool(np.all(np.isfinite(a))) for a in arrays)
