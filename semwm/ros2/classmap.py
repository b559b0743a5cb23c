"""The class-mapping file: a detector's class ids -> the knowledge's classes.

A YAML mapping, one line per class id the detector reports::

    # class_id in results[].hypothesis: knowledge class (null: drop it)
    "47": Cup
    cup: Cup
    person: Person
    tv: null

Class ids not in the file are used as they are (a detector that already says
``Cup`` needs no line). Every class named must be one of the knowledge's.
"""

from __future__ import annotations

from pathlib import Path

import yaml

ClassMap = dict[str, str | None]
"""Class id -> knowledge class, or ``None`` to drop detections of it."""


class ClassMapError(ValueError):
    """The file cannot be used: ``FILE: message`` (with the line where known)."""


def load_class_map(path: Path, known: set[str]) -> ClassMap:
    """The mapping in ``path``, checked against the knowledge's classes ``known``."""
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as error:
        raise ClassMapError(f"{path}: {error.strerror or error}") from None
    try:
        node = yaml.compose(text)
    except yaml.YAMLError as error:
        raise ClassMapError(f"{path}: not YAML: {error}") from None
    if node is None:
        return {}
    if not isinstance(node, yaml.MappingNode):
        raise ClassMapError(
            f"{path}:{node.start_mark.line + 1}: expected a mapping of class id: class"
        )
    mapping: ClassMap = {}
    problems: list[str] = []
    for key, value in node.value:
        where = f"{path}:{key.start_mark.line + 1}"
        if not isinstance(key, yaml.ScalarNode) or not isinstance(value, yaml.ScalarNode):
            problems.append(f"{where}: expected `class_id: Class` on one line")
            continue
        target = yaml.safe_load(yaml.serialize(value))
        if target is not None and not isinstance(target, str):
            problems.append(f"{where}: {key.value!r} maps to {target!r}; expected a class name")
        elif target is not None and target not in known:
            problems.append(
                f"{where}: {key.value!r} maps to {target!r}, which the knowledge has not; "
                f"known classes: {', '.join(sorted(known))}"
            )
        else:
            mapping[str(key.value)] = target
    if problems:
        raise ClassMapError("\n".join(problems))
    return mapping
