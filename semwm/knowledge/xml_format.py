"""The XML form of knowledge files: the vocabulary of paper 002, Listing 1, extended.

Reading turns a file into the plain data a :class:`KnowledgeDocument` validates,
a *line map* (field path -> 1-based line) and the problems only the XML form can
have (unknown elements and attributes, an unknown filter type, ...). Values are
left as text where the model knows their type, so that pydantic reports a bad
number with its path; the loader (:mod:`semwm.knowledge.loader`) validates.

The vocabulary, in short (``docs/knowledge.md`` has the annotated version)::

    <knowledge>
      <world><dimension>2</dimension><region><matrix>0 4; 0 3</matrix></region></world>
      <object>
        <class>CokeCan</class> <is_a>Can</is_a>
        <detection_frequency>2.0</detection_frequency>
        <appearance_model>
          <appearance_relation target="Table" max_distance="0.5" frequency="0.1"/>
        </appearance_model>
        <filter>
          <type>Kalman filter</type> <motion_model>zeroth order</motion_model>
          <system_noise><matrix>1e-4 0; 0 1e-4</matrix></system_noise>
          <measurement_noise><matrix>0.0025 0; 0 0.0025</matrix></measurement_noise>
        </filter>
      </object>
      <detector name="camera" clutter_frequency="0.2" range="5">
        <measurement_noise class="Cup"><matrix>0.01 0; 0 0.01</matrix></measurement_noise>
      </detector>
      <known_object class="Door" name="door"><position>0.5 7.5</position></known_object>
    </knowledge>

A multiple model filter lists its motion models in one ``<motion_model>``
(``zeroth order, first order``) and gives one ``<system_noise>`` per model, in
the same order; each may say which model it belongs to with ``model="first
order"``, which is then checked against that order.
"""

from __future__ import annotations

import re
from bisect import bisect_right
from collections.abc import Callable, Mapping, Sequence
from typing import Any

from lxml import etree

from semwm.knowledge.model import (
    CATEGORY_FIELDS,
    ClassSpec,
    IMMFilterSpec,
    KalmanFilterSpec,
    KnowledgeDocument,
    Matrix,
    MotionModelSpec,
    WorldSettings,
)
from semwm.knowledge.problems import Path, Problem

LineMap = dict[Path, int]
ReadResult = tuple[dict[str, Any] | None, LineMap, list[Problem]]
"""Data for :class:`KnowledgeDocument` (``None`` when unreadable), line map, problems."""

FILTER_TYPES = {
    "kalman filter": "kalman",
    "kalman": "kalman",
    "multiple model kalman filter": "imm",
    "imm": "imm",
}
"""Accepted ``<type>`` spellings (case and ``_`` vs space ignored) -> model literal."""
MOTION_MODELS = {"zeroth order": "zeroth_order", "first order": "first_order"}
"""Accepted ``<motion_model>`` spellings (``_`` vs space ignored) -> model literal."""
_FILTER_NAMES = {"kalman": "Kalman filter", "imm": "multiple model Kalman filter"}
_MOTION_NAMES = {value: key for key, value in MOTION_MODELS.items()}

_WORLD_FIELDS = (
    "dimension",
    "pruning_ratio",
    "max_hypotheses",
    "association_model",
    "missed_detection_term",
    "observed_detection_rates",
    "merge_distance",
    "min_existence",
    "removal_existence",
    "label_gate",
    "label_error_rate",
    "id_memory",
    "gate_probability",
    "region",
    "default_detector",
)
_WORLD_TEXTS = (
    "association_model",
    "missed_detection_term",
    "observed_detection_rates",
    "default_detector",
)
_CLASS_SCALARS = (
    "detection_frequency",
    "new_frequency",
    "max_position_variance",
    "max_time_without_update",
    "leave_frequency",
    "category",
    *CATEGORY_FIELDS,
)
_CLASS_MATRICES = ("measurement_noise", "initial_covariance", "initial_velocity_covariance")
_OBJECT_CHILDREN = (
    "class",
    "is_a",
    *_CLASS_SCALARS,
    "appearance_model",
    "disappearance_model",
    "filter",
    *_CLASS_MATRICES,
)
_KALMAN_CHILDREN = ("type", "motion_model", "system_noise", "measurement_noise")
_IMM_CHILDREN = (
    *_KALMAN_CHILDREN,
    "transition_matrix",
    "initial_mode_probabilities",
    "stationary_velocity_variance",
    "transition_period",
)
_RELATION_ATTRIBUTES = ("target", "max_distance", "frequency")
_DETECTOR_ATTRIBUTES = (
    "name",
    "clutter_frequency",
    "range",
    "field_of_view",
    "confusion_rate",
    "unrelated_confusion_rate",
    "confidence",
    "static",
    "position",
)
_KNOWN_OBJECT_ATTRIBUTES = ("class", "name")
_SEPARATORS = re.compile(r"[\s,]+")


