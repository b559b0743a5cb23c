"""Resolution: a :class:`KnowledgeDocument` checked and turned into :class:`Knowledge`.

Inheritance is applied here, once: a class takes every field it leaves out from
its ``is_a`` parents (first parent that defines it, depth first). Every check
that needs more than one field (references between classes, matrix sizes that
depend on the world's dimension, positive definiteness) is made here, and each
problem names the field path it is about so that loaders can give it a line.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence

import numpy as np

from semwm.knowledge.model import (
    CATEGORY_DEFAULTS,
    CATEGORY_FIELDS,
    ClassSpec,
    DetectorSpec,
    IMMFilterSpec,
    Knowledge,
    KnowledgeDocument,
    Matrix,
    ResolvedClass,
)
from semwm.knowledge.problems import KnowledgeError, Path, Problem

INHERITED_FIELDS = (  # what a class takes from its is-a parents when it leaves it out
    "detection_frequency",
    "new_frequency",
    "appearance",
    "filter",
    "measurement_noise",
    "initial_covariance",
    "initial_velocity_covariance",
    "max_position_variance",
    "max_time_without_update",
    "leave_frequency",
    "disappearance",
    "category",
    *CATEGORY_FIELDS,
)
_REQUIRED = ("detection_frequency", "filter", "measurement_noise")
DEFAULT_NEW_FREQUENCY = 0.1
"""Hz; base rate of new objects when no class in the chain sets one."""
DEFAULT_LEAVE_FREQUENCY = 0.01
"""Hz; objects leave at this rate (an average stay of 100 s) when no class in the chain
sets one. Without any leave rate an object that certainly exists never loses existence
by going unseen (semwm.mhf.existence); with it, an object unseen where it would be seen
at rate f drops below existence 0.5 after about ln(f / mu) / f seconds."""
DEFAULT_VELOCITY_VARIANCE = 1.0
"""m^2/s^2 per axis; initial velocity variance when no class in the chain sets one."""


def matrix_problems(matrix: Matrix, size: int, what: str, path: Path) -> list[Problem]:
    """Problems with a matrix that must be ``size`` x ``size`` symmetric positive definite."""
    rows = len(matrix)
    if any(len(row) != rows for row in matrix):
        lengths = ", ".join(str(len(row)) for row in matrix)
        return [Problem(f"{what} must be square; found {rows} rows of lengths {lengths}", path)]
    if rows != size:
        return [Problem(f"{what} must be {size} x {size}; found {rows} x {rows}", path)]
    array = np.asarray(matrix, dtype=float)
    if not np.all(np.isfinite(array)):
        return [Problem(f"{what} must hold finite numbers", path)]
    if not np.allclose(array, array.T, rtol=1e-9, atol=1e-12):
        return [Problem(f"{what} must be symmetric; found {array.tolist()}", path)]
    if np.linalg.eigvalsh(array).min() <= 0.0:
        low = float(np.linalg.eigvalsh(array).min())
        return [
            Problem(f"{what} must be positive definite; its smallest eigenvalue is {low:g}", path)
        ]
    return []


def _transition_problems(spec: IMMFilterSpec, path: Path) -> list[Problem]:
    modes = len(spec.models)
    matrix = spec.transition_matrix
    where = (*path, "transition_matrix")
    if len(matrix) != modes or any(len(row) != modes for row in matrix):
        shape = f"{len(matrix)} x {max((len(r) for r in matrix), default=0)}"
        return [
            Problem(
                f"transition matrix must be {modes} x {modes} (one row and column per motion "
                f"model); found {shape}",
                where,
            )
        ]
    problems = []
    for i, row in enumerate(matrix):
        if any(value < 0.0 or value > 1.0 for value in row):
            problems.append(
                Problem(f"transition matrix row {i + 1} has entries outside [0, 1]", where)
            )
        elif abs(sum(row) - 1.0) > 1e-9:
            problems.append(
                Problem(
                    f"transition matrix row {i + 1} must sum to 1 "
                    "(row i holds P(mode j | mode i)); "
                    f"it sums to {sum(row):g}",
                    where,
                )
            )
    if not problems and spec.transition_period is not None:
        eigenvalues = np.linalg.eigvals(np.asarray(matrix, dtype=float))
        if np.any(np.abs(eigenvalues.imag) > 1e-12) or np.any(eigenvalues.real <= 0.0):
            problems.append(
                Problem(
                    "with transition_period the transition matrix is scaled in time "
                    "(T^(dt / period)), which needs real positive eigenvalues; found "
                    f"{np.round(eigenvalues, 6).tolist()} (make the diagonal dominant, "
                    "e.g. each row's own mode above 0.5)",
                    where,
                )
            )
    initial = spec.initial_mode_probabilities
    if initial is not None:
        where = (*path, "initial_mode_probabilities")
        if len(initial) != modes:
            problems.append(
                Problem(
                    f"initial mode probabilities need {modes} values; found {len(initial)}", where
                )
            )
        elif any(p < 0.0 for p in initial) or abs(sum(initial) - 1.0) > 1e-9:
            problems.append(
                Problem(
                    f"initial mode probabilities must be >= 0 and sum to 1; found {initial}", where
                )
            )
    return problems


def _class_spec_problems(spec: ClassSpec, dim: int, path: Path) -> list[Problem]:
    """Checks of the values a class writes itself (located at the class)."""
    problems: list[Problem] = []
    for field in ("measurement_noise", "initial_covariance", "initial_velocity_covariance"):
        value = getattr(spec, field)
        if value is not None:
            label = field.replace("_", " ")
            problems += matrix_problems(value, dim, label, (*path, field))
    if spec.filter is not None:
        filter_path = (*path, "filter")
        if isinstance(spec.filter, IMMFilterSpec):
            for m, model in enumerate(spec.filter.models):
                problems += matrix_problems(
                    model.system_noise,
                    dim,
                    "system noise",
                    (*filter_path, "models", m, "system_noise"),
                )
            problems += _transition_problems(spec.filter, filter_path)
        else:
            problems += matrix_problems(
                spec.filter.model.system_noise,
                dim,
                "system noise",
                (*filter_path, "model", "system_noise"),
            )
    return problems


def _ancestry(name: str, parents: dict[str, tuple[str, ...]]) -> Iterator[str]:
    """Depth-first, first-parent-first walk over the ancestors of ``name`` (no repeats)."""
    seen: set[str] = set()
    stack = list(reversed(parents.get(name, ())))
    while stack:
        current = stack.pop()
        if current in seen:
            continue
        seen.add(current)
        yield current
        stack.extend(reversed(parents.get(current, ())))


def _find_cycles(parents: dict[str, tuple[str, ...]]) -> set[str]:
    """Classes that lie on an is-a cycle."""
    on_cycle: set[str] = set()
    for start in parents:
        for ancestor in _ancestry(start, parents):
            if ancestor == start:
                on_cycle.add(start)
                break
    return on_cycle


def resolve(document: KnowledgeDocument, source: str | None = None) -> Knowledge:
    """Check a document and apply inheritance.

    Raises
    ------
    KnowledgeError
        With every problem found, each carrying the field path it is about.
    """
    problems, knowledge = _resolve(document, source)
    if problems:
        raise KnowledgeError(problems)
    assert knowledge is not None
    return knowledge


def _duplicates(names: Sequence[str], what: str, root: str) -> list[Problem]:
    seen: set[str] = set()
    problems = []
    for i, name in enumerate(names):
        if name in seen:
            problems.append(Problem(f"{what} {name!r} is defined twice", (root, i, "name")))
        seen.add(name)
    return problems


def _resolve(
    document: KnowledgeDocument, source: str | None
) -> tuple[list[Problem], Knowledge | None]:
    dim = document.world.dimension
    specs = document.classes
    index = {spec.name: i for i, spec in enumerate(specs)}
    problems = _duplicates([s.name for s in specs], "class", "classes")
    problems += _duplicates([d.name for d in document.detectors], "detector", "detectors")
    known_classes = ", ".join(sorted(index)) or "none"

    parents: dict[str, tuple[str, ...]] = {}
    for i, spec in enumerate(specs):
        valid = []
        for j, parent in enumerate(spec.is_a):
            if parent not in index:
                problems.append(
                    Problem(
                        f"class {spec.name!r} is-a unknown class {parent!r}; "
                        f"known classes: {known_classes}",
                        ("classes", i, "is_a", j),
                    )
                )
            else:
                valid.append(parent)
        parents[spec.name] = tuple(valid)
    cycles = _find_cycles(parents)
    for name in sorted(cycles, key=index.__getitem__):
        problems.append(
            Problem(f"class {name!r} is part of an is-a cycle", ("classes", index[name], "is_a"))
        )
    if cycles:
        parents = {name: () if name in cycles else p for name, p in parents.items()}
    # classes whose chain is broken already have a problem; don't add its consequences
    broken = {s.name for s in specs if len(parents[s.name]) != len(s.is_a)} | cycles

    for i, spec in enumerate(specs):
        problems += _class_spec_problems(spec, dim, ("classes", i))
        for kind in ("appearance", "disappearance"):
            for j, relation in enumerate(getattr(spec, kind) or ()):
                if relation.target not in index:
                    problems.append(
                        Problem(
                            f"{kind} relation of {spec.name!r} targets unknown class "
                            f"{relation.target!r}; known classes: {known_classes}",
                            ("classes", i, kind, j, "target"),
                        )
                    )

    resolved: dict[str, ResolvedClass] = {}
    for i, spec in enumerate(specs):
        chain = [spec] + [specs[index[a]] for a in _ancestry(spec.name, parents)]
        values = {}
        for field in INHERITED_FIELDS:
            values[field] = next(
                (getattr(s, field) for s in chain if getattr(s, field) is not None), None
            )
        missing = [f for f in _REQUIRED if values[f] is None]
        reported = missing and not broken & {s.name for s in chain}
        for field in missing if reported else ():
            lineage = " -> ".join(s.name for s in chain)
            problems.append(
                Problem(
                    f"class {spec.name!r} has no {field.replace('_', ' ')}: neither it nor its "
                    f"ancestors ({lineage}) define one",
                    ("classes", i),
                )
            )
        if missing:
            continue
        measurement_noise = values["measurement_noise"]
        resolved[spec.name] = ResolvedClass(
            name=spec.name,
            parents=parents[spec.name],
            ancestors=tuple(_ancestry(spec.name, parents)),
            detection_frequency=values["detection_frequency"],
            new_frequency=(
                values["new_frequency"]
                if values["new_frequency"] is not None
                else DEFAULT_NEW_FREQUENCY
            ),
            appearance=values["appearance"] or (),
            filter=values["filter"],
            measurement_noise=measurement_noise,
            initial_covariance=values["initial_covariance"] or measurement_noise,
            initial_velocity_covariance=values["initial_velocity_covariance"]
            or tuple(
                tuple(DEFAULT_VELOCITY_VARIANCE if r == c else 0.0 for c in range(dim))
                for r in range(dim)
            ),
            max_position_variance=values["max_position_variance"],
            max_time_without_update=values["max_time_without_update"],
            leave_frequency=(
                values["leave_frequency"]
                if values["leave_frequency"] is not None
                else DEFAULT_LEAVE_FREQUENCY
            ),
            disappearance=values["disappearance"] or (),
            category=values["category"],
            **{
                field: (
                    values[field]
                    if values[field] is not None
                    else CATEGORY_DEFAULTS[values["category"]][field]
                )
                for field in CATEGORY_FIELDS
            },
        )

    for i, spec in enumerate(specs):
        done = resolved.get(spec.name)
        if done is None:
            continue
        if done.invalid_confidence > done.suspicious_confidence:
            problems.append(
                Problem(
                    f"class {spec.name!r}: invalid_confidence ({done.invalid_confidence:g}) must "
                    f"not exceed suspicious_confidence ({done.suspicious_confidence:g})",
                    ("classes", i),
                )
            )
        has_velocity = isinstance(done.filter, IMMFilterSpec) or (
            done.filter.model.motion_model == "first_order"
        )
        if done.category == "static" and has_velocity:
            problems.append(
                Problem(
                    f"class {spec.name!r} is static (paper 004: no velocity) but its filter "
                    "has velocity; use a zeroth_order Kalman filter or another category",
                    ("classes", i),
                )
            )

    detector_names = [d.name for d in document.detectors]
    for i, detector in enumerate(document.detectors):
        problems += _detector_problems(detector, dim, index, known_classes, ("detectors", i))
    default = document.world.default_detector
    if default is not None and default not in detector_names:
        problems.append(
            Problem(
                f"unknown detector {default!r}; known detectors: {', '.join(detector_names)}",
                ("world", "default_detector"),
            )
        )
    region = document.world.region
    if region is not None:
        if len(region) != dim:
            problems.append(
                Problem(
                    f"region needs {dim} [min, max] pairs; found {len(region)}", ("world", "region")
                )
            )
        elif any(low >= high for low, high in region):
            problems.append(Problem("region pairs must have min < max", ("world", "region")))
    if document.world.association_model == "mht" and (
        document.world.region is None or len(document.world.region) == dim
    ):
        for i, detector in enumerate(document.detectors):
            if detector.range is None and document.world.region is None:
                problems.append(
                    Problem(
                        f"detector {detector.name!r} has no range and the world no region: the "
                        "mht model spreads its clutter_frequency over the area it sees; give "
                        "the detector a range (and field_of_view) from its datasheet, or set "
                        "world.region to the area the robot works in",
                        ("detectors", i),
                    )
                )
    for i, known in enumerate(document.known_objects):
        if known.cls not in index:
            problems.append(
                Problem(
                    f"known object of unknown class {known.cls!r}; known classes: {known_classes}",
                    ("known_objects", i, "class"),
                )
            )
        if len(known.position) != dim:
            problems.append(
                Problem(
                    f"known object position needs {dim} coordinates; found {len(known.position)}",
                    ("known_objects", i, "position"),
                )
            )
    if problems:
        return problems, None
    knowledge = Knowledge(
        world=document.world,
        classes=resolved,
        detectors={d.name: d for d in document.detectors},
        known_objects=document.known_objects,
        document=document,
        source=source,
    )
    return [], knowledge


def _detector_problems(
    detector: DetectorSpec, dim: int, index: dict[str, int], known_classes: str, path: Path
) -> list[Problem]:
    problems = []
    for cls, matrix in detector.measurement_noise.items():
        where = (*path, "measurement_noise", cls)
        if cls not in index:
            problems.append(
                Problem(
                    f"detector {detector.name!r} sets measurement noise for unknown class {cls!r}; "
                    f"known classes: {known_classes}",
                    where,
                )
            )
        problems += matrix_problems(matrix, dim, "measurement noise", where)
    if detector.position is not None and len(detector.position) != dim:
        problems.append(
            Problem(
                f"detector {detector.name!r}: position must have {dim} coordinates (the world's "
                f"dimension); found {len(detector.position)}",
                (*path, "position"),
            )
        )
    if detector.position is not None and not detector.static:
        problems.append(
            Problem(
                f"detector {detector.name!r}: position is where a static sensor stands; set "
                "static: true, or leave position out (a moving sensor gives sensor_position "
                "with its detections)",
                (*path, "position"),
            )
        )
    return problems
