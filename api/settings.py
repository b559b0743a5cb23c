"""Service settings: command-line options and ``SEMWM_*`` environment variables."""

from __future__ import annotations

import importlib.util
import ipaddress
from pathlib import Path
from typing import Annotated, Any, Literal

from pydantic import Field, SecretStr, field_validator, model_validator
from pydantic_settings import BaseSettings, SettingsConfigDict

from semwm.mqtt.protocol import check_topic_part, parse_broker_url
from semwm.sources import DEFAULT_ORDER_TOLERANCE

LOOPBACK_NAMES = ("127.0.0.1", "localhost", "::1", "[::1]")
MiB = 1024 * 1024


def is_loopback(host: str) -> bool:
    """Whether binding ``host`` keeps the service on this machine."""
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host.strip("[]")).is_loopback
    except ValueError:
        return False


class Settings(BaseSettings):
    """What the service needs to start.

    Every field can be set from an environment variable named ``SEMWM_<FIELD>``
    (``SEMWM_KNOWLEDGE``, ``SEMWM_PORT``, ...); values given to the constructor
    (the command line) win over the environment. Lists are JSON in the environment
    (``SEMWM_CORS_ORIGINS='["http://robot.local:3000"]'``).

    Attributes
    ----------
    knowledge
        The knowledge file (YAML or XML) the world model is built from.
    host, port
        Where to listen. Loopback by default.
    reorder_window
        Detections up to this many seconds older than the latest processed one are
        still accepted (re-ordered); older ones are refused with 409.
    hold
        Detections newer than the newest accepted one minus ``hold`` (s) are held and
        processed in time order once older: arrivals out of order by less than the
        hold cost no replay (queries still include them). 0: process at once. About
        the sources' arrival jitter (docs/operations.md).
    order_tolerance
        Scans of different sources at most this many seconds older than the newest
        processed scan are processed in arrival order (their time moved just after
        it) instead of replayed; 0: strict time order (docs/operations.md).
    max_batch
        The largest batch ``POST /detections`` accepts.
    max_ahead, max_jump
        Time guards (s): a detection may be at most ``max_ahead`` ahead of the service
        clock, and a source's time may advance at most ``max_jump`` more than the
        service clock did since its previous detection; else 422 (see ``GET /sources``).
    write_back
        Write accepted ``PUT /knowledge/classes/{name}`` edits back to the knowledge
        file (atomically).
    data_dir, sync, snapshot_every, compact_every
        Persistence (docs/persistence.md): journal every accepted change in
        ``data_dir`` and restore the world from it on start; ``always`` commits
        with an fsync before answering, ``batch`` without (a power loss can lose
        the last commits); a snapshot every ``snapshot_every`` records; records
        beyond ``compact_every`` move to archives.
    on_damage
        A data directory found damaged on start (docs/persistence.md, "Damage"):
        ``refuse`` to start (the default: the message says what was lost), or
        ``truncate`` to serve what is intact (``/health`` shows what was lost).
    knowledge_from
        With a data directory whose journal's knowledge (live edits) differs from the
        knowledge file: ``file`` applies the file (refused if tracked objects hold
        classes it lacks), ``journal`` keeps the journal's. ``None`` (the default):
        with ``write_back`` the journal's is kept and written to the file; without,
        the service refuses to start and names the classes that differ.
    record
        Record every accepted change and published world to this MCAP file.
    token, token_file
        The bearer token every write (POST, PUT) needs; ``token_file`` holds it on its
        first line. ``None``: writes are open to whoever reaches the port.
    read_token
        A bearer token the reads need (the write token also reads). ``None``: reads
        are open.
    insecure
        Allow binding a non-loopback address without a token.
    cors_origins
        Web origins (``scheme://host[:port]``) allowed to call the API from a browser.
        Empty: CORS off, and a write from any other origin is refused with 403.
    allowed_hosts
        ``Host`` header values accepted (DNS rebinding guard); ``*`` accepts any.
        Default: the loopback names and ``host``.
    max_body
        The largest request body (bytes); larger ones are refused with 413 before
        they are read whole.
    max_sources
        The most distinct detection sources held in memory (a new one beyond: 422).
    idempotency_keys
        How many recent ``Idempotency-Key``/``batch_id`` values are remembered.
    stuck_after
        ``/ready`` answers 503 while one request has held the world for longer (s).
    timeout_keep_alive, limit_concurrency
        uvicorn: idle keep-alive connections are closed after this many seconds;
        beyond this many connections at once new ones get 503 (slow clients cannot
        hold every worker).
    timeout_request
        A connection must send a request's complete headers and body within this
        many seconds of opening (or of the previous response), else it is closed:
        idle, byte-by-byte (slowloris) or slow-body clients cannot fill
        ``limit_concurrency``. ``GET /health`` and ``/ready`` are served past it.
    max_client_connections
        Connections one client (peer address) may hold; one more is answered 503
        and closed (a proxy in front makes every client one: raise it there).
    max_waiting
        Writes waiting for the world beyond which a new one is answered 503 with
        ``Retry-After`` at once (the service fell behind; docs/api.md, "Overload").
    replay_limit
        The share of the last second the world may spend replaying scans (0-1) above
        which the service is behind: a late scan is then refused (409) instead of
        replayed (1: always replayed; docs/api.md, "Overload").
    max_streams, max_client_streams
        ``GET /world/stream`` responses open at once, in all and per client (peer
        address); one more is refused with ``Retry-After``: 503 beyond the first,
        429 beyond the second (each holds a connection slot for up to
        ``stream_lifetime``).
    stream_lifetime, stream_send_timeout
        A ``GET /world/stream`` ends after ``stream_lifetime`` s (an ``EventSource``
        reconnects by itself); a client that does not read one frame for
        ``stream_send_timeout`` s is dropped.
    http
        uvicorn's HTTP/1.1 implementation: ``httptools`` (C parser, less CPU per
        request), ``h11`` (pure Python), or ``auto``: httptools when installed.
    mqtt, mqtt_prefix, mqtt_world_rate, mqtt_client_id
        Join the MQTT broker at ``mqtt://HOST:PORT`` (see docs/mqtt.md): detections
        in on ``<prefix>/detections/<source>``, the world out on ``<prefix>/world`` at
        most ``mqtt_world_rate`` times a second; the client id names the bridge's
        persistent session (default ``semwm-bridge-<prefix>``).
    foxglove_port
        Also stream the world to Foxglove on this port (``foxglove`` extra); 0 picks one.
    log_format
        ``text`` or ``json`` (one JSON object per line), for the service's logs.
    engine
        ``python`` or ``rust``: who runs the world model's numeric kernels
        (docs/engines.md); ``None``: the default, ``python``. ``rust`` needs the built
        extension ``semwm._core``.
    stage_timing
        Time every accepted ``POST /detections`` by stage (read, parse, lock, the world
        model, respond...) and export the sums in ``/metrics``
        (``semwm_ingest_stage_seconds``; :mod:`api.stages`). About 10 µs per request.
    """

    model_config = SettingsConfigDict(env_prefix="SEMWM_", frozen=True, extra="ignore")

    knowledge: Path | None = None
    engine: Literal["python", "rust"] | None = None
    host: str = "127.0.0.1"
    port: Annotated[int, Field(ge=0, le=65535)] = 8000
    reorder_window: Annotated[float, Field(ge=0.0, allow_inf_nan=False)] = 0.5
    hold: Annotated[float, Field(ge=0.0, le=60.0, allow_inf_nan=False)] = 0.0
    order_tolerance: Annotated[float, Field(ge=0.0, le=1.0, allow_inf_nan=False)] = (
        DEFAULT_ORDER_TOLERANCE
    )
    max_batch: Annotated[int, Field(ge=1)] = 10000
    write_back: bool = False
    data_dir: Path | None = None
    sync: Literal["always", "batch"] = "always"
    snapshot_every: Annotated[int, Field(ge=1)] = 1000
    compact_every: Annotated[int, Field(ge=1)] = 100_000
    on_damage: Literal["refuse", "truncate"] = "refuse"
    knowledge_from: Literal["file", "journal"] | None = None
    record: Path | None = None
    max_ahead: Annotated[float, Field(ge=0.0, allow_inf_nan=False)] = 10.0
    max_jump: Annotated[float, Field(ge=0.0, allow_inf_nan=False)] = 60.0
    token: SecretStr | None = None
    token_file: Path | None = None
    read_token: SecretStr | None = None
    insecure: bool = False
    cors_origins: tuple[str, ...] = ()
    allowed_hosts: tuple[str, ...] | None = None
    max_body: Annotated[int, Field(ge=1024)] = 4 * MiB
    max_sources: Annotated[int, Field(ge=1)] = 1000
    idempotency_keys: Annotated[int, Field(ge=0)] = 1024
    stuck_after: Annotated[float, Field(gt=0.0, allow_inf_nan=False)] = 30.0
    timeout_keep_alive: Annotated[float, Field(gt=0.0, allow_inf_nan=False)] = 5.0
    limit_concurrency: Annotated[int, Field(ge=1)] = 256
    timeout_request: Annotated[float, Field(gt=0.0, allow_inf_nan=False)] = 10.0
    max_client_connections: Annotated[int, Field(ge=1)] = 128
    max_waiting: Annotated[int, Field(ge=1)] = 64
    replay_limit: Annotated[float, Field(gt=0.0, le=1.0, allow_inf_nan=False)] = 0.1
    max_streams: Annotated[int, Field(ge=1)] = 64
    max_client_streams: Annotated[int, Field(ge=1)] = 8
    stream_lifetime: Annotated[float, Field(gt=0.0, allow_inf_nan=False)] = 3600.0
    stream_send_timeout: Annotated[float, Field(gt=0.0, allow_inf_nan=False)] = 10.0
    http: Literal["auto", "h11", "httptools"] = "auto"
    stage_timing: bool = False

    @model_validator(mode="after")
    def _read_token_file(self) -> Settings:
        if self.token is None and self.token_file is not None:
            try:
                lines = self.token_file.read_text(encoding="utf-8").splitlines()
            except (OSError, UnicodeDecodeError) as error:
                raise ValueError(f"cannot read the token file {self.token_file}: {error}") from None
            first = lines[0].strip() if lines else ""
            if not first:
                raise ValueError(f"the token file {self.token_file} is empty")
            object.__setattr__(self, "token", SecretStr(first))
        for name in ("token", "read_token"):
            secret = getattr(self, name)
            if secret is not None and len(secret.get_secret_value()) < 8:
                raise ValueError(f"{name} must have at least 8 characters")
        return self

    def hosts(self) -> list[str]:
        """The ``Host`` header values accepted."""
        if self.allowed_hosts is not None:
            return list(self.allowed_hosts)
        return list(dict.fromkeys([*LOOPBACK_NAMES, self.host]))

    def uvicorn_options(self) -> dict[str, Any]:
        """Where uvicorn listens and its limits against slow or too many clients."""
        from api.protocol import with_header_deadline

        return {
            "host": self.host,
            "port": self.port,
            "timeout_keep_alive": self.timeout_keep_alive,
            "limit_concurrency": self.limit_concurrency,
            "h11_max_incomplete_event_size": 64 * 1024,
            "http": with_header_deadline(
                self.timeout_request, self.http, self.max_client_connections
            ),
        }

    def bind_problem(self) -> str | None:
        """Why ``host`` must not be bound with these settings, or ``None``."""
        if is_loopback(self.host) or self.token is not None or self.insecure:
            return None
        return (
            f"refusing to bind {self.host} (not loopback) without a token: anyone who "
            "reaches the port could change the world. Pass --token/--token-file (or "
            "SEMWM_TOKEN), or --insecure to do it anyway"
        )

    mqtt: str | None = None
    mqtt_prefix: str = "semwm"
    mqtt_world_rate: Annotated[float, Field(gt=0.0)] = 10.0
    mqtt_client_id: Annotated[str | None, Field(min_length=1)] = None

    @field_validator("engine", mode="before")
    @classmethod
    def _engine_name(cls, value: object) -> object:
        return value.strip().lower() if isinstance(value, str) else value

    @field_validator("http")
    @classmethod
    def _http_installed(cls, value: str) -> str:
        if value == "httptools" and importlib.util.find_spec("httptools") is None:
            raise ValueError("http 'httptools' needs the httptools package: pip install httptools")
        return value

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

    foxglove_port: Annotated[int, Field(ge=0, le=65535)] | None = None
    log_format: Literal["text", "json"] = "text"
