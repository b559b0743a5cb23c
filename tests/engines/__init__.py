"""The Rust engine held to the Python engine (its specification)."""

import pytest

from semwm.filters.engine import rust_core, rust_core_error

#: Marks a test that needs the Rust core, with the reason it skips without it.
needs_rust = pytest.mark.skipif(
    rust_core() is None,
    reason=f"the Rust core semwm._core is not built ({rust_core_error()}); "
    "`pip install .` with cargo on PATH builds it (docs/engines.md)",
)
