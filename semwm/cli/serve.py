"""``semwm serve``: run the HTTP service with uvicorn.

The service (``api``) is imported inside the command, so importing the command
line (or the core) does not import FastAPI.
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

from pydantic import ValidationError
from pydantic_core import ErrorDetails

from semwm.cli.common import (
    EXIT_INVALID,
    EXIT_USAGE,
    LOG_LEVELS,
    CommandError,
    Subparsers,
    require,
)
from semwm.knowledge.loader import UnknownFormatError, analyse_file


def add_serve_command(subparsers: Subparsers) -> argparse.ArgumentParser:
    """Add ``serve`` to the ``semwm`` command's sub-commands."""
    parser: argparse.ArgumentParser = subparsers.add_parser(
        "serve",
        help="run the HTTP service",
        description="Run the semwm HTTP service (OpenAPI at /docs). Every option can also be "
        "set from the environment: SEMWM_KNOWLEDGE, SEMWM_HOST, SEMWM_PORT, "
        "SEMWM_REORDER_WINDOW, SEMWM_HOLD, SEMWM_ORDER_TOLERANCE, SEMWM_MAX_BATCH, "
        "SEMWM_WRITE_BACK, SEMWM_TOKEN, "
        "SEMWM_TOKEN_FILE, SEMWM_READ_TOKEN, SEMWM_INSECURE, SEMWM_CORS_ORIGINS, "
        "SEMWM_ALLOWED_HOSTS (JSON lists), SEMWM_MAX_BODY, SEMWM_MAX_SOURCES, "
        "SEMWM_STUCK_AFTER, SEMWM_ENGINE, SEMWM_MQTT, SEMWM_MQTT_PREFIX, SEMWM_MQTT_WORLD_RATE, "
        "SEMWM_MQTT_CLIENT_ID, SEMWM_FOXGLOVE_PORT, SEMWM_LOG_FORMAT. "
        "The live world page is at /, its stream at /world/stream, Prometheus metrics at "
        "/metrics (docs/operations.md).",
    )
    parser.add_argument("--knowledge", type=Path, help="knowledge file (YAML or XML)")
    parser.add_argument(
        "--engine",
        choices=("python", "rust"),
        help="who runs the world model's numeric kernels (default python, or "
        "SEMWM_ENGINE; rust needs the built extension: docs/engines.md)",
    )
    parser.add_argument("--host", help="address to bind (default 127.0.0.1)")
    parser.add_argument("--port", type=int, help="port (default 8000; 0 picks a free one)")
    parser.add_argument("--reorder-window", type=float, help="seconds (default 0.5)")
    parser.add_argument(
        "--hold",
        type=float,
        help="seconds detections are held to be processed in time order without replay "
        "(default 0; about the sources' arrival jitter)",
    )
    parser.add_argument(
        "--order-tolerance",
        type=float,
        help="seconds: scans of different sources this close to the newest processed one "
        "are processed in arrival order instead of replayed (default 0.005; 0: strict "
        "time order)",
    )
    parser.add_argument("--max-batch", type=int, help="largest batch (default 10000)")
    parser.add_argument(
        "--write-back",
        action="store_true",
        default=None,
        help="write accepted class edits back to the knowledge file",
    )
    parser.add_argument(
        "--log-level",
        dest="serve_log_level",
        choices=LOG_LEVELS,
        default=None,
        help="server log level (default: semwm --log-level, else info)",
    )
    parser.add_argument(
        "--log-format",
        choices=("text", "json"),
        help="text (default) or json: one JSON object per log line",
    )
    parser.add_argument(
        "--foxglove",
        type=int,
        metavar="PORT",
        dest="foxglove_port",
        help='also stream the world to Foxglove on this port (pip install "semwm[foxglove]")',
    )
    add_persistence_options(parser)
    add_safety_options(parser)
    add_mqtt_options(parser)
    parser.set_defaults(func=run_serve)
    return parser


PERSISTENCE_OPTIONS = (
    "data_dir", "sync", "snapshot_every", "compact_every", "on_damage", "knowledge_from",
    "record",
)  # fmt: skip


