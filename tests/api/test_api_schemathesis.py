"""Schemathesis, stateful, against the real server: no 5xx, no response outside the
schema, and after every step the world answers and /health agrees with it.

The state machine chains calls along the OpenAPI document's links (api/openapi_links.py):
an object id from ``GET /world`` in ``GET /world/objects/{id}``, a class read from
``/knowledge`` written back and detected, ``POST /reset`` then the world.
"""

from __future__ import annotations

import shutil
from collections import Counter
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import httpx
import pytest
import schemathesis
from hypothesis import HealthCheck, settings
from schemathesis.checks import not_a_server_error
from schemathesis.generation.stateful.state_machine import StepInput
from schemathesis.specs.openapi.checks import (
    response_schema_conformance,
    status_code_conformance,
)

from api.app import create_app
from api.openapi_links import LINKS, add_links
from api.settings import Settings
from api.testing import running_server

# Data the schema calls valid may still be refused (an unknown class name, a time the
# reorder window is past): the checks are no 5xx and every answer within the schema.
CHECKS = [not_a_server_error, status_code_conformance, response_schema_conformance]
SIM1 = Path(__file__).parents[2] / "knowledge" / "sim1.yaml"
# Three scans of a Cup and a Table: both are objects of GET /world after them.
SEED = [
    {
        "detections": [
            {"time": t, "class": "Cup", "position": [1.0, 2.0]},
            {"time": t, "class": "Table", "position": [3.0, 1.0]},
        ]
    }
    for t in (0.0, 0.5, 1.0)
]


@pytest.fixture
def url(tmp_path: Path) -> Iterator[str]:
    path = tmp_path / "sim1.yaml"
    shutil.copy(SIM1, path)
    with running_server(Settings(knowledge=path, port=0)) as base:
        yield base


def test_stateful_run_follows_the_links_finds_no_5xx_and_keeps_the_invariants(url: str) -> None:
    schema = schemathesis.openapi.from_url(f"{url}/openapi.json")
    machine = schema.as_state_machine()
    # Links of the document (not schemathesis' inferred ones) whose values were used.
    followed: Counter[str] = Counter()
    resets: list[int] = []

    class Checked(machine):  # type: ignore[misc, valid-type]
        def setup(self) -> None:
            """Each scenario starts from a reset world holding two objects, so the ids
            GET /world answers are real and its link to an object has one to follow."""
            super().setup()
            assert httpx.post(f"{url}/reset", timeout=30).status_code == 200
            for body in SEED:
                assert httpx.post(f"{url}/detections", json=body, timeout=30).status_code == 200

        def step(self, input):  # type: ignore[no-untyped-def]
            output = super().step(input)
            if _follows_a_document_link(input):
                followed[input.transition.id] += 1
            return output

        def validate_response(self, response, case, **kwargs):  # type: ignore[no-untyped-def]
            assert response.status_code < 500, (case.method, case.path, response.text)
            case.validate_response(response, checks=CHECKS)

        def after_call(self, response, case):  # type: ignore[no-untyped-def]
            super().after_call(response, case)
            world = httpx.get(f"{url}/world", timeout=30)
            health = httpx.get(f"{url}/health", timeout=30)
            assert world.status_code == 200 and health.status_code == 200
            assert world.json()["time"] == health.json()["time"]
            if (case.method, case.path) == ("POST", "/reset") and response.status_code == 200:
                assert world.json() == {"time": None, "objects": []}
                assert health.json()["objects"] == 0
                resets.append(health.json()["commit"])

    Checked.TestCase.settings = settings(
        max_examples=15,
        stateful_step_count=8,
        deadline=None,
        derandomize=True,
        suppress_health_check=list(HealthCheck),
    )
    Checked.TestCase().runTest()
    assert followed, "no link of the OpenAPI document was followed"
    assert all(" -> [200] " in name for name in followed), followed
    assert resets, "no POST /reset was checked"


def _follows_a_document_link(input: StepInput) -> bool:
    """Whether the step is a link of the document (not an inferred one) whose values
    were used: every path parameter (an id, a class name) and anything else it gives."""
    transition = input.transition
    if transition is None or transition.is_inferred or not input.is_applied:
        return False
    applied = {name for _, name in input.applied_parameters}
    return all(name in applied for name in transition.parameters.get("path_parameters", {}))


def _document() -> dict[str, Any]:
    return create_app(Settings()).openapi()


def test_the_document_carries_valid_links_to_operations_that_exist() -> None:
    document = _document()
    schemathesis.openapi.from_dict(document).validate()  # the OpenAPI 3.1 meta-schema
    operations = {
        op["operationId"]: op for path in document["paths"].values() for op in path.values()
    }
    assert len(operations) == sum(len(path) for path in document["paths"].values())
    found = {}
    for source, op in operations.items():
        for status, response in op["responses"].items():
            for name, link in response.get("links", {}).items():
                found[(source, status, name)] = link["operationId"]
                target = operations[link["operationId"]]
                names = {(p["in"], p["name"]) for p in target.get("parameters", [])}
                for parameter in link.get("parameters", {}):
                    location, _, pname = parameter.partition(".")
                    assert (location, pname) in names, (source, name, parameter)
    assert found == {
        (source, status, name): link["operationId"]
        for (source, status), named in LINKS.items()
        for name, link in named.items()
    }
    assert found[("get_world", "200", "GetObject")] == "get_object"
    assert found[("post_detections", "200", "GetWorld")] == "get_world"
    assert found[("put_class", "200", "GetClass")] == "get_class"
    assert found[("reset", "200", "GetWorld")] == "get_world"


def test_a_link_to_an_operation_the_document_lacks_is_an_error() -> None:
    document = _document()
    with pytest.raises(ValueError, match="no operation 'delete_class'"):
        add_links(document, {("get_class", "200"): {"Delete": {"operationId": "delete_class"}}})
    with pytest.raises(ValueError, match="no 201 response"):
        add_links(document, {("get_class", "201"): {}})
