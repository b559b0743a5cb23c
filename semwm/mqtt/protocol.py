"""The MQTT protocol of semwm as pure values: topics, broker addresses, payloads, pacing.

Nothing here opens a socket or reads a clock; :mod:`semwm.mqtt.client` is the edge
that does, and ``api/mqtt_bridge.py`` joins it to the service.

Topics, under a configurable prefix (``semwm`` by default):

========================== ===== ===================================================
topic                      dir   payload
========================== ===== ===================================================
``P/detections/<source>``  in    the ``POST /detections`` body; ``<source>`` fills the
                                 ``source`` of detections that have none
``P/world``                out   the ``GET /world`` JSON, retained
``P/errors/<source>``      out   ``{"status": 422 or 409, "detail": ..., "topic"}``
``P/status``               out   the bridge's counters, retained; ``online: false`` is
                                 its last will
``P/local/<robot>``        out   a robot's local model, the ``GET /world`` JSON, retained
========================== ===== ===================================================
"""

from __future__ import annotations

import hashlib
import json
import math
from collections import OrderedDict
from dataclasses import dataclass
from typing import Any
from urllib.parse import urlsplit

DEFAULT_PORT = 1883


class PayloadError(ValueError):
    """A payload that is not JSON (or not UTF-8): the message says where it broke."""


@dataclass(frozen=True)
class Broker:
    """Where the broker listens, from ``mqtt://HOST[:PORT]``."""

    host: str
    port: int = DEFAULT_PORT

    @property
    def url(self) -> str:
        return f"mqtt://{self.host}:{self.port}"


def parse_broker_url(url: str) -> Broker:
    """``mqtt://HOST:PORT`` (port 1883 when omitted) as a :class:`Broker`.

    Raises
    ------
    ValueError
        Naming the part of ``url`` that is wrong: another scheme, no host, a port
        that is not a number in 1..65535, or a path, query or user name (unsupported).
    """
    parts = urlsplit(url)
    if parts.scheme != "mqtt":
        raise ValueError(f"broker URL must start with mqtt://; got {url!r}")
    try:
        port = parts.port
    except ValueError:
        raise ValueError(f"broker URL port must be a number in 1..65535; got {url!r}") from None
    if not parts.hostname:
        raise ValueError(f"broker URL has no host: expected mqtt://HOST:PORT; got {url!r}")
    if parts.path not in ("", "/") or parts.query or parts.fragment or parts.username:
        raise ValueError(
            f"broker URL must be mqtt://HOST:PORT (no path, query or user); got {url!r}"
        )
    if port == 0:
        raise ValueError(f"broker URL port must be a number in 1..65535; got {url!r}")
    return Broker(parts.hostname, DEFAULT_PORT if port is None else port)


@dataclass(frozen=True)
class Topics:
    """The topic names under ``prefix`` (no wildcards, no leading or trailing slash)."""

    prefix: str = "semwm"

    def __post_init__(self) -> None:
        check_topic_part("prefix", self.prefix, allow_slash=True)

    @property
    def detections_filter(self) -> str:
        """The subscription that matches every source's detections."""
        return f"{self.prefix}/detections/+"

    @property
    def local_filter(self) -> str:
        """The subscription that matches every robot's local model."""
        return f"{self.prefix}/local/+"

    @property
    def world(self) -> str:
        return f"{self.prefix}/world"

    @property
    def status(self) -> str:
        return f"{self.prefix}/status"

    def detections(self, source: str) -> str:
        check_topic_part("source", source)
        return f"{self.prefix}/detections/{source}"

    def errors(self, source: str) -> str:
        return f"{self.prefix}/errors/{source}"

    def local(self, robot: str) -> str:
        check_topic_part("robot", robot)
        return f"{self.prefix}/local/{robot}"

    def source_of(self, topic: str) -> str | None:
        """The ``<source>`` of a detections topic, or ``None`` for any other topic."""
        return _last_level(topic, f"{self.prefix}/detections/")

    def robot_of(self, topic: str) -> str | None:
        """The ``<robot>`` of a local-model topic, or ``None`` for any other topic."""
        return _last_level(topic, f"{self.prefix}/local/")


def _last_level(topic: str, head: str) -> str | None:
    if not topic.startswith(head):
        return None
    rest = topic[len(head) :]
    return rest if rest and "/" not in rest else None


