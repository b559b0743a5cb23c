"""The examples in docs/knowledge.md load, and their XML and YAML say the same."""

from __future__ import annotations

import re
from pathlib import Path

from semwm.knowledge.loader import knowledge_from_text

DOC = Path(__file__).resolve().parents[2] / "docs" / "knowledge.md"


def blocks(language: str) -> list[str]:
    found = re.findall(rf"```{language}\n(.*?)```", DOC.read_text(encoding="utf-8"), re.DOTALL)
    return [str(b) for b in found if "<knowledge>" in b or "classes:" in b]


def example(language: str) -> str:
    """The annotated example (the one with a Child class)."""
    [block] = [b for b in blocks(language) if "Child" in b]
    return block


def test_the_datasheet_example_loads_without_warnings() -> None:
    from semwm.knowledge.loader import analyse_text

    [block] = [b for b in blocks("yaml") if "datasheet" in b or "recall" in b]
    analysis = analyse_text(block, "yaml", "datasheet")
    assert analysis.knowledge is not None, analysis.problems
    assert analysis.warnings == ()


def test_the_documented_xml_and_yaml_examples_are_the_same_knowledge() -> None:
    from_xml = knowledge_from_text(example("xml"), "xml", "docs-xml")
    from_yaml = knowledge_from_text(example("yaml"), "yaml", "docs-yaml")
    assert from_xml.document == from_yaml.document
    child = from_yaml.classes["Child"]
    assert child.filter == from_yaml.classes["Person"].filter
    assert child.max_position_variance == 0.5
