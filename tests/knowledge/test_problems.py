"""Every kind of problem in a knowledge file is reported at its own line, in both forms.

Each case edits one place of a valid file; the expected line is the line of the
edited text (found by searching for it), so the loader's own line bookkeeping
is what is under test.
"""

from __future__ import annotations

from dataclasses import dataclass

import pytest

from semwm.knowledge.loader import analyse_text
from semwm.knowledge.problems import Problem

VALID_XML = """\
<?xml version="1.0" encoding="UTF-8"?>
<knowledge>
  <world>
    <dimension>2</dimension><region><matrix>0 10; 0 10</matrix></region>
  </world>
  <object>
    <class>Thing</class>
    <detection_frequency>1.0</detection_frequency>
    <filter>
      <type>Kalman filter</type>
      <motion_model>zeroth order</motion_model>
      <system_noise><matrix>0.01 0; 0 0.01</matrix></system_noise>
      <measurement_noise><matrix>0.04 0; 0 0.04</matrix></measurement_noise>
    </filter>
  </object>
  <object>
    <class>Mover</class>
    <is_a>Thing</is_a>
    <filter>
      <type>multiple model Kalman filter</type>
      <motion_model>zeroth order, first order</motion_model>
      <system_noise model="zeroth order"><matrix>0.01 0; 0 0.01</matrix></system_noise>
      <system_noise model="first order"><matrix>0.5 0; 0 0.5</matrix></system_noise>
      <transition_matrix><matrix>0.9 0.1; 0.1 0.9</matrix></transition_matrix>
    </filter>
    <appearance_model>
      <appearance_relation target="Thing" max_distance="0.5" frequency="0.1"/>
    </appearance_model>
  </object>
  <detector name="camera" clutter_frequency="0.5"/>
</knowledge>
"""

VALID_YAML = """\
world:
  {dimension: 2, region: [[0, 10], [0, 10]]}
classes:
  - name: Thing
    detection_frequency: 1.0
    filter:
      type: kalman
      model:
        motion_model: zeroth_order
        system_noise: [[0.01, 0], [0, 0.01]]
    measurement_noise: [[0.04, 0], [0, 0.04]]
  - name: Mover
    is_a: [Thing]
    filter:
      type: imm
      models:
        - motion_model: zeroth_order
          system_noise: [[0.01, 0], [0, 0.01]]
        - motion_model: first_order
          system_noise: [[0.5, 0], [0, 0.5]]
      transition_matrix: [[0.9, 0.1], [0.1, 0.9]]
    appearance:
      - target: Thing
        max_distance: 0.5
        frequency: 0.1
detectors:
  - name: camera
    clutter_frequency: 0.5
"""


def line_of(text: str, needle: str) -> int:
    """1-based line of the first occurrence of ``needle`` in ``text``."""
    assert text.count(needle) >= 1, f"{needle!r} not in the test text"
    return text[: text.index(needle)].count("\n") + 1


def edited(text: str, old: str, new: str) -> str:
    assert text.count(old) == 1, f"{old!r} must occur exactly once"
    return text.replace(old, new)


def problems_of(text: str, fmt: str) -> list[Problem]:
    return list(analyse_text(text, fmt, f"test.{fmt}").problems)  # type: ignore[arg-type]


@dataclass(frozen=True)
class Case:
    """One edit of the valid text; the problem must be at the line holding ``at``."""

    old: str
    new: str
    at: str
    message: str


