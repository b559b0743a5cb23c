"""A brute-force reference MHF, written plainly from paper 002 Section III and eqs. (1)-(8).

No sharing, no gating, no batching, no log space: every hypothesis is a plain list
of objects, each object carries its own Kalman filter (a zeroth-order, constant
position model: x- = x, P- = P + dt Qc), and every detection expands every
hypothesis into

* clutter,
* a new object at the detection (P = P0 of the detection's class),
* each existing object whose class is compatible with the detection's (taxonomy)
  and that has not taken a detection of the current scan yet (an object takes at
  most one detection per scan; an object created in this scan has taken one).

Probabilities (model ``paper``), for a parent ``h`` and
``F = f_clutter + f_new(h) + sum_{o in h} f_existing(C(o))``:

* clutter ``f_clutter / F``,
* new ``f_new(h) / F`` with ``f_new(h)`` = max of the class base rate and every
  appearance relation of the detection's class whose target (a known map object, or
  an object of ``h`` that existed before the scan, at its predicted position) lies
  within ``max_distance`` (eq. 4),
* existing ``o``: ``f_existing(C(o)) / F * exp(-1/2 d^T R^-1 d)``, ``d = z - x+``.

Model ``mht`` (existence per object, class distribution per object): no per-parent
``F``; one child "new or clutter" of weight ``f_clutter / V + f_new / V`` (``f_new``
from eq. 4 as above, spread over the disc of a relation), times ``label_error_rate``
when a labelled detection meets a hypothesis in which an object holds that label; it
starts an object with existence ``b / (b + c)``; existing ``o``: ``r_o * f_existing *
L_class * N(z; x-, P- + R)`` (times ``label_error_rate`` for another label, or for
no label while another object of the hypothesis holds the detection's; for the
object holding the detection's label within ``label_gate``, N is 0.9 N(S) + 0.1 N(S +
(label_gate / 3)^2 I)). Between scans every object's existence decays and every
Between scans every object's existence decays by its leave rate (no weight); at a
scan, the objects its source watches (the source took a detection of the object, and
it lies within the convex hull of the scan's detections widened by its noise margin,
or it has had no detection after the time it was created) are
missed over the time since the source's previous scan, and every hypothesis is
weighted by their missed-detection probabilities q (rates f_existing times the
probability of being inside the region widened by the noise's gate quantile); objects
with existence times that probability below ``removal_existence`` are removed. Class distributions
use L(reported | true) = 1 (reported is true or a superclass), ``confusion_rate``
(a common ancestor), ``unrelated_confusion_rate`` (none); the class is the most
specific one whose subtree holds more than half.

Detections clearly outside the region (beyond an edge by more than their noise at the
gate's one-dimensional quantile) are ignored. Then Bayes (eq. 1): children normalised over all parents; pruned by ratio alpha
(eq. 3) after each detection. Objects whose largest position variance exceeds
P_max, or unseen longer than the class's maximum, are removed at each scan's time
(before its detections); hypotheses that became identical are merged.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field, replace

import numpy as np
from scipy.special import chdtri

from semwm.knowledge.model import Knowledge
from semwm.mhf.rates import hull_distance


@dataclass(frozen=True)
class RefDetection:
    seq: int
    time: float
    cls: str
    z: np.ndarray
    label: str | None = None
    source: str | None = None


@dataclass(frozen=True)
class RefObject:
    lineage: int
    history: tuple[int, ...]  # seqs of the detections this object took
    cls: str
    label: str | None
    x: np.ndarray
    P: np.ndarray
    time: float
    last_seen: float
    r: float = 1.0
    probs: tuple[tuple[str, float], ...] = ()
    sources: frozenset[str] = frozenset()  # the sources of the detections it took

    @property
    def identity(self) -> tuple[int, tuple[int, ...], str | None]:
        return (self.lineage, self.history, self.label)


@dataclass
class RefHypothesis:
    p: float
    objects: list[RefObject] = field(default_factory=list)


class ReferenceMHF:
    def __init__(self, knowledge: Knowledge, *, f_counts_taken: bool = False) -> None:
        """``f_counts_taken``: F sums f_existing over every object of the parent, including
        objects that already took a detection of this scan (the MHF's first behaviour, kept
        for comparison). ``False`` (the MHF's): only objects open to the detection."""
        self.k = knowledge
        self.f_counts_taken = f_counts_taken
        self.model = knowledge.world.association_model
        self.ratio = knowledge.world.pruning_ratio
        self.detector = knowledge.detectors[knowledge.default_detector]
        self.hypotheses = [RefHypothesis(1.0, [])]
        self.time: float | None = None
        region = knowledge.world.region
        self.volume = math.prod(hi - lo for lo, hi in region) if region else 1.0
        # each source's clock (semwm.mhf.rates.SourceClock): last scan, mean interval
        # between its scans
        self.created: dict[int, float] = {}  # lineage (its first detection) -> time
        self.last_scan: dict[str, float] = {}
        self.intervals: dict[str, float] = {}

    # -------------------------------------------------------------- knowledge
    def ancestors(self, cls: str) -> set[str]:
        out: set[str] = set()
        todo = list(self.k.classes[cls].parents)
        while todo:
            c = todo.pop()
            if c not in out:
                out.add(c)
                todo.extend(self.k.classes[c].parents)
        return out

    def is_a(self, a: str, b: str) -> bool:
        return a == b or b in self.ancestors(a)

    def compatible(self, a: str, b: str) -> bool:
        return self.is_a(a, b) or self.is_a(b, a)

    def R(self, cls: str) -> np.ndarray:
        noise = self.detector.measurement_noise
        for name in (cls, *self.k.classes[cls].ancestors):
            if name in noise:
                return np.array(noise[name], dtype=float)
        return np.array(self.k.classes[cls].measurement_noise, dtype=float)

    def Qc(self, cls: str) -> np.ndarray:
        return np.array(self.k.classes[cls].filter.model.system_noise, dtype=float)  # type: ignore[union-attr]

    def f_existing(self, cls: str) -> float:
        return self.k.classes[cls].detection_frequency

    # -------------------------------------------------------------- mht pieces
    def related(self, a: str, b: str) -> bool:
        return bool(({a} | self.ancestors(a)) & ({b} | self.ancestors(b)))

    def confusion(self, reported: str, true: str) -> float:
        if self.is_a(true, reported):
            return 1.0
        if self.related(true, reported):
            return self.detector.confusion_rate
        return self.detector.unrelated_confusion_rate

    def initial_probs(self, reported: str) -> dict[str, float]:
        can = [c for c, spec in self.k.classes.items() if spec.new_frequency > 0 or spec.appearance]
        w = {c: self.confusion(reported, c) for c in can}
        total = sum(w.values())
        return {c: v / total for c, v in w.items()}

    def published(self, probs: dict[str, float]) -> str:
        names = sorted(self.k.classes)
        mass = {n: sum(p for c, p in probs.items() if self.is_a(c, n)) for n in names}
        candidates = [n for n in names if mass[n] > 0.5 + 1e-12]
        depth = {n: len(self.ancestors(n)) for n in names}
        if not candidates:  # no class holds more than half: the most probable one
            return max(names, key=lambda n: (probs.get(n, 0.0), -names.index(n)))
        return max(candidates, key=lambda n: (depth[n], mass[n], -names.index(n)))

    def margin(self, o: RefObject, axis: int) -> float:
        """How far outside the region an object still counts as on its edge: its class's
        noise at the gate's one-dimensional quantile (0 with the gate off)."""
        p = self.k.world.gate_probability
        gamma = float(chdtri(1, 1.0 - p)) if p < 1.0 else 0.0
        return math.sqrt(gamma * self.R(o.cls)[axis, axis])

    def inside(self, o: RefObject) -> float:
        region = self.k.world.region
        if region is None:
            return 1.0
        p = 1.0
        for axis, (lo, hi) in enumerate(region):
            # without P_max the spread counts up to the class's noise: growth while
            # unseen is no exit
            variance = o.P[axis, axis]
            if self.k.classes[o.cls].max_position_variance is None:
                variance = min(variance, self.R(o.cls)[axis, axis])
            sd = math.sqrt(variance)
            m = self.margin(o, axis)
            cdf = lambda v: 0.5 * (1.0 + math.erf(v / math.sqrt(2.0)))  # noqa: E731
            p *= cdf((hi + m - o.x[axis]) / sd) - cdf((lo - m - o.x[axis]) / sd)
        return p

    def leave(self, o: RefObject, dt: float) -> RefObject:
        """Existence after dt: it may have left (rate mu); no evidence, no weight."""
        mu = self.k.classes[o.cls].leave_frequency
        return replace(o, r=o.r * math.exp(-mu * dt))

    def watched(self, o: RefObject, scan: Sequence[RefDetection]) -> bool:
        """The scan's source detected the object before, and it lies within the convex
        hull of the scan's detections widened by its margin, or it is unconfirmed."""
        source = scan[0].source or ""
        if source not in o.sources:
            return False
        if o.last_seen <= self.created[o.lineage]:  # no detection since its first
            return True
        radius = max(self.margin(o, a) for a in range(len(o.x)))
        corners = np.array([z.z for z in scan])
        return float(hull_distance(o.x[None, :], corners)[0]) <= radius

    def miss(self, o: RefObject, span: float) -> tuple[RefObject, float]:
        """Existence after the scan's source looked for span seconds where the object is
        and did not report it, and q = P(no detection)."""
        f = self.f_existing(o.cls) * self.inside(o)
        stay = math.exp(-f * span)
        q = (1.0 - o.r) + o.r * stay
        return replace(o, r=o.r * stay / q), q

    def miss_span(self, source: str, t: float) -> float:
        """The time since the source's previous scan, at most twice its mean interval."""
        last = self.last_scan.get(source)
        if last is None or t <= last:
            return 0.0
        interval = self.intervals.get(source)
        return t - last if interval is None else min(t - last, 2.0 * interval)

    def after_scan(self, scan: Sequence[RefDetection]) -> None:
        """The source's clock: last scan, mean interval between its scans."""
        source, t = scan[0].source or "", scan[0].time
        last = self.last_scan.get(source)
        if last is not None and t > last:
            old = self.intervals.get(source)
            self.intervals[source] = t - last if old is None else 0.9 * old + 0.1 * (t - last)
        if last is None or t > last:
            self.last_scan[source] = t

    @staticmethod
    def density(y: np.ndarray, S: np.ndarray) -> float:
        return math.exp(-0.5 * float(y @ np.linalg.inv(S) @ y)) / math.sqrt(
            (2 * math.pi) ** len(y) * np.linalg.det(S)
        )

    # -------------------------------------------------------------- pieces
    def predict(self, o: RefObject, t: float) -> RefObject:
        dt = t - o.time
        if dt <= 0:
            return o
        return replace(o, P=o.P + dt * self.Qc(o.cls), time=t)

    def leaving(self, o: RefObject, t: float) -> bool:
        spec = self.k.classes[o.cls]
        if spec.max_position_variance is not None:
            if np.linalg.eigvalsh(o.P).max() > spec.max_position_variance:
                return True
        if spec.max_time_without_update is not None:
            if t - o.last_seen > spec.max_time_without_update:
                return True
        return False

    def birth(self, z: RefDetection, before: Sequence[RefObject]) -> float:
        """f_new (eq. 4), times the spatial density for mht."""
        spec = self.k.classes[z.cls]
        best = spec.new_frequency / (self.volume if self.model == "mht" else 1.0)
        for rel in spec.appearance:
            value = rel.frequency / (math.pi * rel.max_distance**2 if self.model == "mht" else 1.0)
            targets = [
                np.array(k.position, float)
                for k in self.k.known_objects
                if self.is_a(k.cls, rel.target)
            ]
            targets += [o.x for o in before if self.is_a(o.cls, rel.target)]
            if any(np.linalg.norm(z.z - pos) <= rel.max_distance for pos in targets):
                best = max(best, value)
        return best

    @staticmethod
    def relabel(objects: list[RefObject], holder: int, label: str | None) -> list[RefObject]:
        """Paper 000 III-B: the other objects carrying the holder's label give it up."""
        if label is None:
            return objects
        return [
            replace(o, label=None) if i != holder and o.label == label else o
            for i, o in enumerate(objects)
        ]

    # -------------------------------------------------------------- the filter
    def outside(self, z: RefDetection) -> bool:
        """Clearly outside the region: beyond an edge by more than its noise's margin (such
        a detection is ignored, semwm.validation.outside_region)."""
        region = self.k.world.region
        if region is None:
            return False
        p = self.k.world.gate_probability
        gamma = float(chdtri(1, 1.0 - p)) if p < 1.0 else 0.0
        R = self.R(z.cls)
        return any(
            not lo - math.sqrt(gamma * R[a, a]) <= z.z[a] <= hi + math.sqrt(gamma * R[a, a])
            for a, (lo, hi) in enumerate(region)
        )

    def process_scan(self, scan: Sequence[RefDetection]) -> None:
        scan = [z for z in scan if not self.outside(z)]
        if not scan:
            return
        t = scan[0].time
        self.created.update((z.seq, z.time) for z in scan)
        merged: dict[frozenset, RefHypothesis] = {}
        for h in self.hypotheses:
            objects = [self.predict(o, t) for o in h.objects]
            p = h.p
            if self.model == "mht" and self.time is not None and t > self.time:
                objects = [self.leave(o, t - self.time) for o in objects]
            if self.model == "mht" and self.time is not None:
                span = self.miss_span(scan[0].source or "", t)
                if span > 0.0:
                    missed = [
                        self.miss(o, span) if self.watched(o, scan) else (o, 1.0) for o in objects
                    ]
                    objects = [o for o, _ in missed]
                    p *= math.prod(q for _, q in missed)
            objects = [o for o in objects if not self.leaving(o, t)]
            if self.model == "mht":
                floor = self.k.world.removal_existence
                objects = [o for o in objects if o.r * self.inside(o) >= floor]
            key = frozenset(o.identity for o in objects)
            if key in merged:
                merged[key].p += p
            else:
                merged[key] = RefHypothesis(p, objects)
        self.time = t
        # each hypothesis: (p, objects, lineages that already took a detection of this scan)
        current = [(h.p, h.objects, set(), list(h.objects)) for h in merged.values()]
        total = sum(c[0] for c in current)
        current = [(p / total, objs, taken, before) for p, objs, taken, before in current]
        for z in scan:
            R = self.R(z.cls)
            Rinv = np.linalg.inv(R)
            children = []
            for p, objs, taken, before in current:
                f_c = self.detector.clutter_frequency
                f_new = self.birth(z, before)
                if self.model == "paper":
                    F = (
                        f_c
                        + f_new
                        + sum(
                            self.f_existing(o.cls)
                            for o in objs
                            if self.f_counts_taken or o.lineage not in taken
                        )
                    )
                    w_clutter, w_new = f_c / F, f_new / F
                else:
                    F = 1.0
                    w_clutter = f_c / self.volume
                    w_new = f_new
                    held = z.label is not None and any(o.label == z.label for o in objs)
                    w = (w_clutter + w_new) * (self.k.world.label_error_rate if held else 1.0)
                    probs = self.initial_probs(z.cls)
                    new = RefObject(
                        z.seq,
                        (z.seq,),
                        self.published(probs),
                        z.label,
                        z.z.copy(),
                        np.array(self.k.classes[z.cls].initial_covariance, float),
                        t,
                        t,
                        r=w_new / (w_clutter + w_new),
                        probs=tuple(sorted(probs.items())),
                        sources=frozenset({z.source or ""}),
                    )
                    if w_new > 0:
                        kids = self.relabel([*objs, new], len(objs), z.label)
                        children.append((p * w, kids, taken | {z.seq}, before))
                    elif w > 0:
                        children.append((p * w, objs, taken, before))
                    w_clutter = w_new = 0.0
                if w_clutter > 0:
                    children.append((p * w_clutter, objs, taken, before))
                if w_new > 0:
                    new = RefObject(
                        z.seq,
                        (z.seq,),
                        z.cls,
                        z.label,
                        z.z.copy(),
                        np.array(self.k.classes[z.cls].initial_covariance, float),
                        t,
                        t,
                        sources=frozenset({z.source or ""}),
                    )
                    kids = self.relabel([*objs, new], len(objs), z.label)
                    children.append((p * w_new, kids, taken | {z.seq}, before))
                for i, o in enumerate(objs):
                    if o.lineage in taken:
                        continue
                    if self.model == "paper" and not self.compatible(o.cls, z.cls):
                        continue
                    S = o.P + R
                    K = o.P @ np.linalg.inv(S)
                    x_post = o.x + K @ (z.z - o.x)
                    I = np.eye(len(o.x))
                    P_post = (I - K) @ o.P @ (I - K).T + K @ R @ K.T
                    if self.model == "paper":
                        delta = z.z - x_post
                        lik = math.exp(-0.5 * float(delta @ Rinv @ delta))
                        w = self.f_existing(o.cls) / F * lik
                        refined = o.cls if self.is_a(o.cls, z.cls) else z.cls
                        probs_post: tuple[tuple[str, float], ...] = ()
                    else:
                        y = z.z - o.x
                        dens = self.density(y, S)
                        gate = self.k.world.label_gate
                        if z.label is not None and o.label == z.label and np.linalg.norm(y) <= gate:
                            wide = S + (gate / 3.0) ** 2 * np.eye(len(y))
                            dens = 0.9 * dens + 0.1 * self.density(y, wide)
                        old_probs = dict(o.probs)
                        l_class = sum(
                            p_c * self.confusion(z.cls, c) for c, p_c in old_probs.items()
                        )
                        w = o.r * self.f_existing(o.cls) * l_class * dens
                        if z.label is not None and o.label not in (None, z.label):
                            w *= self.k.world.label_error_rate
                        elif (
                            z.label is not None
                            and o.label is None
                            and any(other.label == z.label for other in objs)
                        ):  # an unlabelled object takes the label from its holder
                            w *= self.k.world.label_error_rate
                        post = {
                            c: p_c * self.confusion(z.cls, c) / l_class
                            for c, p_c in old_probs.items()
                        }
                        refined = self.published(post)
                        probs_post = tuple(sorted(post.items()))
                    updated = RefObject(
                        o.lineage,
                        (*o.history, z.seq),
                        refined,
                        z.label if z.label is not None else o.label,
                        x_post,
                        P_post,
                        t,
                        t,
                        r=1.0,
                        probs=probs_post,
                        sources=o.sources | {z.source or ""},
                    )
                    kids = list(objs)
                    kids[i] = updated
                    kids = self.relabel(kids, i, z.label)
                    children.append((p * w, kids, taken | {o.lineage}, before))
            total = sum(c[0] for c in children)
            children = [(c[0] / total, *c[1:]) for c in children]
            if self.ratio > 0:
                best = max(c[0] for c in children)
                children = [c for c in children if c[0] >= self.ratio * best]
                total = sum(c[0] for c in children)
                children = [(c[0] / total, *c[1:]) for c in children]
            current = children
        self.hypotheses = [RefHypothesis(p, objs) for p, objs, _, _ in current]
        self.after_scan(scan)


def run_reference(
    knowledge: Knowledge, scans: Sequence[Sequence[RefDetection]], **options: bool
) -> ReferenceMHF:
    ref = ReferenceMHF(knowledge, **options)
    for scan in scans:
        ref.process_scan(scan)
    return ref
