"""Fixtures shared by every test directory."""

from __future__ import annotations

import pytest

from semwm.filters.engine import ENGINES, Engine, rust_core, rust_core_error

_needs_rust = pytest.mark.skipif(
    rust_core() is None,
    reason=f"the Rust core semwm._core is not built ({rust_core_error()}); "
    "`pip install .` with cargo on PATH builds it (docs/engines.md)",
)


@pytest.fixture(params=[pytest.param(e, marks=_needs_rust if e == "rust" else ()) for e in ENGINES])
def engine(request: pytest.FixtureRequest) -> Engine:
    """Each engine in turn (``"python"``, ``"rust"``): for tests that must hold with both,
    as RapidFuzz and cbor2 run their suites over both implementations."""
    engine: Engine = request.param
    return engine
