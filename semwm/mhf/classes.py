"""Class as a distribution: confusion likelihoods and the class posterior of an object.

Paper 002 eq. (8) gives a 0/1 class likelihood: 1 when the object's class and the
detection's are the same, or one is a super- or subclass of the other. That locks
an object into the class of its first detections: a CokeCan first reported twice
as a BeerCan can never be updated by a CokeCan detection again. Here an object
holds a probability over the classes it may truly be, and every detection updates
it through the detector's confusion model (Bayes):

.. math::
   p'(c) \\propto p(c) \\, L(C(z) \\mid c), \\qquad
   L_{class}(o, z) = \\sum_c p(c) \\, L(C(z) \\mid c)

with the default confusion model derived from the taxonomy:

* ``L = 1`` when the report is the true class or one of its superclasses (a
  less specific report is always consistent: eq. (8)'s compatible case);
* ``L = confusion_rate`` (per detector, default 0.05) when the report is a
  subclass of the true class (a generic object reported as a specific kind) or
  shares an ancestor with it (siblings, cousins);
* ``L = unrelated_confusion_rate`` (default 0.01) for classes with no common
  ancestor.

With ``confusion_rate = 0`` and an object whose distribution sits on one class,
:math:`L_{class}` is eq. (8) again. The published class is the most specific class
whose subtree holds more than half the probability (two equally likely siblings
publish their parent).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np
import numpy.typing as npt

from semwm.filters.motion import FloatArray
from semwm.knowledge.taxonomy import Taxonomy

PUBLISH_MASS = 0.5
"""A class is published when its subtree holds more than this probability."""

SHOWN_FLOOR = 1e-3
"""An object's ``class_probabilities`` leave out the classes below this probability
(:meth:`ClassModel.as_dict`; the Rust engine's ``Engine.world_at`` is given it)."""


def in_order_product(a: FloatArray, b: FloatArray) -> FloatArray:
    """``a @ b.T`` (``(N, K)`` and ``(M, K)`` to ``(N, M)``) with each entry summed over
    ``k`` in order. A matrix product through BLAS rounds an entry by its place in the
    batch (equal rows can differ in the last bit), and a tie between equal objects would
    then be broken by where they stand; summed in order, equal rows give equal sums."""
    result: FloatArray = np.zeros((a.shape[0], b.shape[0]))
    for k in range(a.shape[1]):
        result = result + a[:, k, None] * b[None, :, k]
    return result


class ClassModel:
    """The class space of a knowledge base and each detector's confusion likelihoods.

    Parameters
    ----------
    taxonomy
        The is-a graph.
    confusion_rates
        Detector name -> its ``(confusion_rate, unrelated_confusion_rate)``.
    can_appear
        Classes new objects may be of (a class with no births and no appearance
        relation, such as a mapped door, is never the class of a new track).
    """

    def __init__(
        self,
        taxonomy: Taxonomy,
        confusion_rates: Mapping[str, tuple[float, float]],
        can_appear: Sequence[str],
    ) -> None:
        self.taxonomy = taxonomy
        self.names: tuple[str, ...] = tuple(sorted(taxonomy.classes))
        self.index = {name: i for i, name in enumerate(self.names)}
        K = len(self.names)
        related = np.zeros((K, K), dtype=bool)
        consistent = np.zeros((K, K), dtype=bool)
        for i, true in enumerate(self.names):
            lineage_true = taxonomy.ancestors(true) | {true}
            for j, reported in enumerate(self.names):
                consistent[i, j] = taxonomy.is_a(true, reported)
                related[i, j] = bool(lineage_true & (taxonomy.ancestors(reported) | {reported}))
        self._likelihood: dict[str, FloatArray] = {}
        for detector, (rate, unrelated) in confusion_rates.items():
            table = np.where(consistent, 1.0, np.where(related, rate, unrelated))
            self._likelihood[detector] = table
        self.appear_mask = np.array([name in set(can_appear) for name in self.names], dtype=float)
        # subtree[i, j] = 1 when class j is class i or one of its descendants
        self.subtree = np.array(
            [[float(taxonomy.is_a(other, name)) for other in self.names] for name in self.names]
        )
        self.depth = np.array([len(taxonomy.ancestors(name)) for name in self.names])

    def likelihood(self, detector: str, reported: str) -> FloatArray:
        """``L(reported | c)`` for every class ``c``, shape ``(K,)``."""
        column: FloatArray = self._likelihood[detector][:, self.index[reported]]
        return column

    def initial(self, detector: str, reported: str) -> FloatArray:
        """The class distribution of a new object started by a report: uniform prior over
        the classes that can appear, times the report's likelihood."""
        weights = self.likelihood(detector, reported) * self.appear_mask
        total = float(weights.sum())
        if total <= 0.0:  # the reported class cannot appear: trust the report
            weights = np.zeros(len(self.names))
            weights[self.index[reported]] = 1.0
            return weights
        result: FloatArray = weights / total
        return result

    def published(self, probabilities: FloatArray) -> str:
        """The most specific class whose subtree holds more than :data:`PUBLISH_MASS`."""
        return self.names[int(self.published_many(probabilities[None, :])[0])]

    def published_many(self, probabilities: FloatArray) -> npt.NDArray[np.intp]:
        """:meth:`published` for ``(N, K)`` distributions, as class indices ``(N,)``.

        Among the classes holding more than half, the deepest wins, then the larger
        mass, then the first name; with none, the most probable class.
        """
        mass = in_order_product(probabilities, self.subtree)  # (N, K): each subtree's mass
        candidate = mass > PUBLISH_MASS + 1e-12
        score = np.where(candidate, self.depth[None, :] * 4.0 + mass, -np.inf)
        chosen: npt.NDArray[np.intp] = np.argmax(score, axis=1)
        none = ~candidate.any(axis=1)
        if none.any():
            chosen[none] = np.argmax(probabilities[none], axis=1)
        return chosen

    def as_dict(
        self, probabilities: FloatArray | Sequence[float], floor: float = SHOWN_FLOOR
    ) -> dict[str, float]:
        """The distribution as ``{class: probability}``, classes below ``floor`` left out."""
        names = self.names
        values = probabilities.tolist() if isinstance(probabilities, np.ndarray) else probabilities
        return {names[i]: p for i, p in enumerate(values) if p >= floor}

    def point(self, name: str) -> FloatArray:
        """A distribution sitting on one class."""
        result = np.zeros(len(self.names))
        result[self.index[name]] = 1.0
        return result
