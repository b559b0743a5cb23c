"""Existence of objects in continuous time (the ``mht`` association model).

Each object version carries an existence probability ``r`` (a Bernoulli track, as
in JIPDA and PMBM trackers). Between detections two things can happen to an
object that exists: it leaves (rate :math:`\\mu`, Hz: the class's
``leave_frequency``, or a disappearance relation's rate near its target), or it
is detected (rate :math:`f`, Hz: the class's ``detection_frequency``, while it is
inside the region). Over an interval :math:`\\Delta` with no detection of it, with
constant rates:

.. math::
   P(\\text{exists at } t+\\Delta, \\text{no detection}) = r\\, e^{-(\\mu+f)\\Delta}

   q = P(\\text{no detection}) = (1 - r) + r\\Big(e^{-(\\mu+f)\\Delta}
       + \\tfrac{\\mu}{\\mu+f}\\big(1 - e^{-(\\mu+f)\\Delta}\\big)\\Big)

   r' = r\\, e^{-(\\mu+f)\\Delta} / q

``q`` multiplies the weight of every hypothesis holding the version (the
missed-detection likelihood, the continuous-time form of PMBM's ``1 - r P_D``),
and ``r'`` is the version's new existence. Over consecutive intervals the ``q``
multiply to the ``q`` of the whole interval, so the update is exact whatever the
scan times are. An object with ``r = 1`` that goes unseen where it would be seen
loses existence (the ``mu/(mu+f)`` term: it may have left), so lone tracks that
nothing confirms are removed, with no competitor needed.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Collection, Mapping, Sequence
from typing import TYPE_CHECKING

import numpy as np
from scipy.special import chdtri, ndtr

from semwm.filters.motion import FloatArray
from semwm.mhf.measurement import SensorView

if TYPE_CHECKING:
    from semwm.knowledge.model import Knowledge
    from semwm.mhf.kernels import ExistenceKernels
    from semwm.mhf.predict import Predicted

Region = tuple[tuple[float, float], ...]


def survive(
    r: FloatArray, mu: FloatArray, f: FloatArray, dt: float
) -> tuple[FloatArray, FloatArray]:
    """Existence after ``dt`` seconds with no detection, and ``log q``.

    Parameters
    ----------
    r, mu, f
        ``(N,)`` existence probabilities, leave rates and detection rates (Hz).
    dt
        Elapsed time (s), ``>= 0``.

    Returns
    -------
    r_new, log_q
        ``(N,)`` each; see the module docstring for the equations.
    """
    total = mu + f
    stay = np.exp(-total * dt)  # P(still there and not detected | exists)
    with np.errstate(invalid="ignore", divide="ignore"):
        left = np.where(total > 0.0, mu / np.where(total > 0.0, total, 1.0), 0.0) * (1.0 - stay)
    q = (1.0 - r) + r * (stay + left)
    q = np.maximum(q, 1e-300)
    r_new = np.minimum(np.maximum(r * stay / q, 0.0), 1.0)  # np.clip, without its wrappers
    return r_new, np.log(q)


def inside_probability(
    position: FloatArray,
    covariance: FloatArray,
    region: Region | None,
    margin: FloatArray | None = None,
) -> FloatArray:
    r"""Probability that each object lies inside ``region`` (axis-aligned box), from its
    Gaussian position estimate, per axis independently (the marginals).

    ``position`` ``(N, d)``, ``covariance`` ``(N, d, d)``; all ones without a region.

    ``margin`` ``(N, d)`` (m): the region is a soft fact. It is where the robot works,
    drawn on a floor plan; an object on its edge (a table top at the region's floor,
    a shelf on its wall) is reported half outside by a sensor with noise, and its
    estimate's spread says nothing about which side it stands on. Each axis's bounds
    are widened by the object's class's measurement noise at the gate's quantile
    (:func:`region_margins`), so an object within the noise of the edge counts as
    inside and only what is clearly outside is out:

    .. math::
       P(\text{inside}) = \prod_i \Phi\Big(\frac{b_i + m_i - x_i}{\sigma_i}\Big)
                        - \Phi\Big(\frac{a_i - m_i - x_i}{\sigma_i}\Big)
    """
    count = position.shape[0]
    if region is None or count == 0:
        return np.ones(count)
    corners = _corners(region)  # (2, d): upper, lower
    sigma = np.sqrt(np.maximum(covariance.diagonal(axis1=1, axis2=2), 1e-18))
    if margin is not None:  # (N, 2, d): upper + m, lower - m
        bounds = corners[None, :, :] + np.stack((margin, -margin), axis=1)
    else:
        bounds = corners[None, :, :]
    # one normal CDF call for both corners: (N, 2, d)
    below = ndtr((bounds - position[:, None, :]) / sigma[:, None, :])
    per_axis = below[:, 0] - below[:, 1]  # in [0, 1]: the CDF is monotone
    result: FloatArray = np.minimum(np.maximum(per_axis, 0.0), 1.0).prod(axis=1)
    return result


def region_margins(noise: FloatArray, gate_probability: float) -> FloatArray:
    r"""How far outside the region (m, per axis) an object still counts as on its edge:
    the measurement noise's standard deviation at the gate's one-dimensional quantile,

    .. math:: m_i = \sqrt{\gamma\, R_{ii}}, \qquad \gamma = \chi^2_1(p_{gate})

    ``noise`` ``(N, d, d)``: each object's class's measurement noise ``R``; returns
    ``(N, d)``. The same margin decides which detections are clearly outside the
    region (:func:`semwm.validation.outside_region`).
    """
    if noise.shape[0] == 0:
        return np.zeros((0, noise.shape[-1]))
    gamma = chdtri(1, 1.0 - gate_probability) if gate_probability < 1.0 else 0.0
    result: FloatArray = np.sqrt(gamma * np.maximum(noise.diagonal(axis1=1, axis2=2), 0.0))
    return result


@functools.lru_cache(maxsize=64)
def _corners(region: Region) -> FloatArray:
    """``(2, d)``: the region's upper corner, then its lower one (made once per region)."""
    low, high = _bounds(region)
    corners = np.stack((high, low))
    corners.flags.writeable = False
    return corners


