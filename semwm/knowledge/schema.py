"""The JSON Schema of the YAML (and JSON) form of knowledge files.

``semwm/knowledge/schemas/knowledge.schema.json`` is generated from
:class:`KnowledgeDocument`; regenerate it after changing the model with::

    python -m semwm.knowledge.schema

Editors use it to complete and check YAML files (for example with the YAML
language server: ``# yaml-language-server: $schema=<path to the schema>``). The
XML form has its hand-written XML Schema beside it, ``knowledge.xsd``.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from semwm.knowledge.model import KnowledgeDocument

SCHEMA_DIRECTORY = Path(__file__).parent / "schemas"
JSON_SCHEMA_PATH = SCHEMA_DIRECTORY / "knowledge.schema.json"
XML_SCHEMA_PATH = SCHEMA_DIRECTORY / "knowledge.xsd"


def knowledge_json_schema() -> dict[str, Any]:
    """The JSON Schema of a knowledge document, with the file's key names (``class``)."""
    schema = KnowledgeDocument.model_json_schema(by_alias=True)
    schema["$schema"] = "https://json-schema.org/draft/2020-12/schema"
    schema["title"] = "semwm knowledge"
    return schema


def json_schema_text() -> str:
    """The schema as the committed file holds it."""
    return json.dumps(knowledge_json_schema(), indent=2, sort_keys=True) + "\n"


def write_json_schema(path: Path = JSON_SCHEMA_PATH) -> None:
    """Write the generated schema to ``path``."""
    path.write_text(json_schema_text(), encoding="utf-8")


if __name__ == "__main__":
    write_json_schema()
    print(f"wrote {JSON_SCHEMA_PATH}")
