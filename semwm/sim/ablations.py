"""Knowledge ablations: a knowledge document with one piece of knowledge taken out.

Used by ``semwm simulate --no-knowledge NAME`` and the notebooks to measure what a
piece of knowledge is worth:

* ``door-relation``: remove every class's appearance relations (paper 002 eq. 4;
  in ``sim2`` "a Person appears near a Door"), leaving the base rates;
* ``taxonomy``: remove every is-a relation, each class keeping the settings it
  inherited (paper 002 eq. 8: ``Can`` then no longer matches ``CokeCan``).
"""

from __future__ import annotations

from collections.abc import Callable

from semwm.knowledge.model import ClassSpec, KnowledgeDocument
from semwm.knowledge.resolve import resolve


def without_appearance_relations(document: KnowledgeDocument) -> KnowledgeDocument:
    """``document`` with no appearance relations: every class's new objects appear
    at its base rate (``new_frequency``) everywhere.

    Each class gets an explicit empty tuple, so none inherits a parent's relations.
    """
    classes = tuple(spec.model_copy(update={"appearance": ()}) for spec in document.classes)
    return document.model_copy(update={"classes": classes})


def without_taxonomy(document: KnowledgeDocument) -> KnowledgeDocument:
    """``document`` with no is-a relations; each class keeps every setting it
    inherited (resolved first, then written out in full)."""
    knowledge = resolve(document)
    classes = []
    for spec in document.classes:
        resolved = knowledge.classes[spec.name]
        classes.append(
            ClassSpec(
                name=spec.name,
                is_a=(),
                detection_frequency=resolved.detection_frequency,
                new_frequency=resolved.new_frequency,
                appearance=resolved.appearance,
                filter=resolved.filter,
                measurement_noise=resolved.measurement_noise,
                initial_covariance=resolved.initial_covariance,
                initial_velocity_covariance=resolved.initial_velocity_covariance,
                max_position_variance=resolved.max_position_variance,
                max_time_without_update=resolved.max_time_without_update,
                category=resolved.category,
            )
        )
    return document.model_copy(update={"classes": tuple(classes)})


ABLATIONS: dict[str, Callable[[KnowledgeDocument], KnowledgeDocument]] = {
    "door-relation": without_appearance_relations,
    "taxonomy": without_taxonomy,
}
"""Ablation name (as ``--no-knowledge`` takes it) -> document transformation."""


def ablate(document: KnowledgeDocument, names: list[str] | tuple[str, ...]) -> KnowledgeDocument:
    """``document`` with each named ablation applied in turn.

    Raises
    ------
    KeyError
        An unknown name; the message lists the known ones.
    """
    for name in names:
        if name not in ABLATIONS:
            raise KeyError(f"unknown ablation {name!r}; known: {', '.join(sorted(ABLATIONS))}")
        document = ABLATIONS[name](document)
    return document
