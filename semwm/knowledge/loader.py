"""Loading knowledge files (XML or YAML) with every problem located at its line.

A file is read by its format's reader into plain data and a line map (field
path -> line), validated into a :class:`KnowledgeDocument` by pydantic, then
resolved (:func:`semwm.knowledge.resolve.resolve`). Every problem of each stage
is collected, given the line of the longest prefix of its field path that the
file wrote, and reported together.

Examples
--------
>>> knowledge = load_knowledge("knowledge/sim1.yaml")  # doctest: +SKIP
>>> for problem in check_file("my_classes.xml"):  # doctest: +SKIP
...     print(problem)  # my_classes.xml:12: class 'Cup' is-a unknown class 'Mug'; ...
"""

from __future__ import annotations

import contextlib
import os
import tempfile
import types
import typing
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path as FilePath
from typing import Any, Literal

from pydantic import BaseModel, ValidationError
from pydantic_core import ErrorDetails

from semwm.knowledge.advice import advice
from semwm.knowledge.model import Knowledge, KnowledgeDocument
from semwm.knowledge.problems import KnowledgeError, Path, Problem
from semwm.knowledge.resolve import resolve
from semwm.knowledge.xml_format import document_to_xml, read_xml
from semwm.knowledge.yaml_format import document_to_yaml, read_yaml

Format = Literal["xml", "yaml"]
LineMap = Mapping[Path, int]

_READERS: dict[str, Callable[[str | bytes], tuple[dict[str, Any] | None, Any, list[Problem]]]] = {
    "xml": read_xml,
    "yaml": read_yaml,
}
_WRITERS: dict[str, Callable[[KnowledgeDocument], str]] = {
    "xml": document_to_xml,
    "yaml": document_to_yaml,
}
_EXTENSIONS: dict[str, Format] = {".xml": "xml", ".yaml": "yaml", ".yml": "yaml"}


class UnknownFormatError(ValueError):
    """A file name whose extension names no knowledge format."""


def format_of(path: str | FilePath) -> Format:
    """The format a file name's extension names.

    Raises
    ------
    UnknownFormatError
        For any extension but ``.xml``, ``.yaml`` and ``.yml``.
    """
    suffix = FilePath(path).suffix.lower()
    if suffix not in _EXTENSIONS:
        raise UnknownFormatError(
            f"{path}: unknown knowledge file extension {suffix or '(none)'!r}; "
            f"expected one of {', '.join(_EXTENSIONS)}"
        )
    return _EXTENSIONS[suffix]


@dataclass(frozen=True)
class Analysis:
    """Everything learnt from one text: its problems, and what could be built."""

    problems: tuple[Problem, ...]
    document: KnowledgeDocument | None
    knowledge: Knowledge | None
    warnings: tuple[Problem, ...] = ()
    """Usable knowledge that will likely not do what its author wants
    (:func:`semwm.knowledge.advice.advice`), located."""


def line_of(path: Path, lines: LineMap) -> int | None:
    """The line of the longest prefix of ``path`` the file wrote (``None`` if none did)."""
    for length in range(len(path), -1, -1):
        line = lines.get(path[:length])
        if line is not None:
            return line
    return None


# -- pydantic errors as problems -------------------------------------------------------------


def _field_path(loc: tuple[str | int, ...]) -> Path:
    """Pydantic's location without the discriminated-union tag (``filter.kalman.model``)."""
    path: list[str | int] = []
    for index, segment in enumerate(loc):
        after_filter = index >= 3 and loc[index - 1] == "filter" and loc[index - 3] == "classes"
        if after_filter and segment in ("kalman", "imm"):
            continue
        path.append(segment)
    return tuple(path)


def _unwrap(annotation: Any) -> list[Any]:
    """The alternatives an annotation admits, without ``Annotated`` and ``None``."""
    while typing.get_origin(annotation) is typing.Annotated:
        annotation = typing.get_args(annotation)[0]
    if typing.get_origin(annotation) in (typing.Union, types.UnionType):
        return [alt for arg in typing.get_args(annotation) for alt in _unwrap(arg)]
    return [] if annotation is type(None) else [annotation]


def _model_field(model: type[BaseModel], name: str) -> Any:
    for field_name, field in model.model_fields.items():
        if name in (field_name, field.alias):
            return field.annotation
    return None