def check_topic_part(what: str, value: str, allow_slash: bool = False) -> None:
    """Refuse a topic part MQTT would misread (empty, wildcards, NUL, slashes at the ends)."""
    problem = None
    if not value:
        problem = "must not be empty"
    elif any(c in value for c in "+#\0"):
        problem = "must not contain '+', '#' or NUL"
    elif not allow_slash and "/" in value:
        problem = "must be one topic level (no '/')"
    elif value.startswith("/") or value.endswith("/") or "//" in value:
        problem = "must not start or end with '/' or hold an empty level"
    if problem:
        raise ValueError(f"MQTT topic {what} {problem}; got {value!r}")


# -- payloads -------------------------------------------------------------------------------


def decode_json(payload: bytes) -> Any:
    """The JSON value of ``payload``; :class:`PayloadError` saying where it is not JSON."""
    try:
        text = payload.decode("utf-8")
    except UnicodeDecodeError as error:
        raise PayloadError(f"payload is not UTF-8: byte {error.start}") from None
    try:
        return json.loads(text)
    except json.JSONDecodeError as error:
        raise PayloadError(
            f"payload is not JSON: {error.msg} at line {error.lineno} column {error.colno}"
        ) from None


def encode_json(value: Any) -> bytes:
    """Compact UTF-8 JSON; NaN and infinities are refused (they are not JSON)."""
    return json.dumps(value, separators=(",", ":"), allow_nan=False).encode("utf-8")


def with_source(payload: Any, source: str) -> Any:
    """``payload`` (one detection or ``{"detections": [...]}``) with ``source`` filled in.

    Only detections that are JSON objects without a ``source`` (or with ``null``) get
    it; anything else is returned as it was, for validation to report.
    """

    def fill(item: Any) -> Any:
        if isinstance(item, dict) and item.get("source") is None:
            return {**item, "source": source}
        return item

    if isinstance(payload, dict) and "detections" in payload:
        items = payload["detections"]
        if isinstance(items, list):
            return {**payload, "detections": [fill(item) for item in items]}
        return payload
    return fill(payload)


def error_payload(topic: str, status: int, body: dict[str, Any]) -> dict[str, Any]:
    """What is published on ``P/errors/<source>``: the HTTP status and body, and the topic."""
    return {"status": status, **body, "topic": topic}


def json_error_body(error: PayloadError) -> dict[str, Any]:
    """A payload that is not JSON, as the 422 body HTTP gives for a body that is not."""
    return {"detail": [{"loc": ["body"], "msg": str(error), "type": "json_invalid"}]}


# -- pacing and duplicates ------------------------------------------------------------------


class RateLimit:
    """At most one publication per ``1 / rate`` seconds, the last change never dropped.

    Changes (:meth:`changed`) arm it; :meth:`due` says when the next publication may
    go out: at once if the last one is at least an interval old, else when the
    interval has passed (so a burst of changes costs one publication at the end,
    never a lost final state). Times are any monotonic clock, in seconds.

    Parameters
    ----------
    rate
        Publications per second (> 0); ``math.inf`` for no limit.
    """

    def __init__(self, rate: float) -> None:
        if not rate > 0:
            raise ValueError(f"rate must be > 0 per second; got {rate}")
        self.interval = 0.0 if math.isinf(rate) else 1.0 / rate
        self.pending = False
        self.last: float | None = None

    def changed(self) -> None:
        """Something changed that must be published."""
        self.pending = True

    def due(self) -> float | None:
        """When the pending publication may go out; ``None`` if nothing is pending."""
        if not self.pending:
            return None
        return 0.0 if self.last is None else self.last + self.interval

    def published(self, now: float) -> None:
        """The pending state went out at ``now``."""
        self.pending = False
        self.last = now


class RecentMessages:
    """Digests of the last ``size`` messages: QoS 1 delivers at least once, so a batch a
    robot re-sends after a broker restart must not be applied twice."""

    def __init__(self, size: int = 65536) -> None:
        if size < 1:
            raise ValueError(f"size must be >= 1; got {size}")
        self.size = size
        self._seen: OrderedDict[bytes, None] = OrderedDict()

    @staticmethod
    def digest(topic: str, payload: bytes) -> bytes:
        return hashlib.blake2b(topic.encode() + b"\0" + payload, digest_size=16).digest()

    def seen(self, key: bytes) -> bool:
        return key in self._seen

    def add(self, key: bytes) -> None:
        self._seen[key] = None
        self._seen.move_to_end(key)
        while len(self._seen) > self.size:
            self._seen.popitem(last=False)
