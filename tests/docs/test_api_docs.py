"""docs/api.md's hypotheses section and the OpenAPI document: every field of the
world and hypotheses answers is described, and the page's example is today's."""

from __future__ import annotations

from pathlib import Path

import pytest

from api.app import create_app
from api.settings import Settings
from semwm import WorldModel, load_knowledge
from semwm.knowledge.shipped import shipped_knowledge_path

ROOT = Path(__file__).resolve().parents[2]
API_MD = (ROOT / "docs" / "api.md").read_text(encoding="utf-8")


@pytest.fixture(scope="module")
def openapi() -> dict[str, object]:
    app = create_app(Settings(knowledge=shipped_knowledge_path("sim1.yaml")))
    document: dict[str, object] = app.openapi()  # what GET /openapi.json serves
    return document


@pytest.mark.parametrize(
    "schema", ["WorldObjectOut", "HypothesisObjectOut", "HypothesisOut", "HypothesesOut"]
)
def test_every_field_of_the_answers_is_described(openapi: dict[str, object], schema: str) -> None:
    schemas = openapi["components"]["schemas"]  # type: ignore[index]
    properties = schemas[schema]["properties"]
    undescribed = [name for name, field in properties.items()
                   if "description" not in field and "$ref" not in field
                   and name not in ("objects", "hypotheses", "confidence")]  # fmt: skip
    assert undescribed == [], f"{schema}: {undescribed}"
    if schema == "HypothesisObjectOut":
        assert "null" in properties["id"]["description"]
        assert "lineage" in properties["track"]["description"]


def test_every_answer_semwm_defines_describes_its_fields(openapi: dict[str, object]) -> None:
    """Every property of every response schema of semwm's own (not FastAPI's
    HTTPValidationError, nor the knowledge document: docs/knowledge.md)."""
    schemas = openapi["components"]["schemas"]  # type: ignore[index]
    answers = set()
    for operations in openapi["paths"].values():  # type: ignore[attr-defined]
        for operation in operations.values():
            for response in operation.get("responses", {}).values():
                schema = response.get("content", {}).get("application/json", {}).get("schema", {})
                for ref in [schema.get("$ref"), *[s.get("$ref") for s in schema.get("anyOf", [])]]:
                    if ref:
                        answers.add(ref.split("/")[-1])
    answers -= {"HTTPValidationError", "KnowledgeDocument"}
    assert {"WorldOut", "HypothesesOut", "HealthOut", "SourcesOut"} <= answers
    undescribed = {
        name: [key for key, field in schemas[name].get("properties", {}).items()
               if "description" not in field]
        for name in sorted(answers)
    }  # fmt: skip
    assert {name: keys for name, keys in undescribed.items() if keys} == {}


def test_the_hypotheses_table_names_every_field() -> None:
    section = API_MD[API_MD.index("### Hypotheses") : API_MD.index("### Confidence and existence")]
    for field in ("`id`", "`track`", "`class`, `label`", "`position`", "`existence`"):
        assert f"| {field} |" in section, field
    assert "**`null`**" in section


def test_the_hypotheses_example_is_what_semwm_gives() -> None:
    wm = WorldModel(load_knowledge(ROOT / "knowledge" / "sim1.yaml"))
    wm.ingest([{"time": 0.0, "class": "Cup", "position": [1.0, 2.0], "source": "camera"}])
    wm.ingest([{"time": 0.5, "class": "Cup", "position": [1.0, 2.0], "source": "camera"}])
    best, second = wm.hypotheses(2)
    assert round(best.probability, 2) == 0.98 and round(second.probability, 2) == 0.02
    (cup,) = best.objects
    assert (cup.id, cup.track, round(cup.existence, 2)) == (1, 0, 1.0)
    old, new = second.objects
    assert (old.id, old.track, round(old.existence, 2)) == (1, 0, 0.04)
    assert (new.id, new.track) == (None, 1)
    section = API_MD[API_MD.index("### Hypotheses") : API_MD.index("### Confidence and existence")]
    assert "probability 0.98" in section and "(0.02)" in section and "(existence 0.04)" in section


def test_the_readme_names_only_routes_the_service_has() -> None:
    import re

    app = create_app(Settings(knowledge=shipped_knowledge_path("sim1.yaml")))
    routes = {*app.openapi()["paths"], "/", "/docs", "/redoc"}
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    named = set(re.findall(r"`(?:GET |POST |PUT )?(/[a-z_/{}A-Z]*)[`?]", readme))
    named |= set(re.findall(r"localhost:8000(/[a-z_/]+)", readme))
    assert named, "the README names no route"
    patterns = [re.compile(re.sub(r"\{[^}]+\}", "[^/]+", r.rstrip("/")) + "/?") for r in routes]
    missing = sorted(path for path in named if not any(p.fullmatch(path) for p in patterns))
    assert missing == [], f"README names routes the service has not: {missing}"