def _step(annotations: list[Any], segment: str | int) -> list[Any]:
    following: list[Any] = []
    for annotation in annotations:
        origin = typing.get_origin(annotation)
        if isinstance(annotation, type) and issubclass(annotation, BaseModel):
            if isinstance(segment, str):
                tag = annotation.model_fields.get("type")
                if tag is not None and tag.default == segment:  # a discriminated-union tag
                    following.append(annotation)
                elif (found := _model_field(annotation, segment)) is not None:
                    following += _unwrap(found)
        elif origin in (tuple, list) and isinstance(segment, int):
            following += _unwrap(typing.get_args(annotation)[0])
        elif origin in (dict, Mapping, typing.Mapping) and isinstance(segment, str):
            following += _unwrap(typing.get_args(annotation)[1])
    return following


def expected_keys(loc: Sequence[str | int]) -> list[str]:
    """The keys the model allows in the mapping at ``loc`` (pydantic's raw location)."""
    annotations: list[Any] = [KnowledgeDocument]
    for segment in loc:
        annotations = _step(annotations, segment)
    keys: list[str] = []
    for annotation in annotations:
        if isinstance(annotation, type) and issubclass(annotation, BaseModel):
            keys += [field.alias or name for name, field in annotation.model_fields.items()]
    return keys


def _found(value: Any) -> str:
    if isinstance(value, str):
        try:
            float(value)
        except ValueError:
            return repr(value)
        return value
    if isinstance(value, Mapping):
        return "a mapping"
    if isinstance(value, list | tuple):
        return f"a list of {len(value)}"
    return repr(value)


def _describe(error: ErrorDetails) -> str:
    """What was expected and what was found, in words people use."""
    kind = error["type"]
    context: dict[str, Any] = dict(error.get("ctx") or {})
    found = _found(error.get("input"))
    loc = error["loc"]
    bounds = {
        "greater_than_equal": (">=", "ge"),
        "greater_than": (">", "gt"),
        "less_than_equal": ("<=", "le"),
        "less_than": ("<", "lt"),
    }
    if kind in bounds:
        symbol, key = bounds[kind]
        return f"expected a number {symbol} {context[key]:g}, found {found}"
    if kind == "missing":
        return f"missing required value {loc[-1]!r}"
    if kind == "extra_forbidden":
        keys = expected_keys(loc[:-1])
        expected = f"; expected one of {', '.join(keys)}" if keys else ""
        return f"unknown key {loc[-1]!r}{expected}"
    if kind in ("float_parsing", "float_type", "int_parsing", "int_type", "int_from_float"):
        number = "an integer" if kind.startswith("int") else "a number"
        return f"expected {number}, found {found}"
    if kind == "finite_number":
        return f"expected a finite number, found {found}"
    if kind == "literal_error":
        return f"expected {context['expected']}, found {found}"
    if kind == "union_tag_invalid":
        expected = " or ".join(context["expected_tags"].split(", "))
        key = context["discriminator"].strip("'")
        return f"expected {key} {expected}, found {context['tag']!r}"
    if kind == "union_tag_not_found":
        return f"missing required value {context['discriminator']}"
    if kind == "too_short":
        return (
            f"expected at least {context['min_length']} item(s), found {context['actual_length']}"
        )
    if kind in ("tuple_type", "list_type"):
        return f"expected a list, found {found}"
    if kind in ("model_type", "dict_type", "model_attributes_type"):
        return f"expected a mapping, found {found}"
    if kind == "string_type":
        return f"expected text, found {found}"
    return f"{error['msg'][0].lower()}{error['msg'][1:]}, found {found}"


def _is_consequence(error: ErrorDetails) -> bool:
    """A ``too_short`` that only says an item failed (the items' own errors say why)."""
    given = error.get("input")
    minimum = (error.get("ctx") or {}).get("min_length", 0)
    return error["type"] == "too_short" and isinstance(given, list) and len(given) >= minimum


def validation_problems(error: ValidationError, reported: Sequence[Path] = ()) -> list[Problem]:
    """Problems for pydantic's errors, skipping those at or under a path already ``reported``."""
    problems = []
    for detail in error.errors():
        path = _field_path(detail["loc"])
        if detail["type"] in ("union_tag_invalid", "union_tag_not_found"):
            path = (*path, str((detail.get("ctx") or {})["discriminator"]).strip("'"))
        if _is_consequence(detail) or any(path[: len(r)] == r for r in reported):
            continue
        problems.append(Problem(_describe(detail), path))
    return problems


# -- the pipeline ------------------------------------------------------------------------------


