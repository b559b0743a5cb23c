"""Per-scan association: gating, batched updates, priors and likelihoods.

Everything a scan's hypothesis expansion needs is computed here once per scan,
batched with numpy, for the distinct objects only: each stored object version is
predicted once, gated against every detection of the scan (class and Mahalanobis
gates), and updated once per detection that passes the gate. Within a scan an
object can take at most one detection, so the gate is computed against the
versions that existed before the scan.

Two association models (``world.association_model``):

``paper`` (paper 002 eqs. (5)-(8))
    clutter ``f_clutter / F``, new ``f_new(o, h) / F``, existing
    ``f_existing(C(o)) / F * L_class * exp(-1/2 delta^T Sigma^-1 delta)`` with
    ``delta = z - H x+`` (the updated position) and ``Sigma = R``.
``mht`` (the default: a track-oriented MHT with existence probabilities)
    the same rates, but spread in space: clutter uniform over its detector's
    coverage (density ``f_c / V_c``), base births uniform over the region
    (``f_new / V``), births from an appearance relation uniform over the disc
    (ball) of its ``max_distance``. A detection no known object takes is *one*
    option, "new or clutter", of weight ``lambda_c + lambda_b``: it starts an object
    with existence ``lambda_b / (lambda_c + lambda_b)`` that later detections confirm
    or its misses deny (:mod:`semwm.mhf.existence`), so no new object is pruned
    before the evidence decides. An existing object ``o`` with existence ``r`` takes
    it with weight ``r f_e(o) L_class(o, z) N(z; H x-, S)``, ``L_class`` from the
    object's class distribution and the detector's confusion model
    (:mod:`semwm.mhf.classes`). A labelled detection can update the object holding
    its label within ``label_gate`` even outside the Mahalanobis gate, and any other
    explanation pays the prior ``label_error_rate`` (paper 000 III-B made a
    likelihood).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from typing import NamedTuple

import numpy as np
import numpy.typing as npt
from scipy.special import chdtri

from semwm.filters.factory import FilterFactory
from semwm.filters.motion import FloatArray
from semwm.filters.small import inverse_and_log_det, quadratic_form
from semwm.knowledge.coverage import birth_volume, coverage_volume
from semwm.knowledge.model import Knowledge
from semwm.knowledge.taxonomy import Taxonomy
from semwm.mhf import nearby
from semwm.mhf.classes import ClassModel, in_order_product
from semwm.mhf.measurement import Measurement
from semwm.mhf.predict import Predicted, conform
from semwm.mhf.prune import TIE, log_add
from semwm.mhf.state import Track

BoolArray = npt.NDArray[np.bool_]
IndexArray = npt.NDArray[np.intp]


class DetectionOptions(NamedTuple):
    """What one detection can be, with the log numerators of its priors times likelihoods.

    A named tuple: one per detection and scan, made faster than a frozen dataclass.

    Attributes
    ----------
    clutter_rate, log_clutter
        f_clutter and the log numerator of the clutter child.
    new_track, new_rate, new_log
        The new object it would be, and the base f_new (class rate or a known map
        object's relation) with its log numerator.
    presence
        Object key -> (rate, log numerator) for objects whose presence makes a new
        object here likelier than the base (eq. 4); only counted in hypotheses
        holding that object.
    existing
        Object key -> (updated version, log numerator, rate change) for each object
        that passed the gates.
    """

    measurement: Measurement
    clutter_rate: float
    log_clutter: float
    new_track: Track
    new_rate: float
    new_log: float
    presence: dict[int, tuple[float, float]]
    existing: dict[int, tuple[Track, float, float]]


class SettledUpdate(NamedTuple):
    """A detection that certainly updates one object (``mht``): the filter replaces the
    object's cluster by its updated version, with probability 1, and builds no options.

    What :meth:`semwm.mhf.filter.MultipleHypothesisFilter._certain_update` decides for
    one detection, decided for a scan's detections at once (:meth:`Associator.options`
    with ``settle``): the detection gates exactly one object and no other detection
    gates it, the object is alone and certain in its cluster, no detection of the scan
    has a label or an appearance relation (nothing else can reach the object), and
    "new object or clutter" falls below eq. (3)'s floor against the update.
    """

    measurement: Measurement
    old_key: int
    updated: Track


def _log(value: float) -> float:
    return math.log(value) if value > 0.0 else -math.inf


def ball_volume(radius: float, dim: int) -> float:
    return math.pi * radius**2 if dim == 2 else 4.0 / 3.0 * math.pi * radius**3


class Associator:
    """Builds the :class:`DetectionOptions` of a scan for one knowledge base."""

    def __init__(self, knowledge: Knowledge, factory: FilterFactory, taxonomy: Taxonomy) -> None:
        self.knowledge = knowledge
        self.factory = factory
        self.taxonomy = taxonomy
        self.dim = knowledge.world.dimension
        self.model = knowledge.world.association_model
        p = knowledge.world.gate_probability
        if p >= 1.0:
            self.gate = math.inf
        else:
            # chi2.ppf(p, dim) without importing scipy.stats (about 1.5 s at start-up)
            self.gate = float(chdtri(self.dim, 1.0 - p))
        world = knowledge.world
        self.clutter_log_density: dict[str, float] = {}
        for name, detector in knowledge.detectors.items():
            volume = coverage_volume(detector, world)
            self.clutter_log_density[name] = -math.log(volume) if volume else 0.0
        births = birth_volume(world, tuple(knowledge.detectors.values()))
        self.log_volume = math.log(births) if births else 0.0
        if self.model == "mht" and births is None:
            raise ValueError(
                "association_model 'mht' needs world.region or a detector range, to spread "
                "clutter and new objects over space"
            )

        can_appear = [
            name
            for name, spec in knowledge.classes.items()
            if spec.new_frequency > 0.0 or spec.appearance
        ]
        self.class_model = ClassModel(
            taxonomy,
            {
                name: (d.confusion_rate, d.unrelated_confusion_rate)
                for name, d in knowledge.detectors.items()
            },
            can_appear,
        )
        self._initial_classes: dict[tuple[str, str], tuple[FloatArray, str]] = {}
        self.label_gate = knowledge.world.label_gate
        self.log_label_error = math.log(knowledge.world.label_error_rate)

    def _initial_class(self, detector: str, reported: str) -> tuple[FloatArray, str]:
        """A new object's class distribution and published class (``mht``), once per
        detector and reported class (read-only: every new object shares it)."""
        key = (detector, reported)
        known = self._initial_classes.get(key)
        if known is None:
            probs = self.class_model.initial(detector, reported)
            probs.flags.writeable = False
            known = self._initial_classes[key] = (probs, self.class_model.published(probs))
        return known

    def _spread(self, radius: float) -> float:
        """Log spatial density of a birth within ``radius`` (mht model), else 0."""
        return -math.log(ball_volume(radius, self.dim)) if self.model == "mht" else 0.0

    def options(
        self,
        predicted: Predicted,
        measurements: Sequence[Measurement],
        new_key: Callable[[], int],
        existence: Sequence[float] = (),
        detection_rates: Mapping[str, FloatArray] | None = None,
        settle: Mapping[int, float] | None = None,
        log_ratio: float = -math.inf,
    ) -> list[DetectionOptions | SettledUpdate]:
        """Every detection's options against the predicted objects; ``existence`` is each
        predicted object's existence probability (``mht``), ``detection_rates`` per
        detector each predicted object's rate f_e in the weight of that detector's
        detections (:mod:`semwm.mhf.rates`; default: its class's).

        ``settle`` (``mht``): object key -> log weight of the only hypothesis of its
        cluster, for the objects alone and certain in theirs; with eq. (3)'s
        ``log_ratio``, a detection that certainly updates one of them is a
        :class:`SettledUpdate` instead of options (the key of the object it would have
        started is used up all the same, so keys do not depend on it).
        """
        tracks = predicted.tracks
        classes = self.knowledge.classes
        existing = self._existing(predicted, measurements, new_key, existence, detection_rates)
        spread_uniform = -self.log_volume if self.model == "mht" else 0.0
        settled = (
            self._settled(measurements, existing, settle, log_ratio) if settle is not None else {}
        )
        result: list[DetectionOptions | SettledUpdate] = []
        pending = [j for j in range(len(measurements)) if j not in settled]
        new_states = dict(
            zip(pending, self._new_states([measurements[j] for j in pending]), strict=True)
        )
        for j, m in enumerate(measurements):
            done = settled.get(j)
            if done is not None:
                new_key()  # the key its new object would have had
                result.append(done)
                continue
            resolved = classes[m.cls]
            base_rate = resolved.new_frequency
            base_log = _log(base_rate) + spread_uniform
            presence: dict[int, tuple[float, float]] = {}
            for relation in resolved.appearance:
                covered = self.taxonomy.covers(relation.target)
                log_num = _log(relation.frequency) + self._spread(relation.max_distance)
                for known in self.knowledge.known_objects:
                    if (
                        known.cls in covered
                        and _distance(m.z, known.position) <= relation.max_distance
                    ) and log_num > base_log:
                        base_rate, base_log = relation.frequency, log_num
                targets = [i for i, track in enumerate(tracks) if track.cls in covered]
                if not targets:
                    continue
                offset = predicted.position[targets] - m.z
                near = np.einsum("td,td->t", offset, offset) <= relation.max_distance**2
                for i in np.flatnonzero(near).tolist():
                    key = tracks[targets[i]].key
                    if log_num > presence.get(key, (0.0, -math.inf))[1]:
                        presence[key] = (relation.frequency, log_num)
            if presence:
                presence = {k: v for k, v in presence.items() if v[1] > base_log}
            x, P, mu = new_states[j]
            if self.model == "mht":
                class_probs, cls = self._initial_class(m.detector, m.cls)
                if cls != m.cls:
                    x, P, mu = conform(
                        x, P, mu, self.factory.filter_for(m.cls), self.factory.filter_for(cls)
                    )
            else:
                class_probs, cls = self.class_model.point(m.cls), m.cls
            new_track = Track(
                new_key(),
                m.seq,
                cls,
                m.label,
                x,
                P,
                mu,
                m.time,
                m.time,
                m.time,
                classes[cls].detection_frequency,
                class_probs,
                frozenset((m.source or "",)),
            )
            result.append(
                DetectionOptions(
                    measurement=m,
                    clutter_rate=m.clutter_rate,
                    log_clutter=_log(m.clutter_rate)
                    + (self.clutter_log_density[m.detector] if self.model == "mht" else 0.0),
                    new_track=new_track,
                    new_rate=base_rate,
                    new_log=base_log,
                    presence=presence,
                    existing=existing[j],
                )
            )
        return result

    def _settled(
        self,
        measurements: Sequence[Measurement],
        existing: Sequence[Mapping[int, tuple[Track, float, float]]],
        settle: Mapping[int, float],
        log_ratio: float,
    ) -> dict[int, SettledUpdate]:
        """The detections (by row) that certainly update one object: see
        :class:`SettledUpdate`. The weights are compared exactly as
        ``MultipleHypothesisFilter._certain_update`` compares them."""
        if not settle or self.model != "mht":
            return {}
        classes = self.knowledge.classes
        if any(m.label is not None or classes[m.cls].appearance for m in measurements):
            return {}
        gated: dict[int, int] = {}
        for found in existing:
            for key in found:
                gated[key] = gated.get(key, 0) + 1
        spread_uniform = -self.log_volume
        result: dict[int, SettledUpdate] = {}
        for j, (m, found) in enumerate(zip(measurements, existing, strict=True)):
            if len(found) != 1:
                continue
            ((old_key, (updated, log_num, _)),) = found.items()
            log_norm = settle.get(old_key)
            if log_norm is None or gated[old_key] != 1:
                continue
            log_update = log_norm + log_num
            if log_update == -math.inf:
                continue
            log_clutter = _log(m.clutter_rate) + self.clutter_log_density[m.detector]
            new_log = _log(classes[m.cls].new_frequency) + spread_uniform
            if log_norm + log_add(log_clutter, new_log) >= log_update + log_ratio - TIE:
                continue  # "new object or clutter" survives eq. (3): the general path
            result[j] = SettledUpdate(m, old_key, updated)
        return result

    def _new_states(
        self, measurements: Sequence[Measurement]
    ) -> list[tuple[FloatArray, FloatArray, FloatArray]]:
        """Initial filter states of the objects each detection would start, one batched call
        per class."""
        by_class: dict[str, list[int]] = {}
        for j, m in enumerate(measurements):
            by_class.setdefault(m.cls, []).append(j)
        states: dict[int, tuple[FloatArray, FloatArray, FloatArray]] = {}
        for cls, rows in by_class.items():
            z = np.array([measurements[j].z for j in rows])
            x, P, mu = self.factory.filter_for(cls).initial_states(z)
            for row, j in enumerate(rows):
                states[j] = (x[row], P[row], mu[row])
        return [states[j] for j in range(len(measurements))]

    def _class_likelihoods(
        self, tracks: Sequence[Track], measurements: Sequence[Measurement]
    ) -> FloatArray:
        """L_class for every (detection, object) pair, ``(D, T)``.

        ``paper``: eq. (8), 0/1 from the taxonomy, once per pair of distinct classes.
        ``mht``: ``sum_c p_o(c) L(C(z) | c)`` from each object's class distribution and
        the detection's detector (:mod:`semwm.mhf.classes`).
        """
        if self.model == "mht":
            mixed = in_order_product(self._reported(measurements), self._class_probs(tracks))
            return mixed
        track_classes = sorted({t.cls for t in tracks})
        detection_classes = sorted({m.cls for m in measurements})
        table = np.array(
            [
                [self.taxonomy.class_likelihood(tc, dc) for tc in track_classes]
                for dc in detection_classes
            ]
        )
        t_index = {c: i for i, c in enumerate(track_classes)}
        d_index = {c: i for i, c in enumerate(detection_classes)}
        rows = np.fromiter((d_index[m.cls] for m in measurements), dtype=np.intp)
        cols = np.fromiter((t_index[t.cls] for t in tracks), dtype=np.intp)
        result: FloatArray = table[rows[:, None], cols[None, :]]
        return result

    def _class_probs(self, tracks: Sequence[Track]) -> FloatArray:
        """``(T, K)``: each object's class distribution."""
        return np.array([t.class_probs for t in tracks])

    def _reported(self, measurements: Sequence[Measurement]) -> FloatArray:
        """``(D, K)``: ``L(C(z) | c)`` of each detection for every class ``c``."""
        return np.array([self.class_model.likelihood(m.detector, m.cls) for m in measurements])

    def _label_pairs(
        self, predicted: Predicted, measurements: Sequence[Measurement], diff: FloatArray
    ) -> BoolArray:
        """``(D, T)``: the object holds the detection's label and is within ``label_gate``
        (paper 000: a robot's own report decides which object it is)."""
        tracks = predicted.tracks
        same = np.zeros((len(measurements), len(tracks)), dtype=bool)
        labels = {m.label for m in measurements if m.label is not None}
        if not labels:
            return same
        holding = [i for i, t in enumerate(tracks) if t.label in labels]
        if not holding:
            return same
        for j, m in enumerate(measurements):
            if m.label is not None:
                for i in holding:
                    same[j, i] = tracks[i].label == m.label
        close: BoolArray = (diff * diff).sum(-1) <= self.label_gate**2
        result: BoolArray = same & close
        return result

    def _existing(
        self,
        predicted: Predicted,
        measurements: Sequence[Measurement],
        new_key: Callable[[], int],
        existence: Sequence[float] = (),
        detection_rates: Mapping[str, FloatArray] | None = None,
    ) -> list[dict[int, tuple[Track, float, float]]]:
        """Gate every (detection, object) pair and update the pairs that pass."""
        tracks = predicted.tracks
        found: list[dict[int, tuple[Track, float, float]]] = [{} for _ in measurements]
        if not tracks or not measurements:
            return found
        mht = self.model == "mht"
        z = np.array([m.z for m in measurements])  # (D, d)
        R = np.array([m.R for m in measurements])  # (D, d, d)
        if mht:  # L_class from the class distributions (semwm.mhf.classes)
            probs, reported = self._class_probs(tracks), self._reported(measurements)
            likelihood: FloatArray = in_order_product(reported, probs)  # (D, T)
        else:
            likelihood = self._class_likelihoods(tracks, measurements)  # (D, T): eq. (8)
        sparse = self._sparse_gate(predicted, measurements, z, R, likelihood)
        if sparse is not None:  # many pairs, no labels: a k-d tree finds the near ones
            jj, ii, pair_diff = sparse
            labelled = None
            diff = pair_diff  # only _label_robust reads the dense one (labels: dense path)
        else:
            diff = z[:, None, :] - predicted.position[None, :, :]  # (D, T, d)
            labelled = self._label_pairs(predicted, measurements, diff) if mht else None
            candidate = likelihood > 0.0
            if math.isfinite(self.gate):
                # Cheap bound first: d^2 <= gate * lambda_max(S) <= gate * trace(S).
                bound = self.gate * (
                    np.trace(predicted.position_covariance, axis1=1, axis2=2)[None, :]
                    + np.trace(R, axis1=1, axis2=2)[:, None]
                )
                if any(m.time_std > 0.0 for m in measurements):
                    # trace(sigma_t^2 v v^T) = sigma_t^2 |v|^2
                    time_var = np.array([m.time_std * m.time_std for m in measurements])
                    speed2 = (predicted.velocity(self.dim) ** 2).sum(-1)
                    bound = bound + self.gate * time_var[:, None] * speed2[None, :]
                candidate &= (diff * diff).sum(-1) <= bound
                if labelled is not None:
                    candidate |= labelled & (likelihood > 0.0)
            jj, ii = np.nonzero(candidate)
            pair_diff = diff[jj, ii]
        if jj.size == 0:
            return found
        R_pair = R[jj] + self._timing_noise(predicted, measurements, jj, ii)
        S = predicted.position_covariance[ii] + R_pair
        d2 = self.factory.mahalanobis_squared(pair_diff, S)
        passed = d2 <= self.gate
        if labelled is not None:
            passed |= labelled[jj, ii]
        jj, ii, R_pair = jj[passed], ii[passed], R_pair[passed]
        if mht:  # Bayes over the class distribution (semwm.mhf.classes), every pair at once
            posteriors = probs[ii] * reported[jj]
            posteriors /= posteriors.sum(axis=1, keepdims=True)
            names = self.class_model.names
            refined_all = [names[k] for k in self.class_model.published_many(posteriors)]
        # one update per filter shape: the Kalman / IMM update is the same for every
        # class of one shape (the class only decides the prediction)
        by_shape: dict[tuple[int, int], list[int]] = {}
        for p, i in enumerate(ii.tolist()):
            by_shape.setdefault(predicted.shape(i), []).append(p)
        classes = self.knowledge.classes
        d = self.dim
        label_error = self.log_label_error
        for pairs_list in by_shape.values():
            pairs = np.asarray(pairs_list)
            rows_i = ii[pairs]
            rows_j = jj[pairs]
            R_rows = R_pair[pairs]
            x, P, mu = predicted.stacked(rows_i)
            x_new, P_new, mu_new, log_lik = self.factory.update(x, P, mu, z[rows_j], R_rows)
            if self.model == "paper":
                x_hat, _ = self.factory.combine(x_new, P_new, mu_new)
                delta = z[rows_j] - x_hat[:, :d]
                log_lik = -0.5 * self.factory.mahalanobis_squared(delta, R_rows)
            elif labelled is not None and labelled[rows_j, rows_i].any():
                log_lik = self._label_robust(
                    log_lik, labelled[rows_j, rows_i], diff, rows_j, rows_i, predicted, R_rows
                )
            # one conversion per batch, not one numpy scalar per pair
            pair_likelihood = likelihood[rows_j, rows_i].tolist()
            pair_log_lik = log_lik.tolist()
            states = zip(list(x_new), list(P_new), list(mu_new), strict=True)
            for p, i, j, (xs, Ps, mus), lik, log_l in zip(
                pairs_list,
                rows_i.tolist(),
                rows_j.tolist(),
                states,
                pair_likelihood,
                pair_log_lik,
                strict=True,
            ):
                old = tracks[i]
                m = measurements[j]
                if mht:
                    class_probs, refined = posteriors[p], refined_all[p]
                else:  # eq. (8): the more specific of two compatible classes
                    refined = self.taxonomy.most_specific(old.cls, m.cls)
                    class_probs = self.class_model.point(refined)
                if refined != old.cls:
                    target = self.factory.filter_for(refined)
                    xs, Ps, mus = conform(xs, Ps, mus, None, target)
                rate = classes[refined].detection_frequency
                updated = Track(
                    new_key(),
                    old.lineage,
                    refined,
                    m.label if m.label is not None else old.label,
                    xs,
                    Ps,
                    mus,
                    m.time,
                    m.time,
                    old.created,
                    rate,
                    class_probs,
                    old.sources
                    if (m.source or "") in old.sources
                    else old.sources | {m.source or ""},
                )
                f_existing = old.rate if detection_rates is None else detection_rates[m.detector][i]
                log_num = _log(f_existing) + math.log(lik) + log_l
                if mht:
                    log_num += _log(existence[i]) if existence else 0.0
                    if m.label is not None and old.label not in (None, m.label):
                        log_num += label_error
                found[j][old.key] = (updated, log_num, rate - old.rate)
        return found

    def _sparse_gate(
        self,
        predicted: Predicted,
        measurements: Sequence[Measurement],
        z: FloatArray,
        R: FloatArray,
        likelihood: FloatArray,
    ) -> tuple[IndexArray, IndexArray, FloatArray] | None:
        """The pairs that pass the cheap gate bound, and their differences, found with a
        k-d tree (:mod:`semwm.mhf.nearby`): the same pairs in the same order as the
        dense test, without its ``(D, T, d)`` arrays. ``None`` (use the dense test) for
        few pairs, labelled detections, no gate, or non-finite values."""
        if (
            z.shape[0] * len(predicted.tracks) <= nearby.DENSE_PAIRS
            or not math.isfinite(self.gate)
            or any(m.label is not None for m in measurements)
        ):
            return None
        position = predicted.position
        trace_P = np.trace(predicted.position_covariance, axis1=1, axis2=2)
        trace_R = np.trace(R, axis1=1, axis2=2)
        time_var = np.array([m.time_std * m.time_std for m in measurements])
        moving = bool(np.any(time_var > 0.0))
        speed2 = (predicted.velocity(self.dim) ** 2).sum(-1) if moving else None
        reach = trace_P + trace_R.max()
        if speed2 is not None:
            reach = reach + time_var.max() * speed2
        if not nearby.usable(z, position, reach):
            return None
        jj, ii = nearby.within(z, position, np.sqrt(self.gate * reach))
        # the dense test's bound, element for element
        bound = self.gate * (trace_P[ii] + trace_R[jj])
        if speed2 is not None:
            bound = bound + self.gate * time_var[jj] * speed2[ii]
        pair_diff = z[jj] - position[ii]
        keep = (likelihood[jj, ii] > 0.0) & ((pair_diff * pair_diff).sum(-1) <= bound)
        return jj[keep], ii[keep], pair_diff[keep]

    def _timing_noise(
        self,
        predicted: Predicted,
        measurements: Sequence[Measurement],
        jj: IndexArray,
        ii: IndexArray,
    ) -> FloatArray | float:
        r"""Measurement noise from an uncertain time stamp, per (detection, object) pair.

        A detection stamped with standard uncertainty :math:`\sigma_t` (``time_std``:
        a synced source's clock offset) of an object moving at :math:`v` is off by
        :math:`v\,\delta t` with :math:`\delta t \sim N(0, \sigma_t^2)`, to first order:

        .. math:: R' = R + \sigma_t^2\, v v^\top

        ``0.0`` when no detection has a time uncertainty.
        """
        if not any(m.time_std > 0.0 for m in measurements):
            return 0.0
        sigma2 = np.array([m.time_std * m.time_std for m in measurements])
        v = predicted.velocity(self.dim)[ii]
        noise: FloatArray = sigma2[jj][:, None, None] * v[:, :, None] * v[:, None, :]
        return noise

    def _label_robust(
        self,
        log_lik: FloatArray,
        labelled: BoolArray,
        diff: FloatArray,
        rows_j: IndexArray,
        rows_i: IndexArray,
        predicted: Predicted,
        R_rows: FloatArray,
    ) -> FloatArray:
        """For a detection and the object holding its label: the likelihood mixed with a
        wide component (standard deviation ``label_gate / 3`` per axis), so that a
        robot's own precise report far from its lagging estimate still fits it.
        ``R_rows``: each pair's measurement noise."""
        d = self.dim
        wide_var = (self.label_gate / 3.0) ** 2
        S_wide = predicted.position_covariance[rows_i] + R_rows + wide_var * np.eye(d)
        delta = diff[rows_j, rows_i]
        S_inv, log_det = inverse_and_log_det(S_wide)
        log_wide = -0.5 * (quadratic_form(delta, S_inv) + log_det + d * math.log(2.0 * math.pi))
        mixed = np.logaddexp(log_lik + math.log(0.9), log_wide + math.log(0.1))
        result: FloatArray = np.where(labelled, mixed, log_lik)
        return result


def _distance(z: FloatArray, position: Sequence[float]) -> float:
    offset = z - np.asarray(position, dtype=float)
    return math.sqrt(float(offset @ offset))  # what np.linalg.norm computes


def _with_source(sources: frozenset[str], source: str) -> frozenset[str]:
    """``sources`` and ``source`` (the same set when it holds it: no new set per update)."""
    return sources if source in sources else sources | {source}