def _number_or_text(text: str) -> int | float | str:
    """``text`` as an int or float when it is one, else unchanged (pydantic reports it)."""
    for kind in (int, float):
        try:
            return kind(text)
        except ValueError:
            pass
    return text


def _source_line(element: etree._Element) -> int:
    line: Any = element.sourceline  # lxml-stubs type it loosely
    return int(line) if line else 1


def _spelling(text: str) -> str:
    return " ".join(text.replace("_", " ").lower().split())


class _Reader:
    """One pass over a parsed tree, collecting data, lines and problems."""

    def __init__(self, text: str) -> None:
        self.source = text
        self.line_starts = [0] + [m.end() for m in re.finditer("\n", text)]
        self.lines: LineMap = {}
        self.problems: list[Problem] = []

    # -- positions -------------------------------------------------------------------
    def _offset_range(self, element: etree._Element) -> tuple[int, int]:
        """Offsets of the start tag: libxml2 gives the line where the start tag *ends*."""
        end_line = _source_line(element)
        end = self.line_starts[end_line] if end_line < len(self.line_starts) else len(self.source)
        start = self.source.rfind(f"<{element.tag}", 0, end)
        return (start if start >= 0 else self.line_starts[end_line - 1]), end

    def _line_of_offset(self, offset: int) -> int:
        return bisect_right(self.line_starts, offset)

    def line(self, element: etree._Element) -> int:
        """The line where ``element``'s start tag begins."""
        return self._line_of_offset(self._offset_range(element)[0])

    def attribute_line(self, element: etree._Element, name: str) -> int:
        start, end = self._offset_range(element)
        found = re.compile(rf"\s{re.escape(name)}\s*=").search(self.source, start, end)
        return self._line_of_offset(found.start() + 1) if found else self.line(element)

    def record(self, path: Path, line: int) -> None:
        self.lines.setdefault(path, line)

    def problem(self, message: str, path: Path, line: int) -> None:
        self.problems.append(Problem(message, path, line=line))

    # -- generic shapes ----------------------------------------------------------------
    def children(
        self,
        element: etree._Element,
        allowed: Sequence[str],
        path: Path,
        repeatable: Sequence[str] = (),
    ) -> dict[str, list[etree._Element]]:
        """Child elements by tag; unknown tags and unexpected repeats are problems."""
        found: dict[str, list[etree._Element]] = {}
        for child in element:
            if not isinstance(child.tag, str):  # comments, processing instructions
                continue
            if child.tag not in allowed:
                self.problem(
                    f"unknown element <{child.tag}> in <{element.tag}>; expected one of "
                    + ", ".join(f"<{tag}>" for tag in allowed),
                    path,
                    self.line(child),
                )
                continue
            earlier = found.setdefault(child.tag, [])
            if earlier and child.tag not in repeatable:
                self.problem(
                    f"element <{child.tag}> given twice in <{element.tag}> "
                    f"(first at line {self.line(earlier[0])}); the first one is used",
                    path,
                    self.line(child),
                )
                continue
            earlier.append(child)
        return found

    def check_attributes(self, element: etree._Element, allowed: Sequence[str], path: Path) -> None:
        for name in element.attrib:
            if name not in allowed:
                expected = ", ".join(allowed) if allowed else "none"
                self.problem(
                    f"unknown attribute {name!r} on <{element.tag}>; expected: {expected}",
                    path,
                    self.attribute_line(element, str(name)),
                )

    def text(self, element: etree._Element) -> str:
        return (element.text or "").strip()

    def vector(self, element: etree._Element, path: Path) -> list[int | float | str]:
        self.record(path, self.line(element))
        return [_number_or_text(token) for token in _SEPARATORS.split(self.text(element)) if token]

    def matrix(
        self, element: etree._Element, path: Path, attributes: Sequence[str] = ()
    ) -> list[list[int | float | str]] | None:
        """``<x><matrix>a b; c d</matrix></x>``; rows on their own lines get their own line."""
        self.record(path, self.line(element))
        self.check_attributes(element, attributes, path)
        inner = [child for child in element if isinstance(child.tag, str)]
        if len(inner) != 1 or inner[0].tag != "matrix":
            found = ", ".join(f"<{child.tag}>" for child in inner) or "nothing"
            self.problem(
                f"expected one <matrix> inside <{element.tag}>; found {found}",
                path,
                self.line(element),
            )
            return None
        first_line = _source_line(inner[0])
        rows: list[list[int | float | str]] = []
        text = inner[0].text or ""
        offset = 0
        for piece in re.split(r"(;|\n)", text):
            if piece == "\n":
                offset += 1
                continue
            tokens = [token for token in _SEPARATORS.split(piece) if token]
            if piece == ";" or not tokens:
                continue
            self.record((*path, len(rows)), first_line + offset)
            rows.append([_number_or_text(token) for token in tokens])
        return rows

    # -- the vocabulary -------------------------------------------------------------------
    def knowledge(self, root: etree._Element) -> dict[str, Any]:
        self.record((), self.line(root))
        if root.tag != "knowledge":
            self.problem(
                f"expected the root element <knowledge>; found <{root.tag}>", (), self.line(root)
            )
            return {}
        self.check_attributes(root, (), ())
        parts = self.children(
            root,
            ("world", "object", "detector", "known_object"),
            (),
            ("object", "detector", "known_object"),
        )
        data: dict[str, Any] = {
            "classes": [
                self.object(e, ("classes", i)) for i, e in enumerate(parts.get("object", []))
            ],
            "detectors": [
                self.detector(e, ("detectors", i)) for i, e in enumerate(parts.get("detector", []))
            ],
        }
        self.record(
            ("classes",), self.line(parts["object"][0]) if "object" in parts else self.line(root)
        )
        self.record(
            ("detectors",),
            self.line(parts["detector"][0]) if "detector" in parts else self.line(root),
        )
        if "world" in parts:
            data["world"] = self.world(parts["world"][0])
        if "known_object" in parts:
            data["known_objects"] = [
                self.known_object(e, ("known_objects", i))
                for i, e in enumerate(parts["known_object"])
            ]
        return data

    def world(self, element: etree._Element) -> dict[str, Any]:
        path: Path = ("world",)
        self.record(path, self.line(element))
        self.check_attributes(element, (), path)
        world: dict[str, Any] = {}
        for tag, (child, *_) in self.children(element, _WORLD_FIELDS, path).items():
            if tag == "region":
                world[tag] = self.matrix(child, (*path, tag))
            else:
                self.record((*path, tag), self.line(child))
                text = self.text(child)
                world[tag] = text if tag in _WORLD_TEXTS else _number_or_text(text)
        return world

    def object(self, element: etree._Element, path: Path) -> dict[str, Any]:
        self.record(path, self.line(element))
        self.check_attributes(element, (), path)
        parts = self.children(element, _OBJECT_CHILDREN, path, ("is_a",))
        spec: dict[str, Any] = {}
        if "class" in parts:
            self.record((*path, "name"), self.line(parts["class"][0]))
            spec["name"] = self.text(parts["class"][0])
        else:
            self.problem("<object> needs a <class> naming it", path, self.line(element))
        if "is_a" in parts:
            self.record((*path, "is_a"), self.line(parts["is_a"][0]))
            spec["is_a"] = []
            for j, parent in enumerate(parts["is_a"]):
                self.record((*path, "is_a", j), self.line(parent))
                spec["is_a"].append(self.text(parent))
        for tag in _CLASS_SCALARS:
            if tag in parts:
                child = parts[tag][0]
                self.record((*path, tag), self.line(child))
                text = self.text(child)
                spec[tag] = text if tag in ("category", "trust_labels") else _number_or_text(text)
        for tag in _CLASS_MATRICES:
            if tag in parts:
                spec[tag] = self.matrix(parts[tag][0], (*path, tag))
        if "appearance_model" in parts:
            spec["appearance"] = self.appearance(
                parts["appearance_model"][0], (*path, "appearance")
            )
        if "disappearance_model" in parts:
            spec["disappearance"] = self.appearance(
                parts["disappearance_model"][0], (*path, "disappearance"), "disappearance_relation"
            )
        if "filter" in parts:
            spec["filter"] = self.filter(parts["filter"][0], (*path, "filter"), spec)
        return spec

    def appearance(
        self, element: etree._Element, path: Path, tag: str = "appearance_relation"
    ) -> list[dict[str, Any]]:
        """An appearance (or, with ``tag``, disappearance) model's relations."""
        self.record(path, self.line(element))
        relations = self.children(element, (tag,), path, (tag,))
        result = []
        for j, relation in enumerate(relations.get(tag, [])):
            where = (*path, j)
            self.record(where, self.line(relation))
            self.check_attributes(relation, _RELATION_ATTRIBUTES, where)
            values: dict[str, Any] = {}
            for name in _RELATION_ATTRIBUTES:
                if name in relation.attrib:
                    self.record((*where, name), self.attribute_line(relation, name))
                    raw = str(relation.attrib[name])
                    values[name] = raw if name == "target" else _number_or_text(raw)
            result.append(values)
        return result

    def filter(self, element: etree._Element, path: Path, spec: dict[str, Any]) -> dict[str, Any]:
        self.record(path, self.line(element))
        self.check_attributes(element, (), path)
        parts = self.children(element, _IMM_CHILDREN, path, ("system_noise",))
        if "measurement_noise" in parts:
            noise = parts["measurement_noise"][0]
            if "measurement_noise" in spec:
                self.problem(
                    "measurement noise given both in <filter> and in <object>; give it once",
                    (*path[:-1], "measurement_noise"),
                    self.line(noise),
                )
            else:
                spec["measurement_noise"] = self.matrix(noise, (*path[:-1], "measurement_noise"))
        if "type" not in parts:
            self.problem(
                "<filter> needs a <type>: 'Kalman filter' or 'multiple model Kalman filter'",
                path,
                self.line(element),
            )
            return {}
        type_element = parts["type"][0]
        self.record((*path, "type"), self.line(type_element))
        written = self.text(type_element)
        kind = FILTER_TYPES.get(_spelling(written))
        if kind is None:
            self.problem(
                f"unknown filter type {written!r}; expected 'Kalman filter' or "
                "'multiple model Kalman filter'",
                path,
                self.line(type_element),
            )
            return {"type": written}
        for tag in set(parts) - set(_KALMAN_CHILDREN if kind == "kalman" else _IMM_CHILDREN):
            self.problem(
                f"element <{tag}> only applies to a multiple model Kalman filter",
                path,
                self.line(parts[tag][0]),
            )
        if kind == "kalman":
            models = self.motion_models(parts, path, kind, element, lambda i: (*path, "model"))
            return {"type": kind} if models is None else {"type": kind, "model": models[0]}
        models = self.motion_models(parts, path, kind, element, lambda i: (*path, "models", i))
        result: dict[str, Any] = {"type": kind}
        if models is not None:
            self.record((*path, "models"), self.line(element))
            result["models"] = models
        if "transition_matrix" in parts:
            result["transition_matrix"] = self.matrix(
                parts["transition_matrix"][0], (*path, "transition_matrix")
            )
        else:
            self.problem(
                "a multiple model Kalman filter needs a <transition_matrix>",
                path,
                self.line(element),
            )
        if "initial_mode_probabilities" in parts:
            result["initial_mode_probabilities"] = self.vector(
                parts["initial_mode_probabilities"][0], (*path, "initial_mode_probabilities")
            )
        if "stationary_velocity_variance" in parts:
            child = parts["stationary_velocity_variance"][0]
            self.record((*path, "stationary_velocity_variance"), self.line(child))
            result["stationary_velocity_variance"] = _number_or_text(self.text(child))
        if "transition_period" in parts:
            child = parts["transition_period"][0]
            self.record((*path, "transition_period"), self.line(child))
            result["transition_period"] = _number_or_text(self.text(child))
        return result

    def motion_models(
        self,
        parts: Mapping[str, list[etree._Element]],
        path: Path,
        kind: str,
        element: etree._Element,
        model_path: Callable[[int], Path],
    ) -> list[dict[str, Any]] | None:
        """The motion models, model ``i`` recorded under ``model_path(i)``; None if unusable."""
        if "motion_model" not in parts or "system_noise" not in parts:
            self.problem(
                "<filter> needs a <motion_model> and a <system_noise>", path, self.line(element)
            )
            return None
        motion = parts["motion_model"][0]
        names = [name for name in self.text(motion).split(",") if name.strip()]
        orders = [MOTION_MODELS.get(_spelling(name)) for name in names]
        noises = parts["system_noise"]
        problems_before = len(self.problems)
        for name, order in zip(names, orders, strict=True):
            if order is None:
                self.problem(
                    f"unknown motion model {name.strip()!r}; expected 'zeroth order' or "
                    "'first order'",
                    path,
                    self.line(motion),
                )
        expected = 1 if kind == "kalman" else None
        if expected is not None and len(names) != expected:
            self.problem(
                f"a Kalman filter has one motion model; found {len(names)}", path, self.line(motion)
            )
        if len(noises) != len(names):
            self.problem(
                f"{len(names)} motion model(s) need as many <system_noise> elements, in the same "
                f"order; found {len(noises)}",
                path,
                self.line(noises[0]),
            )
        if len(self.problems) > problems_before:
            return None
        models = []
        for i, (order, noise) in enumerate(zip(orders, noises, strict=True)):
            where = model_path(i)
            self.record(where, self.line(noise))
            self.record((*where, "motion_model"), self.line(motion))
            stated = noise.attrib.get("model")
            if stated is not None and MOTION_MODELS.get(_spelling(str(stated))) != order:
                self.problem(
                    f"<system_noise model={str(stated)!r}> is number {i + 1}, but motion model "
                    f"number {i + 1} is {_MOTION_NAMES[str(order)]!r}",
                    where,
                    self.line(noise),
                )
            matrix = self.matrix(noise, (*where, "system_noise"), ("model",))
            models.append({"motion_model": order, "system_noise": matrix})
        return models

    def detector(self, element: etree._Element, path: Path) -> dict[str, Any]:
        self.record(path, self.line(element))
        self.check_attributes(element, _DETECTOR_ATTRIBUTES, path)
        detector: dict[str, Any] = {}
        for name in _DETECTOR_ATTRIBUTES:
            if name in element.attrib:
                self.record((*path, name), self.attribute_line(element, name))
                raw = str(element.attrib[name])
                if name == "position":  # "x y" or "x y z", like <position> elements
                    detector[name] = [_number_or_text(v) for v in _SEPARATORS.split(raw.strip())]
                else:
                    detector[name] = raw if name == "name" else _number_or_text(raw)
        parts = self.children(element, ("measurement_noise",), path, ("measurement_noise",))
        if "measurement_noise" in parts:
            noises: dict[str, Any] = {}
            self.record((*path, "measurement_noise"), self.line(parts["measurement_noise"][0]))
            for noise in parts["measurement_noise"]:
                cls = str(noise.attrib.get("class", ""))
                where = (*path, "measurement_noise", cls)
                if not cls:
                    self.problem(
                        '<measurement_noise> in a <detector> needs class="..."',
                        (*path, "measurement_noise"),
                        self.line(noise),
                    )
                    continue
                if cls in noises:
                    self.problem(
                        f"detector measurement noise for class {cls!r} given twice",
                        where,
                        self.line(noise),
                    )
                    continue
                noises[cls] = self.matrix(noise, where, ("class",))
            detector["measurement_noise"] = noises
        return detector

    def known_object(self, element: etree._Element, path: Path) -> dict[str, Any]:
        self.record(path, self.line(element))
        self.check_attributes(element, _KNOWN_OBJECT_ATTRIBUTES, path)
        known: dict[str, Any] = {}
        for name in _KNOWN_OBJECT_ATTRIBUTES:
            if name in element.attrib:
                self.record((*path, name), self.attribute_line(element, name))
                known[name] = str(element.attrib[name])
        parts = self.children(element, ("position",), path)
        if "position" in parts:
            known["position"] = self.vector(parts["position"][0], (*path, "position"))
        return known


