"""Markers of the persistence tests."""

from __future__ import annotations

import pytest


def pytest_configure(config: pytest.Config) -> None:
    config.addinivalue_line(
        "markers", "slow: a fault-injection test of several seconds (runs in CI all the same)"
    )
