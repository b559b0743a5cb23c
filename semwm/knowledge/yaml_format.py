"""The YAML form of knowledge files: the model's field names, one to one.

Reading composes PyYAML's node tree (which keeps every node's position) and
builds the plain data from it, so that every key and list item gets its line in
the *line map* (field path -> 1-based line). A mapping entry is located at its
key, a list item where it starts. Validation is the loader's job
(:mod:`semwm.knowledge.loader`).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import yaml

from semwm.knowledge.model import KnowledgeDocument
from semwm.knowledge.problems import Path, Problem

LineMap = dict[Path, int]

MAX_VALUES = 100_000
"""The most values (mappings, lists, scalars) a file may expand to, aliases included.

Aliases are references: a few hundred bytes can name 10^9 values (an "alias bomb").
The largest shipped file has a few thousand; reading stops with a located problem
beyond this.
"""
MAX_DEPTH = 64
"""The deepest nesting of mappings and lists a file may have. The shipped files nest at
most 7 deep; a file nested 100,000 deep made the reader recurse past Python's limit
(issue 30), so reading stops with a located problem beyond this."""
ReadResult = tuple[dict[str, Any] | None, LineMap, list[Problem]]
"""Data for :class:`KnowledgeDocument` (``None`` when unreadable), line map, problems."""


def _line(node: yaml.Node) -> int:
    return int(node.start_mark.line) + 1


def _too_many(node: yaml.Node) -> yaml.constructor.ConstructorError:
    return yaml.constructor.ConstructorError(
        None,
        None,
        f"the document expands to more than {MAX_VALUES} values (aliases or merge keys "
        "repeat too much)",
        node.start_mark,
    )


class _LimitedLoader(yaml.SafeLoader):
    """A safe loader whose ``<<`` merges stop at :data:`MAX_VALUES` entries and whose
    nodes nest at most :data:`MAX_DEPTH` deep."""

    _depth = 0

    def compose_node(self, parent: yaml.Node | None, index: Any) -> yaml.Node | None:
        self._depth += 1
        try:
            if self._depth > MAX_DEPTH:
                raise yaml.composer.ComposerError(
                    None,
                    None,
                    f"mappings and lists nested deeper than {MAX_DEPTH} levels",
                    self.peek_event().start_mark,  # type: ignore[no-untyped-call]
                )
            return super().compose_node(parent, index)
        finally:
            self._depth -= 1

    def flatten_mapping(self, node: yaml.MappingNode) -> None:
        super().flatten_mapping(node)  # flattens merged sub-mappings through this method
        if len(node.value) > MAX_VALUES:
            raise _too_many(node)


class _Builder:
    """Python values from composed nodes, recording where each path was written.

    Counts the values built: aliases are expanded here, so an alias bomb stops at
    :data:`MAX_VALUES` with the line of the value where it did.
    """

    def __init__(self, loader: yaml.SafeLoader) -> None:
        self.loader = loader
        self.lines: LineMap = {}
        self.problems: list[Problem] = []
        self.built = 0

    def build(self, node: yaml.Node, path: Path) -> Any:
        self.built += 1
        if self.built > MAX_VALUES:
            raise _too_many(node)
        if isinstance(node, yaml.MappingNode):
            self.loader.flatten_mapping(node)  # resolves "<<" merge keys
            result: dict[Any, Any] = {}
            for key_node, value_node in node.value:
                key = self.loader.construct_object(key_node, deep=True)
                where = (*path, key if isinstance(key, str | int) else str(key))
                if key in result:
                    self.problems.append(
                        Problem(
                            f"key {key!r} given twice (first at line {self.lines[where]})",
                            where,
                            line=_line(key_node),
                        )
                    )
                    continue
                self.lines[where] = _line(key_node)
                result[key] = self.build(value_node, where)
            return result
        if isinstance(node, yaml.SequenceNode):
            items = []
            for index, item in enumerate(node.value):
                self.lines[(*path, index)] = _line(item)
                items.append(self.build(item, (*path, index)))
            return items
        return self.loader.construct_object(node, deep=True)


def read_yaml(content: str | bytes) -> ReadResult:
    """Read the YAML form.

    Returns
    -------
    data, lines, problems
        ``data`` is ``None`` when the text is not well-formed YAML or not a mapping
        at the top (then ``problems`` says so, at its line).
    """
    loader = _LimitedLoader(content)
    try:
        node = loader.get_single_node()
        if node is None:
            return None, {}, [Problem("empty YAML document; expected a mapping", (), line=1)]
        builder = _Builder(loader)
        data = builder.build(node, ())
    except yaml.MarkedYAMLError as error:
        mark = error.problem_mark or error.context_mark
        line = int(mark.line) + 1 if mark is not None else None
        parts = [part for part in (error.context, error.problem) if part]
        return None, {}, [Problem("malformed YAML: " + ", ".join(parts), (), line=line)]
    except yaml.YAMLError as error:
        return None, {}, [Problem(f"malformed YAML: {error}", ())]
    finally:
        loader.dispose()
    builder.lines[()] = _line(node)
    if not isinstance(data, dict):
        found = type(data).__name__
        return (
            None,
            {},
            [Problem(f"expected a mapping at the top; found a {found}", (), line=_line(node))],
        )
    return data, builder.lines, builder.problems


def _plain(value: Any) -> Any:
    """Tuples and mappings as lists and dicts, which ``yaml.safe_dump`` represents."""
    if isinstance(value, Mapping):
        return {key: _plain(item) for key, item in value.items()}
    if isinstance(value, tuple | list):
        return [_plain(item) for item in value]
    return value


def document_to_data(document: KnowledgeDocument) -> dict[str, Any]:
    """``document`` as plain data, leaving out what is empty or unset in the world settings."""
    data: dict[str, Any] = _plain(document.model_dump(by_alias=True, exclude_none=True))
    world = document.world
    data["world"] = {
        name: value
        for name, value in data["world"].items()
        if name in world.model_fields_set or value != type(world).model_fields[name].default
    }
    if not data["world"]:
        del data["world"]
    for spec in data["classes"]:
        if not spec["is_a"]:
            del spec["is_a"]
    for detector in data["detectors"]:
        if not detector["measurement_noise"]:
            del detector["measurement_noise"]
    if not data["known_objects"]:
        del data["known_objects"]
    return data


class _Dumper(yaml.SafeDumper):
    """Block style, except that a list of plain values (a matrix row) goes on one line."""


def _represent_list(dumper: yaml.SafeDumper, items: list[Any]) -> yaml.Node:
    flat = all(not isinstance(item, list | dict) for item in items)
    return dumper.represent_sequence("tag:yaml.org,2002:seq", items, flow_style=flat)


_Dumper.add_representer(list, _represent_list)


def document_to_yaml(document: KnowledgeDocument) -> str:
    """The YAML form of ``document``; :func:`read_yaml` reads it back to an equal document."""
    return yaml.dump(
        document_to_data(document),
        Dumper=_Dumper,
        sort_keys=False,
        default_flow_style=False,
        allow_unicode=True,
    )