def read_xml(content: str | bytes) -> ReadResult:
    """Read the XML form.

    Returns
    -------
    data, lines, problems
        ``data`` is ``None`` when the text is not well-formed XML (then ``problems``
        holds lxml's message at its line).
    """
    raw = content.encode("utf-8") if isinstance(content, str) else content
    parser = etree.XMLParser(resolve_entities=False, no_network=True, huge_tree=False)
    try:
        root = etree.fromstring(raw, parser)
    except etree.XMLSyntaxError as error:
        message = re.sub(r", line \d+, column \d+$", "", str(error.msg))
        line = error.lineno if error.lineno else None
        return None, {}, [Problem(f"malformed XML: {message}", (), line=line)]
    reader = _Reader(raw.decode("utf-8", errors="replace"))
    data = reader.knowledge(root)
    return data, reader.lines, reader.problems


# -- writing -------------------------------------------------------------------------------


def _format_number(value: float) -> str:
    return repr(float(value)) if not isinstance(value, int) else str(value)


def _format_matrix(matrix: Matrix | Sequence[Sequence[float]]) -> str:
    return "; ".join(" ".join(_format_number(x) for x in row) for row in matrix)


def _add(
    parent: etree._Element, tag: str, text: str | None = None, **attributes: str
) -> etree._Element:
    child = etree.SubElement(parent, tag, {k.rstrip("_"): v for k, v in attributes.items()})
    if text is not None:
        child.text = text
    return child


