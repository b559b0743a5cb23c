"""Service settings: command-line options and ``SEMWM_*`` environment variables."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Literal

from pydantic import Field, field_validator
from pydantic_settings import BaseSettings, SettingsConfigDict

from semwm.mqtt.protocol import check_topic_part, parse_broker_url


class Settings(BaseSettings):
    """What the service needs to start.

    Every field can be set from an environment variable named ``SEMWM_<FIELD>``
    (``SEMWM_KNOWLEDGE``, ``SEMWM_PORT``, ...); values given to the constructor
    (the command line) win over the environment.

    Attributes
    ----------
    knowledge
        The knowledge file (YAML or XML) the world model is built from.
    host, port
        Where to listen. Loopback by default: the API has no authentication.
    reorder_window
        Detections up to this many seconds older than the latest processed one are
        still accepted (re-ordered); older ones are refused with 409.
    max_batch
        The largest batch ``POST /detections`` accepts.
    write_back
        Write accepted ``PUT /knowledge/classes/{name}`` edits back to the knowledge
        file (atomically).
    data_dir, sync, snapshot_every, compact_every
        Persistence (docs/persistence.md): journal every accepted change in
        ``data_dir`` and restore the world from it on start; ``always`` commits
        with an fsync before answering, ``batch`` without (a power loss can lose
        the last commits); a snapshot every ``snapshot_every`` records; records
        beyond ``compact_every`` move to archives.
    record
        Record every accepted change and published world to this MCAP file.
    mqtt, mqtt_prefix, mqtt_world_rate, mqtt_client_id
        Join the MQTT broker at ``mqtt://HOST:PORT`` (see docs/mqtt.md): detections
        in on ``<prefix>/detections/<source>``, the world out on ``<prefix>/world`` at
        most ``mqtt_world_rate`` times a second; the client id names the bridge's
        persistent session (default ``semwm-bridge-<prefix>``).
    """

    model_config = SettingsConfigDict(env_prefix="SEMWM_", frozen=True, extra="ignore")

    knowledge: Path | None = None
    host: str = "127.0.0.1"
    port: Annotated[int, Field(ge=0, le=65535)] = 8000
    reorder_window: Annotated[float, Field(ge=0.0, allow_inf_nan=False)] = 0.5
    max_batch: Annotated[int, Field(ge=1)] = 10000
    write_back: bool = False
    data_dir: Path | None = None
    sync: Literal["always", "batch"] = "always"
    snapshot_every: Annotated[int, Field(ge=1)] = 1000
    compact_every: Annotated[int, Field(ge=1)] = 100_000
    record: Path | None = None
    mqtt: str | None = None
    mqtt_prefix: str = "semwm"
    mqtt_world_rate: Annotated[float, Field(gt=0.0)] = 10.0
    mqtt_client_id: Annotated[str | None, Field(min_length=1)] = None

    @field_validator("mqtt")
    @classmethod
    def _broker_url(cls, value: str | None) -> str | None:
        if value is not None:
            parse_broker_url(value)
        return value

    @field_validator("mqtt_prefix")
    @classmethod
    def _topic_prefix(cls, value: str) -> str:
        check_topic_part("prefix", value, allow_slash=True)
        return value
