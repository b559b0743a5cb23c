"""``semwm knowledge ...``: validate, convert and show knowledge files.

* ``semwm knowledge validate FILE...``: one line per problem (``FILE:LINE: message``)
  and exit status 1, or one ``FILE: OK (...)`` line per file and exit status 0;
* ``semwm knowledge convert IN OUT``: XML <-> YAML, by the files' extensions;
* ``semwm knowledge show FILE [CLASS]``: a class's resolved settings (each with the
  class it comes from), or a summary with the taxonomy as an indented tree.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Iterator
from pathlib import Path

from semwm.cli.common import (
    EXIT_INVALID,
    EXIT_OK,
    EXIT_USAGE,
    CommandError,
    Subparsers,
    description,
)
from semwm.knowledge.loader import (
    UnknownFormatError,
    analyse_file,
    dump_document,
    load_document,
    load_knowledge,
)
from semwm.knowledge.model import (
    CATEGORY_FIELDS,
    IMMFilterSpec,
    Knowledge,
    Matrix,
    ResolvedClass,
)
from semwm.knowledge.problems import KnowledgeError
from semwm.knowledge.resolve import INHERITED_FIELDS


def add_knowledge_command(subparsers: Subparsers) -> None:
    """Add ``knowledge validate|convert|show`` to a top-level parser's subparsers.

    Each command parser sets ``func``, a function of the parsed arguments returning
    the exit status.
    """
    knowledge = subparsers.add_parser(
        "knowledge",
        help="validate, convert and show knowledge files (XML or YAML)",
        description=description(__doc__),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    commands = knowledge.add_subparsers(dest="knowledge_command", metavar="COMMAND", required=True)

    validate = commands.add_parser("validate", help="check knowledge files; one line per problem")
    validate.add_argument("files", nargs="+", metavar="FILE")
    validate.set_defaults(func=validate_command)

    convert = commands.add_parser(
        "convert",
        help="convert between XML and YAML (by extension)",
        description="Convert a knowledge file between XML and YAML, chosen by the extensions "
        "(.xml, .yaml, .yml). OUT's folder must exist.",
    )
    convert.add_argument("source", metavar="IN")
    convert.add_argument("target", metavar="OUT")
    convert.set_defaults(func=convert_command)

    show = commands.add_parser("show", help="show a class's resolved settings, or a summary")
    show.add_argument("file", metavar="FILE")
    show.add_argument("cls", nargs="?", metavar="CLASS")
    show.set_defaults(func=show_command)


def _plural(count: int, word: str) -> str:
    return f"{count} {word}{'' if count == 1 else 'es' if word.endswith('s') else 's'}"


def _summary(knowledge: Knowledge) -> str:
    return (
        f"{_plural(len(knowledge.classes), 'class')}, "
        f"{_plural(len(knowledge.detectors), 'detector')}, dimension {knowledge.dimension}"
    )


def validate_command(args: argparse.Namespace) -> int:
    """Check every file; print its problems, or ``FILE: OK (...)``."""
    status = EXIT_OK
    for file in args.files:
        try:
            analysis = analyse_file(file)
        except (OSError, UnknownFormatError) as error:
            print(f"{file}: {error}" if isinstance(error, OSError) else str(error))
            status = EXIT_INVALID
            continue
        for problem in (*analysis.problems, *analysis.warnings):
            print(problem)
        if analysis.knowledge is None:
            status = EXIT_INVALID
        else:
            print(f"{file}: OK ({_summary(analysis.knowledge)})")
    return status


def _report(error: Exception) -> int:
    """Print why a file could not be used: one ``FILE:LINE: message`` line per problem
    (stdout), or the I/O or format error (stderr)."""
    if isinstance(error, KnowledgeError):
        for problem in error.problems:
            print(problem)
    else:
        print(error, file=sys.stderr)
    return EXIT_INVALID


def convert_command(args: argparse.Namespace) -> int:
    """Read ``IN`` and write the same document to ``OUT`` in the other format.

    ``OUT``'s folder must exist (a typo in it is not silently created): else a
    :class:`CommandError` names it, and nothing is written.
    """
    folder = Path(args.target).parent
    if not folder.is_dir():
        raise CommandError(f"cannot write {args.target}: no such folder {folder}/", EXIT_INVALID)
    try:
        document = load_document(args.source)
        dump_document(document, args.target)
    except (KnowledgeError, OSError, UnknownFormatError) as error:
        return _report(error)
    print(f"wrote {args.target}")
    return EXIT_OK


def _matrix(matrix: Matrix) -> str:
    return "[" + "; ".join(" ".join(f"{x:g}" for x in row) for row in matrix) + "]"


def _filter_text(resolved: ResolvedClass) -> str:
    spec = resolved.filter
    if isinstance(spec, IMMFilterSpec):
        models = ", ".join(
            f"{m.motion_model.replace('_', ' ')} (system noise {_matrix(m.system_noise)})"
            for m in spec.models
        )
        return f"multiple model: {models}; transition matrix {_matrix(spec.transition_matrix)}"
    model = spec.model
    order = model.motion_model.replace("_", " ")
    return f"Kalman, {order} (system noise {_matrix(model.system_noise)})"


_UNITS = {
    "detection_frequency": "Hz",
    "new_frequency": "Hz",
    "measurement_noise": "m^2",
    "initial_covariance": "m^2",
    "initial_velocity_covariance": "m^2/s^2",
    "max_position_variance": "m^2",
    "max_time_without_update": "s",
}
_SHOWN = INHERITED_FIELDS
_UNITS.update(
    {
        "velocity_decay": "m/s^2",
        "confidence_decay": "1/s",
        "confidence_decay_distance": "1/m",
        "looking_decay": "1/s",
        "kick_direction_spread": "deg",
    }
)


def _origin(knowledge: Knowledge, resolved: ResolvedClass, field: str) -> str:
    """The class whose file entry gives ``field`` (first in the inheritance chain), or default."""
    specs = {spec.name: spec for spec in knowledge.document.classes}
    for name in (resolved.name, *resolved.ancestors):
        if getattr(specs[name], field) is not None:
            return "" if name == resolved.name else f"  (from {name})"
    if field == "initial_covariance":
        return "  (default: the measurement noise)"
    if field in CATEGORY_FIELDS and resolved.category is not None:
        return f"  (default of category {resolved.category})"
    return "  (default)"


def _value_text(resolved: ResolvedClass, field: str) -> str:
    value = getattr(resolved, field)
    if value is None:
        return "not set"
    if field == "filter":
        return _filter_text(resolved)
    if field == "appearance":
        relations = [
            f"within {r.max_distance:g} m of a {r.target} at {r.frequency:g} Hz" for r in value
        ]
        return "; ".join(relations) or "none"
    unit = _UNITS.get(field, "")
    text = _matrix(value) if isinstance(value, tuple) else f"{value:g}" if unit else str(value)
    return f"{text} {unit}".rstrip()


def class_lines(knowledge: Knowledge, name: str) -> list[str]:
    """A class's resolved settings, one per line, each with the class it is inherited from."""
    resolved = knowledge.classes[name]
    parents = f" (is-a {', '.join(resolved.parents)})" if resolved.parents else ""
    lines = [f"{name}{parents}"]
    if resolved.ancestors:
        lines.append(f"  ancestors: {', '.join(resolved.ancestors)}")
    for field in _SHOWN:
        origin = _origin(knowledge, resolved, field)
        lines.append(f"  {field}: {_value_text(resolved, field)}{origin}")
    return lines