XML_CASES = {
    "unknown element": Case(
        "<class>Thing</class>",
        "<class>Thing</class>\n    <colour>red</colour>",
        "<colour>",
        "unknown element <colour> in <object>; expected one of <class>, <is_a>",
    ),
    "unknown attribute": Case(
        'clutter_frequency="0.5"/>',
        'clutter_frequency="0.5"\n    colour="red"/>',
        'colour="red"',
        "unknown attribute 'colour' on <detector>",
    ),
    "detector without clutter frequency": Case(
        '<detector name="camera" clutter_frequency="0.5"/>',
        '<detector name="camera"/>',
        "<detector",
        "missing required value 'clutter_frequency'",
    ),
    "appearance relation without target": Case(
        '<appearance_relation target="Thing" max_distance="0.5"',
        '<appearance_relation max_distance="0.5"',
        "<appearance_relation",
        "missing required value 'target'",
    ),
    "no filter in the chain": Case(
        """    <filter>
      <type>Kalman filter</type>
      <motion_model>zeroth order</motion_model>
      <system_noise><matrix>0.01 0; 0 0.01</matrix></system_noise>
      <measurement_noise><matrix>0.04 0; 0 0.04</matrix></measurement_noise>
    </filter>
""",
        "    <measurement_noise><matrix>0.04 0; 0 0.04</matrix></measurement_noise>\n",
        "<object>",
        "class 'Thing' has no filter",
    ),
    "unknown parent": Case(
        "<is_a>Thing</is_a>", "<is_a>Ghost</is_a>", "<is_a>Ghost", "is-a unknown class 'Ghost'"
    ),
    "is-a cycle": Case(
        "<class>Thing</class>",
        "<class>Thing</class>\n    <is_a>Mover</is_a>",
        "<is_a>Mover",
        "class 'Thing' is part of an is-a cycle",
    ),
    "matrix not square": Case(
        "<matrix>0.04 0; 0 0.04</matrix>",
        "<matrix>0.04 0; 0</matrix>",
        "<measurement_noise>",
        "measurement noise must be square",
    ),
    "matrix of the wrong size": Case(
        "<matrix>0.04 0; 0 0.04</matrix>",
        "<matrix>0.04 0 0; 0 0.04 0; 0 0 0.04</matrix>",
        "<measurement_noise>",
        "measurement noise must be 2 x 2; found 3 x 3",
    ),
    "matrix not symmetric": Case(
        "<matrix>0.5 0; 0 0.5</matrix>",
        "<matrix>0.5 0.1; 0 0.5</matrix>",
        '<system_noise model="first order">',
        "system noise must be symmetric",
    ),
    "matrix not positive definite": Case(
        "<matrix>0.04 0; 0 0.04</matrix>",
        "<matrix>1 2; 2 1</matrix>",
        "<measurement_noise>",
        "measurement noise must be positive definite; its smallest eigenvalue is -1",
    ),
    "unknown appearance target": Case(
        'target="Thing"', 'target="Ghost"', 'target="Ghost"', "targets unknown class 'Ghost'"
    ),
    "negative frequency": Case(
        "<detection_frequency>1.0</detection_frequency>",
        "<detection_frequency>-1</detection_frequency>",
        "<detection_frequency>",
        "expected a number >= 0, found -1",
    ),
    "not a number": Case(
        "<detection_frequency>1.0</detection_frequency>",
        "<detection_frequency>often</detection_frequency>",
        "<detection_frequency>",
        "expected a number, found 'often'",
    ),
    "transition rows not summing to 1": Case(
        "<matrix>0.9 0.1; 0.1 0.9</matrix>",
        "<matrix>0.9 0.2; 0.1 0.9</matrix>",
        "<transition_matrix>",
        "transition matrix row 1 must sum to 1",
    ),
    "unknown default detector": Case(
        "<dimension>2</dimension>",
        "<dimension>2</dimension>\n    <default_detector>radar</default_detector>",
        "<default_detector>",
        "unknown detector 'radar'; known detectors: camera",
    ),
    "unknown filter type": Case(
        "<type>Kalman filter</type>",
        "<type>particle filter</type>",
        "<type>particle",
        "unknown filter type 'particle filter'",
    ),
    "unknown motion model": Case(
        "<motion_model>zeroth order</motion_model>",
        "<motion_model>second order</motion_model>",
        "<motion_model>second",
        "unknown motion model 'second order'",
    ),
    "system noise count": Case(
        '      <system_noise model="first order"><matrix>0.5 0; 0 0.5</matrix></system_noise>\n',
        "",
        '<system_noise model="zeroth order">',
        "2 motion model(s) need as many <system_noise> elements",
    ),
    "system noise model attribute out of order": Case(
        '<system_noise model="zeroth order">',
        '<system_noise model="first order">',
        '<system_noise model="first order"><matrix>0.01',
        "motion model number 1 is 'zeroth order'",
    ),
    "wrong dimension": Case(
        "<dimension>2</dimension>", "<dimension>4</dimension>", "<dimension>", "expected 2 or 3"
    ),
}