@functools.lru_cache(maxsize=64)
def _bounds(region: Region) -> tuple[FloatArray, FloatArray]:
    """The region's lower and upper corners as arrays (made once per region)."""
    low = np.array([a for a, _ in region], dtype=float)
    high = np.array([b for _, b in region], dtype=float)
    low.flags.writeable = high.flags.writeable = False
    return low, high


def near_rate(
    position: FloatArray,
    base: float,
    relations: Sequence[tuple[FloatArray, float, float]],
) -> float:
    """The larger of a base rate and the rates of relations whose target is within reach.

    ``relations``: ``(target position, max_distance, rate)``. Paper 002 eq. (4) takes
    the maximum over targets for appearance; disappearance mirrors it.
    """
    rate = base
    for target, reach, value in relations:
        if value > rate:
            offset = position - target
            if math.sqrt(float(offset @ offset)) <= reach:  # what np.linalg.norm computes
                rate = value
    return rate


def log_or_minus_inf(value: float) -> float:
    return math.log(value) if value > 0.0 else -math.inf


# 7 x 7 Gauss-Hermite rule (probabilists'): points and weights for a standard normal
_GH_X, _GH_W = np.polynomial.hermite_e.hermegauss(7)
_GH_W = _GH_W / _GH_W.sum()
_GRID = np.stack(np.meshgrid(_GH_X, _GH_X, indexing="ij"), axis=-1).reshape(-1, 2)
_GRID_W = np.outer(_GH_W, _GH_W).reshape(-1)