def _add_matrix(parent: etree._Element, tag: str, matrix: Matrix, **attributes: str) -> None:
    _add(_add(parent, tag, **attributes), "matrix", _format_matrix(matrix))


def _write_world(root: etree._Element, world: WorldSettings) -> None:
    element = _add(root, "world")
    for name, field in WorldSettings.model_fields.items():
        value = getattr(world, name)
        if value is None or (name not in world.model_fields_set and value == field.default):
            continue
        if name == "region":
            _add_matrix(element, name, value)
        elif isinstance(value, bool):
            _add(element, name, "true" if value else "false")
        else:
            _add(element, name, value if isinstance(value, str) else _format_number(value))


def _write_filter(element: etree._Element, spec: KalmanFilterSpec | IMMFilterSpec) -> None:
    models: tuple[MotionModelSpec, ...] = (
        (spec.model,) if isinstance(spec, KalmanFilterSpec) else spec.models
    )
    _add(element, "type", _FILTER_NAMES[spec.type])
    _add(element, "motion_model", ", ".join(_MOTION_NAMES[m.motion_model] for m in models))
    for model in models:
        _add_matrix(
            element, "system_noise", model.system_noise, model=_MOTION_NAMES[model.motion_model]
        )
    if isinstance(spec, IMMFilterSpec):
        _add_matrix(element, "transition_matrix", spec.transition_matrix)
        if spec.initial_mode_probabilities is not None:
            _add(
                element,
                "initial_mode_probabilities",
                " ".join(_format_number(p) for p in spec.initial_mode_probabilities),
            )
        _add(
            element,
            "stationary_velocity_variance",
            _format_number(spec.stationary_velocity_variance),
        )
        if spec.transition_period is not None:
            _add(element, "transition_period", _format_number(spec.transition_period))


