"""Schemathesis, stateful, against the real server: no 5xx, no response outside the
schema, and after every step the world answers and /health agrees with it."""

from __future__ import annotations

import shutil
from collections.abc import Iterator
from pathlib import Path

import httpx
import pytest
import schemathesis
from hypothesis import HealthCheck, settings
from schemathesis.checks import not_a_server_error
from schemathesis.specs.openapi.checks import (
    response_schema_conformance,
    status_code_conformance,
)

from api.settings import Settings
from api.testing import running_server

# Data the schema calls valid may still be refused (an unknown class name, a time the
# reorder window is past): the checks are no 5xx and every answer within the schema.
CHECKS = [not_a_server_error, status_code_conformance, response_schema_conformance]
SIM1 = Path(__file__).parents[2] / "knowledge" / "sim1.yaml"


@pytest.fixture
def url(tmp_path: Path) -> Iterator[str]:
    path = tmp_path / "sim1.yaml"
    shutil.copy(SIM1, path)
    with running_server(Settings(knowledge=path, port=0)) as base:
        yield base


def test_stateful_run_finds_no_5xx_and_keeps_the_invariants(url: str) -> None:
    schema = schemathesis.openapi.from_url(f"{url}/openapi.json")
    machine = schema.as_state_machine()

    class Checked(machine):  # type: ignore[misc, valid-type]
        def validate_response(self, response, case, **kwargs):  # type: ignore[no-untyped-def]
            assert response.status_code < 500, (case.method, case.path, response.text)
            case.validate_response(response, checks=CHECKS)

        def after_call(self, response, case):  # type: ignore[no-untyped-def]
            world = httpx.get(f"{url}/world", timeout=30)
            health = httpx.get(f"{url}/health", timeout=30)
            assert world.status_code == 200 and health.status_code == 200
            assert world.json()["time"] == health.json()["time"]

    Checked.TestCase.settings = settings(
        max_examples=15,
        stateful_step_count=6,
        deadline=None,
        derandomize=True,
        suppress_health_check=list(HealthCheck),
    )
    Checked.TestCase().runTest()