def in_view_probability(
    position: FloatArray,
    covariance: FloatArray,
    view: SensorView,
    margin: FloatArray | None = None,
) -> FloatArray:
    """Probability that each object lies in the sensor's view (a disc sector of radius
    ``range`` and opening ``2 half_angle`` around ``heading``), from its Gaussian
    position estimate's horizontal marginal, by a 7 x 7 Gauss-Hermite rule.

    ``position`` ``(N, d)``, ``covariance`` ``(N, d, d)``; returns ``(N,)``.
    ``margin`` ``(N,)`` (m): the view eroded by each object's margin, a node counts
    only at least that far inside the range and from both edges of the opening (an
    object that stands within its noise of the view's edge may be just outside it,
    and is then never detected there, however often the sensor looks).
    """
    count = position.shape[0]
    if count == 0:
        return np.ones(0)
    mean = position[:, :2]
    cov = covariance[:, :2, :2] + 1e-12 * np.eye(2)
    L = np.linalg.cholesky(cov)  # (N, 2, 2)
    points = mean[:, None, :] + np.einsum("nij,kj->nki", L, _GRID)  # (N, K, 2)
    offset = points - view.position[None, None, :2]
    m = np.zeros((count, 1)) if margin is None else np.asarray(margin, dtype=float)[:, None]
    distance = np.linalg.norm(offset, axis=-1)
    inside = np.ones(offset.shape[:2], dtype=bool)
    if view.range is not None:
        inside &= distance <= view.range - m
    if view.half_angle is not None:
        bearing = np.arctan2(offset[..., 1], offset[..., 0]) - view.heading
        bearing = (bearing + np.pi) % (2.0 * np.pi) - np.pi
        slack = view.half_angle - np.abs(bearing)  # the angle to the nearer edge
        inside &= slack >= 0.0
        if margin is not None:  # the distance to that edge (a ray from the sensor)
            to_edge = np.where(slack >= 0.5 * np.pi, distance, distance * np.sin(slack))
            inside &= to_edge >= m
    # the weights of the nodes in view summed in node order, row by row (a matrix-vector
    # product rounds a row by its place in the batch: equal objects would differ in the
    # last bit, and hypotheses that tie exactly would not)
    result: FloatArray = np.cumsum(inside * _GRID_W, axis=1)[:, -1]
    return result


def missed(r: FloatArray, p_detect: FloatArray) -> tuple[FloatArray, FloatArray]:
    r"""Existence after a scan that could have reported each object (with probability
    ``p_detect``: P_D times the probability that it is in the view) and did not, and
    ``log q``; the missed-detection update of a Bernoulli track (PMBM):

    .. math:: q = 1 - r\,p, \qquad r' = \frac{r (1 - p)}{q}

    ``p = 0`` (outside the view) leaves ``r`` unchanged and ``q = 1``.
    """
    q = np.maximum(1.0 - r * p_detect, 1e-300)
    return np.clip(r * (1.0 - p_detect) / q, 0.0, 1.0), np.log(q)


def looked_at(
    view: SensorView,
    predicted: Predicted,
    seen: Collection[int],
    existence: Mapping[int, float],
    knowledge: Knowledge,
    kernels: ExistenceKernels | None = None,
    observed: Mapping[str, float] | None = None,
    margins: FloatArray | None = None,
) -> tuple[dict[int, float], dict[int, float]]:
    """Negative information of one scan: the existence of every predicted version after
    the scan did not report it, and the log missed-detection likelihood of each.
    ``margins`` ``(N,)`` (m): each object's margin the view is eroded by
    (:func:`in_view_probability`; a class that stands still: its region margin).

    The detection probability is state-dependent: ``P_D(class) * P(in view)``, with
    P_D the class's ``detection_probability``, or (``observed``, per class) the one the
    scan's stream is observed to have (:meth:`semwm.mhf.rates.StreamCounts.detection_probability`,
    whose prior is the class's: a datasheet's recall that the data contradicts does not
    make every miss count as more, or less, than it is)
    (:func:`in_view_probability`; 1 for objects flagged ``looking_at``), so an object
    outside the view is unchanged. Versions in ``seen`` (a detection of this scan fell
    in their gate) are left to the association: one of its children explains them.
    """
    tracks = predicted.tracks
    if not tracks:
        return {}, {}
    in_view = in_view_probability if kernels is None else kernels.in_view_probability
    update = missed if kernels is None else kernels.missed
    inside = in_view(predicted.position, predicted.position_covariance, view, margins)
    p = np.array(
        [
            0.0
            if t.key in seen
            else _detection_probability(t.cls, knowledge, observed)
            * (1.0 if t.lineage in view.looking_at else float(inside[i]))
            for i, t in enumerate(tracks)
        ]
    )
    r = np.array([existence.get(t.key, 1.0) for t in tracks])
    r_new, log_q = update(r, p)
    keys = [t.key for t in tracks]
    return dict(zip(keys, r_new.tolist(), strict=True)), dict(
        zip(keys, log_q.tolist(), strict=True)
    )


def _detection_probability(
    cls: str, knowledge: Knowledge, observed: Mapping[str, float] | None
) -> float:
    """P_D of an object of class ``cls`` for one scan: observed, else the class's."""
    if observed is not None:
        value = observed.get(cls)
        if value is not None:
            return value
    return knowledge.classes[cls].detection_probability