YAML_CASES = {
    "unknown key": Case(
        "  - name: Thing\n",
        "  - name: Thing\n    colour: red\n",
        "colour:",
        "unknown key 'colour'; expected one of name, is_a, detection_frequency",
    ),
    "unknown key in a filter": Case(
        "      type: kalman\n",
        "      type: kalman\n      gain: 2\n",
        "gain:",
        "unknown key 'gain'; expected one of type, model",
    ),
    "detector without clutter frequency": Case(
        "  - name: camera\n    clutter_frequency: 0.5\n",
        "  - name: camera\n",
        "- name: camera",
        "missing required value 'clutter_frequency'",
    ),
    "appearance relation without target": Case(
        "      - target: Thing\n        max_distance: 0.5\n",
        "      - max_distance: 0.5\n",
        "- max_distance: 0.5",
        "missing required value 'target'",
    ),
    "no filter in the chain": Case(
        """    filter:
      type: kalman
      model:
        motion_model: zeroth_order
        system_noise: [[0.01, 0], [0, 0.01]]
""",
        "",
        "- name: Thing",
        "class 'Thing' has no filter",
    ),
    "unknown parent": Case(
        "is_a: [Thing]", "is_a: [Ghost]", "is_a: [Ghost]", "unknown class 'Ghost'"
    ),
    "is-a cycle": Case(
        "  - name: Thing\n",
        "  - name: Thing\n    is_a: [Mover]\n",
        "is_a: [Mover]",
        "class 'Thing' is part of an is-a cycle",
    ),
    "matrix not square": Case(
        "measurement_noise: [[0.04, 0], [0, 0.04]]",
        "measurement_noise: [[0.04, 0], [0]]",
        "measurement_noise:",
        "measurement noise must be square",
    ),
    "matrix of the wrong size": Case(
        "measurement_noise: [[0.04, 0], [0, 0.04]]",
        "measurement_noise: [[0.04]]",
        "measurement_noise:",
        "measurement noise must be 2 x 2; found 1 x 1",
    ),
    "matrix not positive definite": Case(
        "system_noise: [[0.5, 0], [0, 0.5]]",
        "system_noise: [[0, 0], [0, 0.5]]",
        "system_noise: [[0, 0]",
        "system noise must be positive definite",
    ),
    "unknown appearance target": Case(
        "target: Thing", "target: Ghost", "target: Ghost", "targets unknown class 'Ghost'"
    ),
    "negative frequency": Case(
        "clutter_frequency: 0.5",
        "clutter_frequency: -1",
        "clutter_frequency:",
        "expected a number >= 0, found -1",
    ),
    "transition rows not summing to 1": Case(
        "transition_matrix: [[0.9, 0.1], [0.1, 0.9]]",
        "transition_matrix: [[0.9, 0.1], [0.2, 0.9]]",
        "transition_matrix:",
        "transition matrix row 2 must sum to 1",
    ),
    "unknown default detector": Case(
        "  {dimension: 2, region: [[0, 10], [0, 10]]}\n",
        "  {dimension: 2, region: [[0, 10], [0, 10]],\n   default_detector: radar}\n",
        "default_detector:",
        "unknown detector 'radar'",
    ),
    "unknown filter type": Case(
        "type: kalman", "type: particle", "type: particle", "expected type 'kalman' or 'imm'"
    ),
    "duplicate key": Case(
        "  - name: Thing\n",
        "  - name: Thing\n    name: Other\n",
        "name: Other",
        "key 'name' given twice",
    ),
}


def check_case(valid: str, fmt: str, case: Case) -> None:
    text = edited(valid, case.old, case.new)
    problems = problems_of(text, fmt)
    expected_line = line_of(text, case.at)
    matching = [p for p in problems if case.message in p.message]
    assert matching, f"no problem says {case.message!r}; got {[str(p) for p in problems]}"
    assert matching[0].line == expected_line, str(matching[0])
    assert matching[0].file == f"test.{fmt}"


def test_the_valid_texts_have_no_problems() -> None:
    assert problems_of(VALID_XML, "xml") == []
    assert problems_of(VALID_YAML, "yaml") == []


@pytest.mark.parametrize("case", XML_CASES.values(), ids=XML_CASES.keys())
def test_xml_problem_is_at_its_line(case: Case) -> None:
    check_case(VALID_XML, "xml", case)


@pytest.mark.parametrize("case", YAML_CASES.values(), ids=YAML_CASES.keys())
def test_yaml_problem_is_at_its_line(case: Case) -> None:
    check_case(VALID_YAML, "yaml", case)


def test_a_problem_in_a_multiline_matrix_is_at_its_row() -> None:
    text = edited(
        VALID_XML,
        "<matrix>0.04 0; 0 0.04</matrix>",
        "<matrix>\n        0.04 0\n        0 oops\n      </matrix>",
    )
    [problem] = problems_of(text, "xml")
    assert problem.line == line_of(text, "0 oops")
    assert problem.message == "expected a number, found 'oops'"


def test_an_attribute_on_its_own_line_is_located_there() -> None:
    text = edited(
        VALID_XML,
        '<detector name="camera" clutter_frequency="0.5"/>',
        '<detector\n    name="camera"\n    clutter_frequency="-2"/>',
    )
    [problem] = problems_of(text, "xml")
    assert problem.line == line_of(text, 'clutter_frequency="-2"')
    assert problem.message == "expected a number >= 0, found -2"


def test_all_problems_are_collected_in_line_order() -> None:
    text = edited(VALID_XML, "<matrix>0.5 0; 0 0.5</matrix>", "<matrix>-1 0; 0 1</matrix>")
    text = edited(text, "<class>Thing</class>", "<class>Thing</class>\n    <colour>red</colour>")
    text = edited(text, 'target="Thing"', 'target="Nowhere"')
    problems = problems_of(text, "xml")
    assert [p.line for p in problems] == [
        line_of(text, "<colour>"),
        line_of(text, "<matrix>-1 0"),
        line_of(text, 'target="Nowhere"'),
    ]