def add_persistence_options(parser: argparse.ArgumentParser) -> None:
    """``--data-dir``, ``--sync``, ``--snapshot-every``, ``--compact-every``, ``--record``."""
    group = parser.add_argument_group("persistence and recording (docs/persistence.md)")
    group.add_argument(
        "--data-dir",
        type=Path,
        help="journal every accepted change here and restore the world from it on start",
    )
    group.add_argument(
        "--sync",
        choices=["always", "batch"],
        help="always: fsync before each answer (default); batch: a process crash loses "
        "nothing, a power loss the commits since the last checkpoint",
    )
    group.add_argument("--snapshot-every", type=int, help="records between snapshots (1000)")
    group.add_argument(
        "--compact-every", type=int, help="records kept in the database before archiving (100000)"
    )
    group.add_argument(
        "--on-damage",
        choices=["refuse", "truncate"],
        help="a data dir found damaged on start: refuse to start (default), or truncate "
        "to what is intact and serve it (the loss is on /health and /metrics)",
    )
    group.add_argument(
        "--knowledge-from",
        choices=["file", "journal"],
        help="the journal's knowledge (live edits) differs from --knowledge: apply the "
        "file, or keep the journal's (default: refuse to start, unless --write-back, "
        "which keeps the journal's and writes it to the file)",
    )
    group.add_argument(
        "--record", type=Path, help="record changes and published worlds to FILE.mcap"
    )


SAFETY_OPTIONS = (
    "token", "token_file", "read_token", "insecure", "cors_origins", "allowed_hosts",
    "max_body", "max_sources", "stuck_after", "max_client_connections", "stream_lifetime",
    "stream_send_timeout", "max_waiting", "replay_limit", "max_streams", "max_client_streams",
)  # fmt: skip


def add_safety_options(parser: argparse.ArgumentParser) -> None:
    """Who may change the world, browsers, hosts and limits (docs/api.md, "Safety")."""
    group = parser.add_argument_group("safety and limits (docs/api.md)")
    group.add_argument("--token", help="bearer token writes need (or SEMWM_TOKEN)")
    group.add_argument("--token-file", type=Path, help="file whose first line is the token")
    group.add_argument("--read-token", help="bearer token reads need (default: reads open)")
    group.add_argument(
        "--insecure",
        action="store_true",
        default=None,
        help="allow a non-loopback --host without a token",
    )
    group.add_argument(
        "--cors-origin",
        dest="cors_origins",
        action="append",
        help="web origin allowed to call the API from a browser (repeatable)",
    )
    group.add_argument(
        "--allowed-host",
        dest="allowed_hosts",
        action="append",
        help="Host header value accepted (repeatable; default loopback names and --host)",
    )
    group.add_argument("--max-body", type=int, help="largest request body, bytes (4 MiB)")
    group.add_argument("--max-sources", type=int, help="most distinct sources held (1000)")
    group.add_argument("--stuck-after", type=float, help="s before /ready says stuck (30)")
    group.add_argument(
        "--max-client-connections",
        type=int,
        help="connections one client address may hold (128; raise it behind a proxy)",
    )
    group.add_argument("--stream-lifetime", type=float, help="s before a /world/stream ends (3600)")
    group.add_argument(
        "--max-streams", type=int, help="/world/stream responses open at once; one more: 503 (64)"
    )
    group.add_argument(
        "--max-client-streams",
        type=int,
        help="/world/stream responses one client address may hold; one more: 429 (8)",
    )
    group.add_argument(
        "--stream-send-timeout",
        type=float,
        help="s a /world/stream client may read nothing before it is dropped (10)",
    )
    group.add_argument(
        "--max-waiting",
        type=int,
        help="writes waiting for the world beyond which new ones get 503 + Retry-After (64)",
    )
    group.add_argument(
        "--replay-limit",
        type=float,
        help="share of the last second the world may spend replaying before late scans are "
        "refused (409) instead of replayed (0.1; 1: always replay)",
    )


MQTT_OPTIONS = ("mqtt", "mqtt_prefix", "mqtt_world_rate", "mqtt_client_id")


