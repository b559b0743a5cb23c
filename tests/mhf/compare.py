"""Comparing the real world model's hypotheses with the reference's."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from semwm.world import WorldModel

from .reference import ReferenceMHF

Hyp = tuple[float, list[tuple[int, str, str | None, tuple[float, ...]]]]


def real_hypotheses(wm: WorldModel) -> list[Hyp]:
    return [
        (
            h.probability,
            sorted((o.track, o.cls, o.label, (*o.position, o.existence)) for o in h.objects),
        )
        for h in wm.hypotheses(10**9)
    ]


def ref_hypotheses(ref: ReferenceMHF) -> list[Hyp]:
    """The reference's hypotheses; an object's 'position' carries its existence last."""
    return [
        (
            h.p,
            sorted((o.lineage, o.cls, o.label, (*(float(v) for v in o.x), o.r)) for o in h.objects),
        )
        for h in ref.hypotheses
    ]


def lineage_existence(ref: ReferenceMHF) -> dict[int, tuple[str, float]]:
    """Lineage -> (class in the most probable hypothesis holding it, existence summed
    over hypotheses, inside the region)."""
    totals: dict[int, float] = {}
    chosen: dict[int, str] = {}
    for h in sorted(ref.hypotheses, key=lambda h: -h.p):
        for o in h.objects:
            totals[o.lineage] = totals.get(o.lineage, 0.0) + h.p * o.r * ref.inside(o)
            chosen.setdefault(o.lineage, o.cls)
    return {lin: (chosen[lin], total) for lin, total in totals.items()}


def published(ref: ReferenceMHF, floor: float) -> list[tuple[int, str]]:
    """(lineage, class) of the objects whose existence over all hypotheses (sum of p times
    existence inside the region) is at least ``floor``, each in the version of the most
    probable hypothesis holding it."""
    return sorted(
        (lin, cls) for lin, (cls, total) in lineage_existence(ref).items() if total >= floor
    )


def _same_objects(a: Hyp, b: Hyp, tol: float) -> bool:
    if len(a[1]) != len(b[1]):
        return False
    for (la, ca, lba, xa), (lb, cb, lbb, xb) in zip(a[1], b[1], strict=True):
        if (la, ca, lba) != (lb, cb, lbb) or not np.allclose(xa, xb, rtol=0, atol=tol):
            return False
    return True


def assert_same_hypotheses(real: Sequence[Hyp], ref: Sequence[Hyp], tol: float = 1e-9) -> None:
    """The two are the same multiset of (probability, objects), to ``tol``."""
    assert math.isclose(sum(p for p, _ in real), 1.0, abs_tol=1e-9)
    left = list(ref)
    for hyp in real:
        match = next(
            (
                i
                for i, r in enumerate(left)
                if abs(r[0] - hyp[0]) <= tol and _same_objects(hyp, r, tol)
            ),
            None,
        )
        assert match is not None, (
            f"real hypothesis {hyp} not in the reference;\nreference: {sorted(left, key=lambda h: -h[0])}"
        )
        del left[match]
    assert not left, f"reference hypotheses missing from the real MHF: {left}"


def map_objects(hyps: Sequence[Hyp]) -> list | None:
    """Objects (lineage, class) of the most probable hypothesis; None if it is a tie."""
    ranked = sorted(hyps, key=lambda h: -h[0])
    if len(ranked) > 1 and ranked[0][0] - ranked[1][0] < 1e-9:
        return None
    return [(lin, cls) for lin, cls, _, _ in ranked[0][1]]
