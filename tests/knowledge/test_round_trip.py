"""Writing a document and reading it back gives an equal document, in both forms."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from semwm.knowledge import (
    AppearanceRelation,
    ClassSpec,
    DetectorSpec,
    IMMFilterSpec,
    KalmanFilterSpec,
    KnowledgeDocument,
    KnownObject,
    MotionModelSpec,
    WorldSettings,
    load_document,
)
from semwm.knowledge.loader import UnknownFormatError, analyse_text, document_to_text, dump_document
from semwm.knowledge.shipped import shipped_knowledge_path

names = st.from_regex(r"[A-Za-z][A-Za-z0-9_]{0,7}", fullmatch=True)
reals = st.floats(min_value=-1e6, max_value=1e6, allow_nan=False)
non_negative = st.floats(min_value=0.0, max_value=1e6)
positive = st.floats(min_value=1e-9, max_value=1e6)
matrices = st.lists(st.lists(reals, min_size=1, max_size=3), min_size=1, max_size=3).map(
    lambda rows: tuple(tuple(row) for row in rows)
)
motion_models = st.builds(
    MotionModelSpec,
    motion_model=st.sampled_from(["zeroth_order", "first_order"]),
    system_noise=matrices,
)
filters = st.one_of(
    st.builds(KalmanFilterSpec, model=motion_models),
    st.builds(
        IMMFilterSpec,
        models=st.lists(motion_models, min_size=2, max_size=3).map(tuple),
        transition_matrix=matrices,
        initial_mode_probabilities=st.none() | st.lists(reals, min_size=1, max_size=3).map(tuple),
        stationary_velocity_variance=positive,
    ),
)


def optional(strategy: st.SearchStrategy[Any]) -> st.SearchStrategy[Any]:
    return st.none() | strategy


classes = st.builds(
    ClassSpec,
    name=names,
    is_a=st.lists(names, max_size=2).map(tuple),
    detection_frequency=optional(non_negative),
    new_frequency=optional(non_negative),
    appearance=optional(
        st.lists(
            st.builds(
                AppearanceRelation, target=names, max_distance=positive, frequency=non_negative
            ),
            max_size=2,
        ).map(tuple)
    ),
    filter=optional(filters),
    measurement_noise=optional(matrices),
    initial_covariance=optional(matrices),
    initial_velocity_covariance=optional(matrices),
    max_position_variance=optional(positive),
    max_time_without_update=optional(positive),
    category=optional(
        st.sampled_from(["static", "passive", "actively_controlled", "foreign_controlled"])
    ),
    velocity_decay=optional(non_negative),
    confidence_decay=optional(non_negative),
    looking_decay=optional(non_negative),
    suspicious_confidence=optional(st.floats(min_value=0.0, max_value=1.0)),
    detection_probability=optional(st.floats(min_value=0.0, max_value=1.0)),
    kick_direction_spread=optional(st.floats(min_value=0.0, max_value=180.0)),
    trust_labels=optional(st.booleans()),
)
worlds = st.builds(
    WorldSettings,
    dimension=st.sampled_from([2, 3]),
    pruning_ratio=st.floats(min_value=0.0, max_value=0.99),
    max_hypotheses=st.integers(min_value=1, max_value=10_000),
    association_model=st.sampled_from(["paper", "mht"]),
    gate_probability=st.floats(min_value=1e-6, max_value=1.0),
    region=optional(st.lists(st.tuples(reals, reals), min_size=1, max_size=3).map(tuple)),
    default_detector=optional(names),
)
documents = st.builds(
    KnowledgeDocument,
    world=worlds,
    classes=st.lists(classes, max_size=4).map(tuple),
    detectors=st.lists(
        st.builds(
            DetectorSpec,
            name=names,
            clutter_frequency=non_negative,
            measurement_noise=st.dictionaries(names, matrices, max_size=2),
            range=optional(positive),
        ),
        min_size=1,
        max_size=2,
    ).map(tuple),
    known_objects=st.lists(
        st.builds(
            KnownObject,
            cls=names,
            position=st.lists(reals, min_size=1, max_size=3).map(tuple),
            name=optional(names),
        ),
        max_size=2,
    ).map(tuple),
)


@pytest.mark.parametrize("fmt", ["xml", "yaml"])
@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(document=documents)
def test_writing_then_reading_gives_an_equal_document(
    fmt: str, document: KnowledgeDocument
) -> None:
    text = document_to_text(document, fmt)  # type: ignore[arg-type]
    analysis = analyse_text(text, fmt)  # type: ignore[arg-type]
    # Form only: resolution problems (unknown parents, matrix sizes) are expected here.
    assert analysis.document == document, [str(p) for p in analysis.problems]


@settings(max_examples=30, deadline=None)
@given(document=documents)
def test_xml_and_yaml_forms_read_to_the_same_document(document: KnowledgeDocument) -> None:
    from_xml = analyse_text(document_to_text(document, "xml"), "xml").document
    from_yaml = analyse_text(document_to_text(document, "yaml"), "yaml").document
    assert from_xml == from_yaml == document


def test_an_empty_appearance_stays_empty_rather_than_inherited() -> None:
    # appearance=() overrides the parent's relations; None inherits them.
    spec = ClassSpec(name="Quiet", is_a=("Person",), appearance=())
    document = KnowledgeDocument(
        classes=(spec,), detectors=(DetectorSpec(name="d", clutter_frequency=0.0),)
    )
    for fmt in ("xml", "yaml"):
        read = analyse_text(document_to_text(document, fmt), fmt).document
        assert read is not None and read.classes[0].appearance == ()


@pytest.mark.parametrize("source", ["sim2.xml", "robocup.yaml"])
@pytest.mark.parametrize("suffix", [".xml", ".yaml", ".yml"])
def test_dump_document_by_extension(tmp_path: Path, source: str, suffix: str) -> None:
    document = load_document(shipped_knowledge_path(source))
    target = tmp_path / f"copy{suffix}"
    dump_document(document, target)
    assert load_document(target) == document


def test_an_unknown_extension_is_a_clear_error(tmp_path: Path) -> None:
    document = load_document(shipped_knowledge_path("sim1.yaml"))
    with pytest.raises(UnknownFormatError, match=r"unknown knowledge file extension '.json'"):
        dump_document(document, tmp_path / "x.json")
    with pytest.raises(UnknownFormatError, match=r"expected one of .xml, .yaml, .yml"):
        load_document(tmp_path / "x.txt")


EXISTENCE_YAML = """\
world:
  dimension: 2
  region: [[0, 10], [0, 8]]
  min_existence: 0.6
  removal_existence: 1.0e-6
  label_gate: 1.5
  label_error_rate: 0.002
