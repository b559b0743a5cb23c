"""The is-a taxonomy of object classes (paper 002, Section IV and Fig. 1)."""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from functools import cache


class Taxonomy:
    """An is-a graph over class names; a class may have several parents.

    Parameters
    ----------
    parents
        Class name -> its direct parents. Must be acyclic (resolution checks it).
    """

    def __init__(self, parents: Mapping[str, Iterable[str]]) -> None:
        self._parents: dict[str, tuple[str, ...]] = {k: tuple(v) for k, v in parents.items()}
        self._ancestors: dict[str, frozenset[str]] = {}
        for name in self._parents:
            self._ancestors[name] = frozenset(self._walk_up(name))
        children: dict[str, set[str]] = {name: set() for name in self._parents}
        for name, ancestors in self._ancestors.items():
            for ancestor in ancestors:
                children.setdefault(ancestor, set()).add(name)
        self._descendants = {k: frozenset(v) for k, v in children.items()}
        self.class_likelihood = cache(self._class_likelihood)

    def _walk_up(self, name: str) -> list[str]:
        seen: list[str] = []
        stack = list(self._parents.get(name, ()))
        while stack:
            parent = stack.pop()
            if parent not in seen:
                seen.append(parent)
                stack.extend(self._parents.get(parent, ()))
        return seen

    @property
    def classes(self) -> tuple[str, ...]:
        return tuple(self._parents)

    def __contains__(self, name: object) -> bool:
        return name in self._parents

    def parents(self, name: str) -> tuple[str, ...]:
        return self._parents[name]

    def ancestors(self, name: str) -> frozenset[str]:
        """Every class ``name`` is-a, directly or not, excluding itself."""
        return self._ancestors[name]

    def descendants(self, name: str) -> frozenset[str]:
        """Every class that is-a ``name``, directly or not, excluding itself."""
        return self._descendants[name]

    def is_a(self, name: str, other: str) -> bool:
        """True when ``name`` is ``other`` or one of its subclasses."""
        return name == other or other in self._ancestors[name]

    def compatible(self, first: str, second: str) -> bool:
        """True when one class is the other, or a super- or subclass of it."""
        return self.is_a(first, second) or self.is_a(second, first)

    def _class_likelihood(self, object_class: str, detection_class: str) -> float:
        """L_class(C(o), C(z)) of paper 002 eq. (8).

        .. math::
           L_{class} = 1 \\text{ if } C(o) \\text{ and } C(z)
           \\text{ are compatible, else } 0

        Kept behind this one function so that a softer confusion model (visual
        similarity, paper 002 IV-A.5) can replace it.
        """
        return 1.0 if self.compatible(object_class, detection_class) else 0.0

    def most_specific(self, first: str, second: str) -> str:
        """The more specific of two compatible classes (``Can``, ``CokeCan`` -> ``CokeCan``)."""
        if self.is_a(first, second):
            return first
        if self.is_a(second, first):
            return second
        raise ValueError(f"classes {first!r} and {second!r} are not compatible")

    def covers(self, name: str) -> frozenset[str]:
        """The classes a query for ``name`` covers: itself and its descendants."""
        return self._descendants[name] | {name}