def add_mqtt_options(parser: argparse.ArgumentParser) -> None:
    """``--mqtt URL``, ``--mqtt-prefix``, ``--mqtt-world-rate``, ``--mqtt-client-id``."""
    group = parser.add_argument_group("MQTT bridge (pip install 'semwm[mqtt]'; docs/mqtt.md)")
    group.add_argument("--mqtt", metavar="URL", help="join the broker at mqtt://HOST:PORT")
    group.add_argument("--mqtt-prefix", metavar="P", help="topic prefix (default semwm)")
    group.add_argument(
        "--mqtt-world-rate", type=float, metavar="HZ", help="most world messages/s (default 10)"
    )
    group.add_argument(
        "--mqtt-client-id", metavar="ID", help="persistent session id (semwm-bridge-<prefix>)"
    )


def _setting_problem(problem: ErrorDetails) -> str:
    """One settings error as ``--option: message`` (pydantic's "Value error, " dropped;
    a whole-settings check names no option)."""
    message = problem["msg"].removeprefix("Value error, ")
    if not problem["loc"]:
        return message
    return f"--{str(problem['loc'][0]).replace('_', '-')}: {message}"


def _check_knowledge(path: Path) -> None:
    """The knowledge file's problems as ``knowledge validate`` prints them (one
    ``FILE:LINE: message`` line each, on stderr) and a :class:`CommandError`; before
    the server starts, so a mistake in the file is no startup traceback."""
    try:
        analysis = analyse_file(path)
    except OSError as error:
        raise CommandError(f"{path}: {error.strerror or error}", EXIT_INVALID) from None
    except UnknownFormatError as error:
        raise CommandError(str(error), EXIT_INVALID) from None
    if analysis.knowledge is None:
        for problem in analysis.problems:
            print(problem, file=sys.stderr)
        count = len(analysis.problems)
        raise CommandError(
            f"{path}: {count} problem{'' if count == 1 else 's'} (above); the server did not start",
            EXIT_INVALID,
        )


def run_serve(args: argparse.Namespace) -> int:
    """Start uvicorn with the settings from ``args`` over the environment."""
    import uvicorn

    from api.app import create_app
    from api.logs import logging_config
    from api.server import Server
    from api.settings import Settings

    given = {
        key: getattr(args, key)
        for key in (
            "knowledge",
            "engine",
            "host",
            "port",
            "reorder_window",
            "hold",
            "order_tolerance",
            "max_batch",
            "write_back",
            "foxglove_port",
            "log_format",
            *PERSISTENCE_OPTIONS,
            *SAFETY_OPTIONS,
            *MQTT_OPTIONS,
        )
        if getattr(args, key, None) is not None
    }
    try:
        settings = Settings(**given)
    except ValidationError as error:
        problems = "; ".join(_setting_problem(problem) for problem in error.errors())
        raise CommandError(problems, EXIT_USAGE) from None
    if settings.knowledge is None:
        raise CommandError("no knowledge file: pass --knowledge FILE or set SEMWM_KNOWLEDGE")
    from semwm.filters.engine import ENGINE_ENV, EngineUnavailable, resolve_engine

    try:
        engine = resolve_engine(settings.engine)
    except EngineUnavailable as error:
        raise CommandError(str(error), EXIT_USAGE) from None
    # every world model this process builds (a data directory's restore and replay
    # too) runs the same engine
    os.environ[ENGINE_ENV] = engine
    if not settings.knowledge.is_file():
        raise CommandError(f"{settings.knowledge}: no such file")
    _check_knowledge(settings.knowledge)
    if (refusal := settings.bind_problem()) is not None:
        raise CommandError(refusal, EXIT_USAGE)
    if settings.mqtt is not None:
        require("mqtt", "--mqtt")
    if settings.foxglove_port is not None:
        require("foxglove", "--foxglove")
    if settings.record is not None:
        require("mcap", "--record")
        if not settings.record.parent.is_dir():
            raise CommandError(
                f"--record {settings.record}: no such folder {settings.record.parent}/"
            )
    if (
        settings.data_dir is not None
        and settings.data_dir.exists()
        and not settings.data_dir.is_dir()
    ):
        raise CommandError(f"--data-dir {settings.data_dir}: exists and is not a folder")
    log_level = args.serve_log_level or getattr(args, "log_level", None) or "info"
    app = create_app(settings)
    config = uvicorn.Config(
        app,
        **settings.uvicorn_options(),
        log_config=logging_config(settings.log_format, log_level),
        access_log=False,  # api.logs writes the access log, with request ids
    )
    Server(config, app).run()  # ends open /world/stream responses first on shutdown
    return 0