classes:
  - name: Person
    detection_frequency: 5.0
    leave_frequency: 0.02
    appearance:
      - {target: Door, max_distance: 0.5, frequency: 0.1}
    disappearance:
      - {target: Door, max_distance: 0.7, frequency: 2.0}
    filter:
      type: kalman
      model: {motion_model: zeroth_order, system_noise: [[0.01, 0], [0, 0.01]]}
    measurement_noise: [[0.02, 0], [0, 0.02]]
  - name: Door
    is_a: [Person]
    detection_frequency: 0.1
    new_frequency: 0.0
detectors:
  - name: camera
    clutter_frequency: 0.5
    range: 6.0
    field_of_view: 120
    confusion_rate: 0.1
    unrelated_confusion_rate: 0.02
"""


@pytest.mark.parametrize("fmt", ["xml", "yaml"])
def test_existence_coverage_and_confusion_fields_round_trip(fmt: str) -> None:
    """The mht model's fields (existence thresholds, label gate, leave rates,
    disappearance relations, detector coverage and confusion) survive either form."""
    analysis = analyse_text(EXISTENCE_YAML, "yaml", "existence.yaml")
    assert analysis.document is not None and not analysis.problems
    text = document_to_text(analysis.document, fmt)  # type: ignore[arg-type]
    again = analyse_text(text, fmt, f"existence.{fmt}")  # type: ignore[arg-type]
    assert not again.problems, again.problems
    assert again.document == analysis.document
    knowledge = again.knowledge
    assert knowledge is not None
    person = knowledge.classes["Person"]
    assert person.leave_frequency == 0.02
    assert person.disappearance[0].frequency == 2.0
    detector = knowledge.detectors["camera"]
    assert (detector.field_of_view, detector.confusion_rate) == (120, 0.1)
    assert knowledge.world.removal_existence == 1e-6
