"""Fixtures of the MQTT tests: a world service on the shipped sim1 knowledge and a private
Mosquitto on a free loopback port (skipped, saying why, where it cannot run)."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest
from mqtt_helpers import KNOWLEDGE, RecordingService

from api.mqtt_testing import PrivateBroker, mosquitto_path
from semwm import WorldModel, load_knowledge


@pytest.fixture
def service() -> RecordingService:
    service = RecordingService(WorldModel(load_knowledge(KNOWLEDGE), reorder_window=5.0))
    service.applied = []
    return service


@pytest.fixture
def broker(tmp_path: Path) -> Iterator[PrivateBroker]:
    """A Mosquitto of this test only, with persistence (restartable on the same port)."""
    pytest.importorskip("paho.mqtt.client", reason='paho-mqtt missing: pip install ".[mqtt]"')
    if mosquitto_path() is None:
        pytest.skip(
            "mosquitto is not installed and could not be: apt-get install mosquitto "
            "(listed in .ci/apt-packages.txt)"
        )
    directory = tmp_path / "broker"
    directory.mkdir()
    broker = PrivateBroker(directory)
    broker.start()
    try:
        yield broker
    finally:
        broker.stop()