def taxonomy_lines(knowledge: Knowledge) -> Iterator[str]:
    """The is-a taxonomy as an indented tree; a class with several parents shows under each."""
    names = list(knowledge.classes)

    def subtree(name: str, depth: int) -> Iterator[str]:
        resolved = knowledge.classes[name]
        yield f"{'  ' * depth}{name}  [{resolved.filter.type}, {resolved.detection_frequency:g} Hz]"
        for child in names:
            if name in knowledge.classes[child].parents:
                yield from subtree(child, depth + 1)

    for name in names:
        if not knowledge.classes[name].parents:
            yield from subtree(name, 1)


def summary_lines(knowledge: Knowledge, file: str) -> list[str]:
    """A file's world settings, detectors and taxonomy."""
    world = knowledge.world
    lines = [f"{file}: {_summary(knowledge)}"]
    lines.append(
        f"world: pruning ratio {world.pruning_ratio:g}, at most {world.max_hypotheses} hypotheses, "
        f"{world.association_model} association model"
        + (f", region {[list(axis) for axis in world.region]}" if world.region else "")
    )
    lines.append("detectors:")
    for detector in knowledge.detectors.values():
        extra = f", range {detector.range:g} m" if detector.range is not None else ""
        own = ", ".join(detector.measurement_noise)
        extra += f", own measurement noise for {own}" if own else ""
        default = " (default)" if detector.name == knowledge.default_detector else ""
        lines.append(
            f"  {detector.name}{default}: clutter {detector.clutter_frequency:g} Hz{extra}"
        )
    lines.append("taxonomy:")
    lines += taxonomy_lines(knowledge)
    return lines


def show_command(args: argparse.Namespace) -> int:
    """Print one class's resolved settings, or the whole file's summary."""
    try:
        knowledge = load_knowledge(args.file)
    except (KnowledgeError, OSError, UnknownFormatError) as error:
        return _report(error)
    if args.cls is None:
        print("\n".join(summary_lines(knowledge, args.file)))
        return EXIT_OK
    if args.cls not in knowledge.classes:
        known = ", ".join(knowledge.classes)
        print(f"{args.file}: unknown class {args.cls!r}; known classes: {known}", file=sys.stderr)
        return EXIT_USAGE
    print("\n".join(class_lines(knowledge, args.cls)))
    return EXIT_OK