def test_every_pydantic_error_is_reported() -> None:
    text = edited(VALID_YAML, "clutter_frequency: 0.5", "clutter_frequency: -1")
    text = edited(text, "detection_frequency: 1.0", "detection_frequency: lots")
    text = edited(text, "max_distance: 0.5", "max_distance: 0")
    problems = problems_of(text, "yaml")
    assert [(p.line, p.message) for p in problems] == [
        (line_of(text, "detection_frequency"), "expected a number, found 'lots'"),
        (line_of(text, "max_distance"), "expected a number > 0, found 0"),
        (line_of(text, "clutter_frequency"), "expected a number >= 0, found -1"),
    ]


def test_paper_listing_1_as_printed_is_malformed_at_its_line() -> None:
    # Paper 002, Listing 1, verbatim: two top-level elements, unquoted attribute
    # values, a missing "/" in </motion_model> and a "<\object>" closing tag.
    listing = r"""<object>
<class>table</class>
<filter>
<type>Kalman filter</type>
<motion_model>zeroth order</motion_model>
<system_noise>
<matrix> ... </matrix>
</system_noise>
<measurement_noise>
<matrix> ... </matrix>
</measurement_noise>
</filter>
</object>
<object>
<class>human</class>
<appearance_model>
<appearance_relation target="door"
max_distance=0.5 frequency=0.1 />
</appearance_model>
...
<\object>"""
    [problem] = problems_of(listing, "xml")
    assert problem.line == 14  # the second top-level <object>
    assert problem.message.startswith("malformed XML: Extra content")
    inside_root = (
        "<knowledge>\n" + listing[listing.index("<object>\n<class>human") :] + "\n</knowledge>"
    )
    [problem] = problems_of(inside_root, "xml")
    assert problem.line == line_of(inside_root, "max_distance=0.5")
    assert "AttValue" in problem.message
    quoted = inside_root.replace("=0.5 frequency=0.1", '="0.5" frequency="0.1"')
    [problem] = problems_of(quoted, "xml")
    assert problem.line == line_of(quoted, "<\\object>")


def test_a_root_other_than_knowledge_is_named() -> None:
    [problem] = problems_of("<object>\n<class>x</class>\n</object>\n", "xml")
    assert problem.message == "expected the root element <knowledge>; found <object>"
    assert problem.line == 1


def test_malformed_yaml_is_at_its_line() -> None:
    text = edited(VALID_YAML, "is_a: [Thing]", "is_a: [Thing")
    [problem] = problems_of(text, "yaml")
    assert problem.message.startswith("malformed YAML")
    assert problem.line == line_of(text, "is_a: [Thing") + 1  # where the parser notices


def test_yaml_that_is_not_a_mapping_is_named() -> None:
    [problem] = problems_of("- a\n- b\n", "yaml")
    assert problem.message == "expected a mapping at the top; found a list"


def test_problem_text_is_file_colon_line() -> None:
    text = edited(VALID_YAML, "target: Thing", "target: Ghost")
    [problem] = problems_of(text, "yaml")
    assert str(problem) == (
        f"test.yaml:{line_of(text, 'Ghost')}: appearance relation of 'Mover' targets unknown "
        "class 'Ghost'; known classes: Mover, Thing (at classes.1.appearance.0.target)"
    )


@pytest.mark.parametrize(
    ("fields", "message"),
    [
        ("static: true\n    position: [1.0, 2.0, 3.0]", "position must have 2 coordinates"),
        ("position: [1.0, 2.0]", "set static: true"),
    ],
)
def test_a_static_detectors_position_is_checked(fields: str, message: str) -> None:
    """Issue 28's static detector: its position has the world's dimension and belongs to
    a static sensor, reported at its line."""
    from semwm.knowledge.loader import analyse_text

    text = (
        "world: {dimension: 2, region: [[0, 4], [0, 3]]}\n"
        "classes:\n  - name: Cup\n    detection_frequency: 2.0\n    new_frequency: 0.1\n"
        "    filter: {type: kalman, model: {motion_model: zeroth_order, "
        "system_noise: [[1.0e-6, 0], [0, 1.0e-6]]}}\n"
        "    measurement_noise: [[0.01, 0], [0, 0.01]]\n"
        "detectors:\n  - name: camera\n    clutter_frequency: 0.5\n    " + fields + "\n"
    )
    analysis = analyse_text(text, "yaml", "mine.yaml")
    assert analysis.knowledge is None
    problems = [str(p) for p in analysis.problems]
    assert any(message in p and p.startswith("mine.yaml:1") for p in problems), problems
