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

import math
from collections.abc import Sequence

import numpy as np
from scipy.special import ndtr

from semwm.filters.motion import FloatArray

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
    r_new = np.clip(r * stay / q, 0.0, 1.0)
    return r_new, np.log(q)


def inside_probability(
    position: FloatArray, covariance: FloatArray, region: Region | None
) -> FloatArray:
    """Probability that each object lies inside ``region`` (axis-aligned box), from its
    Gaussian position estimate, per axis independently (the marginals).

    ``position`` ``(N, d)``, ``covariance`` ``(N, d, d)``; all ones without a region.
    """
    count = position.shape[0]
    if region is None or count == 0:
        return np.ones(count)
    low = np.array([a for a, _ in region])
    high = np.array([b for _, b in region])
    sigma = np.sqrt(np.maximum(np.diagonal(covariance, axis1=1, axis2=2), 1e-18))
    per_axis = ndtr((high - position) / sigma) - ndtr((low - position) / sigma)
    result: FloatArray = np.prod(np.clip(per_axis, 0.0, 1.0), axis=1)
    return result


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
        if value > rate and float(np.linalg.norm(position - target)) <= reach:
            rate = value
    return rate


def log_or_minus_inf(value: float) -> float:
    return math.log(value) if value > 0.0 else -math.inf
