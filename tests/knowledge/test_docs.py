"""The examples in docs/knowledge.md load, and their XML and YAML say the same."""

from __future__ import annotations

import re
from pathlib import Path

from semwm.knowledge.loader import knowledge_from_text

DOC = Path(__file__).resolve().parents[2] / "docs" / "knowledge.md"


def example(language: str) -> str:
    blocks = re.findall(rf"```{language}\n(.*?)```", DOC.read_text(encoding="utf-8"), re.DOTALL)
    [block] = [b for b in blocks if "<knowledge>" in b or "classes:" in b]
    return str(block)


def test_the_documented_xml_and_yaml_examples_are_the_same_knowledge() -> None:
    from_xml = knowledge_from_text(example("xml"), "xml", "docs-xml")
    from_yaml = knowledge_from_text(example("yaml"), "yaml", "docs-yaml")
    assert from_xml.document == from_yaml.document
    child = from_yaml.classes["Child"]
    assert child.filter == from_yaml.classes["Person"].filter
    assert child.max_position_variance == 0.5