def analyse_text(content: str | bytes, fmt: Format, source: str | None = None) -> Analysis:
    """Read, validate and resolve ``content``, collecting every problem, located.

    Parameters
    ----------
    content
        The file's text (bytes are fine for XML, which may declare its encoding).
    fmt
        ``"xml"`` or ``"yaml"``.
    source
        The file name problems name.
    """
    data, lines, problems = _READERS[fmt](content)
    document: KnowledgeDocument | None = None
    knowledge: Knowledge | None = None
    if data is not None:
        try:
            document = KnowledgeDocument.model_validate(data)
        except ValidationError as error:
            problems += validation_problems(error, [p.path for p in problems])
    if document is not None:
        try:
            knowledge = resolve(document, source)
        except KnowledgeError as error:
            problems += error.problems
    located = [
        p.located(source, p.line if p.line is not None else line_of(p.path, lines))
        for p in problems
    ]
    located.sort(key=lambda p: p.line or 0)
    warnings: list[Problem] = []
    if knowledge is not None and not located:
        warnings = [p.located(source, line_of(p.path, lines)) for p in advice(knowledge)]
        warnings.sort(key=lambda p: p.line or 0)
    return Analysis(tuple(located), document, knowledge if not located else None, tuple(warnings))


def analyse_file(path: str | FilePath) -> Analysis:
    """Read, validate and resolve a knowledge file (see :func:`analyse_text`)."""
    fmt = format_of(path)
    content = FilePath(path).read_bytes()
    if fmt == "xml":
        return analyse_text(content, fmt, str(path))
    try:
        text = content.decode("utf-8")
    except UnicodeDecodeError as error:
        line = content[: error.start].count(b"\n") + 1
        byte = content[error.start : error.start + 1].hex()
        problem = Problem(f"the file is not UTF-8 text: byte 0x{byte} cannot be decoded", ())
        return Analysis((problem.located(str(path), line),), None, None)
    return analyse_text(text, fmt, str(path))


def check_file(path: str | FilePath) -> list[Problem]:
    """Every problem in a knowledge file, located; empty when it is usable.

    Raises only when the file cannot be read (``OSError``) or its extension names no
    format (:class:`UnknownFormatError`), never for its content.
    """
    return list(analyse_file(path).problems)


def load_document(path: str | FilePath) -> KnowledgeDocument:
    """The document a knowledge file writes, with its form checked but not resolved.

    Raises
    ------
    KnowledgeError
        When the file is malformed or does not fit the model (each problem located).
    """
    analysis = analyse_file(path)
    if analysis.document is None:
        raise KnowledgeError(analysis.problems)
    return analysis.document


def load_knowledge(path: str | FilePath) -> Knowledge:
    """Load, check and resolve a knowledge file (``.xml``, ``.yaml`` or ``.yml``).

    Raises
    ------
    KnowledgeError
        With every problem found, each as ``FILE:LINE: message``.
    UnknownFormatError
        When the extension names no format.
    """
    analysis = analyse_file(path)
    if analysis.knowledge is None:
        raise KnowledgeError(analysis.problems)
    return analysis.knowledge


def knowledge_from_text(content: str | bytes, fmt: Format, source: str | None = None) -> Knowledge:
    """Like :func:`load_knowledge`, for text in hand (``source`` names it in problems)."""
    analysis = analyse_text(content, fmt, source)
    if analysis.knowledge is None:
        raise KnowledgeError(analysis.problems)
    return analysis.knowledge


def document_to_text(document: KnowledgeDocument, fmt: Format) -> str:
    """The text of ``document`` in ``fmt``; reading it back gives an equal document."""
    return _WRITERS[fmt](document)


def dump_document(document: KnowledgeDocument, path: str | FilePath) -> None:
    """Write ``document`` to ``path`` in the format its extension names, atomically.

    The text goes to a temporary file beside ``path``, flushed to disk, then renamed
    over it: a reader sees the old file or the new one, never half of one, and a
    failure (``OSError``) leaves the old file as it was.
    """
    target = FilePath(path)
    text = document_to_text(document, format_of(target))
    descriptor, temporary = tempfile.mkstemp(
        prefix=f".{target.name}.", suffix=".tmp", dir=target.parent
    )
    try:
        with os.fdopen(descriptor, "w", encoding="utf-8") as stream:
            stream.write(text)
            stream.flush()
            os.fsync(stream.fileno())
        if target.exists():
            os.chmod(temporary, target.stat().st_mode & 0o7777)
        os.replace(temporary, target)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(temporary)
        raise