def _write_class(root: etree._Element, spec: ClassSpec) -> None:
    element = _add(root, "object")
    _add(element, "class", spec.name)
    for parent in spec.is_a:
        _add(element, "is_a", parent)
    for name in _CLASS_SCALARS:
        value = getattr(spec, name)
        if isinstance(value, bool):
            _add(element, name, "true" if value else "false")
        elif value is not None:
            _add(element, name, value if isinstance(value, str) else _format_number(value))
    for kind in ("appearance", "disappearance"):
        relations = getattr(spec, kind)
        if relations is None:
            continue
        model = _add(element, f"{kind}_model")
        for relation in relations:
            _add(
                model,
                f"{kind}_relation",
                target=relation.target,
                max_distance=_format_number(relation.max_distance),
                frequency=_format_number(relation.frequency),
            )
    if spec.filter is not None:
        _write_filter(_add(element, "filter"), spec.filter)
    for name in _CLASS_MATRICES:
        value = getattr(spec, name)
        if value is not None:
            _add_matrix(element, name, value)


def document_to_xml(document: KnowledgeDocument) -> str:
    """The XML form of ``document``; :func:`read_xml` reads it back to an equal document."""
    root = etree.Element("knowledge")
    _write_world(root, document.world)
    for spec in document.classes:
        _write_class(root, spec)
    for detector in document.detectors:
        attributes = {
            "name": detector.name,
            "clutter_frequency": _format_number(detector.clutter_frequency),
        }
        for name in _DETECTOR_ATTRIBUTES[2:]:
            value = getattr(detector, name)
            if value is None or name not in detector.model_fields_set:
                continue
            if isinstance(value, bool):
                attributes[name] = "true" if value else "false"
            elif isinstance(value, tuple):
                attributes[name] = " ".join(_format_number(v) for v in value)
            else:
                attributes[name] = _format_number(value)
        element = _add(root, "detector", **attributes)
        for cls, matrix in detector.measurement_noise.items():
            _add_matrix(element, "measurement_noise", matrix, class_=cls)
    for known in document.known_objects:
        attributes = {"class_": known.cls} | (
            {"name": known.name} if known.name is not None else {}
        )
        element = _add(root, "known_object", **attributes)
        _add(element, "position", " ".join(_format_number(x) for x in known.position))
    text: bytes = etree.tostring(root, pretty_print=True, xml_declaration=True, encoding="UTF-8")
    return text.decode("utf-8")
