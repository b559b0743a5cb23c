"""Problems found in knowledge: where (file, line, field path) and what."""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass, replace

Path = tuple[str | int, ...]


@dataclass(frozen=True)
class Problem:
    """One problem in a knowledge file.

    ``path`` is the field path in the document (``("classes", 2, "filter")``);
    ``line`` is filled in by the loader that knows where that path was written.
    """

    message: str
    path: Path = ()
    file: str | None = None
    line: int | None = None
    severity: str = "error"
    """``error`` (the knowledge cannot be used) or ``warning`` (it can, but it will
    likely not do what its author wants)."""

    def located(self, file: str | None, line: int | None) -> Problem:
        return replace(self, file=file, line=line)

    def __str__(self) -> str:
        where = self.file or "<knowledge>"
        if self.line is not None:
            where = f"{where}:{self.line}"
        field = ".".join(str(p) for p in self.path)
        suffix = f" (at {field})" if field else ""
        kind = "warning: " if self.severity == "warning" else ""
        return f"{where}: {kind}{self.message}{suffix}"


class KnowledgeError(ValueError):
    """Knowledge that cannot be used, with every problem found in it."""

    def __init__(self, problems: Sequence[Problem]) -> None:
        self.problems: tuple[Problem, ...] = tuple(problems)
        super().__init__("\n".join(str(p) for p in self.problems))

    @classmethod
    def from_problems(cls, problems: Iterable[Problem]) -> KnowledgeError:
        return cls(list(problems))
