"""The MQTT protocol values: broker URLs, topics, payload helpers, pacing, duplicates."""

from __future__ import annotations

import itertools
import math

import pytest

from semwm.mqtt.protocol import (
    Broker,
    PayloadError,
    RateLimit,
    RecentMessages,
    Topics,
    decode_json,
    encode_json,
    parse_broker_url,
    with_source,
)


@pytest.mark.parametrize(
    ("url", "expected"),
    [
        ("mqtt://127.0.0.1:1884", Broker("127.0.0.1", 1884)),
        ("mqtt://broker.local", Broker("broker.local", 1883)),
        ("mqtt://[::1]:1999", Broker("::1", 1999)),
    ],
)
def test_broker_url_is_parsed(url: str, expected: Broker) -> None:
    assert parse_broker_url(url) == expected


@pytest.mark.parametrize(
    ("url", "says"),
    [
        ("http://127.0.0.1:1883", "must start with mqtt://"),
        ("127.0.0.1:1883", "must start with mqtt://"),
        ("mqtt://:1883", "no host"),
        ("mqtt://host:port", "port must be a number"),
        ("mqtt://host:70000", "port must be a number"),
        ("mqtt://host:0", "port must be a number"),
        ("mqtt://host:1883/semwm", "no path"),
        ("mqtt://user@host:1883", "no path, query or user"),
    ],
)
def test_bad_broker_url_is_refused_naming_the_problem(url: str, says: str) -> None:
    with pytest.raises(ValueError, match=says) as error:
        parse_broker_url(url)
    assert repr(url) in str(error.value)


def test_topics_under_a_prefix() -> None:
    topics = Topics("team/a")
    assert topics.detections_filter == "team/a/detections/+"
    assert topics.detections("r1") == "team/a/detections/r1"
    assert topics.world == "team/a/world"
    assert topics.errors("r1") == "team/a/errors/r1"
    assert topics.local("r2") == "team/a/local/r2"
    assert topics.status == "team/a/status"


def test_source_and_robot_are_read_back_from_topics() -> None:
    topics = Topics()
    assert topics.source_of("semwm/detections/robot7") == "robot7"
    assert topics.source_of("semwm/detections/") is None
    assert topics.source_of("semwm/detections/a/b") is None
    assert topics.source_of("other/detections/r1") is None
    assert topics.robot_of("semwm/local/r3") == "r3"
    assert topics.robot_of("semwm/world") is None


@pytest.mark.parametrize(
    ("prefix", "says"),
    [("", "must not be empty"), ("a/+", "'\\+'"), ("#", "'#'"), ("/a", "start or end"),
     ("a//b", "empty level")],
)  # fmt: skip
def test_bad_prefix_is_refused(prefix: str, says: str) -> None:
    with pytest.raises(ValueError, match=f"prefix .*{says}"):
        Topics(prefix)


def test_source_with_a_slash_or_wildcard_is_refused() -> None:
    with pytest.raises(ValueError, match="one topic level"):
        Topics().detections("a/b")
    with pytest.raises(ValueError, match="'\\+'"):
        Topics().local("r+")


def test_topic_source_fills_only_detections_without_one() -> None:
    batch = {"detections": [{"time": 1.0}, {"time": 2.0, "source": "cam"}, {"source": None}, 7]}
    assert with_source(batch, "r1") == {
        "detections": [{"time": 1.0, "source": "r1"}, {"time": 2.0, "source": "cam"},
                       {"source": "r1"}, 7]
    }  # fmt: skip
    assert with_source({"time": 1.0}, "r1") == {"time": 1.0, "source": "r1"}
    assert with_source({"detections": "x"}, "r1") == {"detections": "x"}
    assert with_source([1], "r1") == [1]


def test_payload_decoding_says_where_it_breaks() -> None:
    assert decode_json(b'{"a": [1, 2]}') == {"a": [1, 2]}
    with pytest.raises(PayloadError, match=r"not JSON: .* line 2 column 1"):
        decode_json(b'{"a":\n}')
    with pytest.raises(PayloadError, match="not UTF-8: byte 1"):
        decode_json(b"{\xff}")


def test_encoding_refuses_nan() -> None:
    assert encode_json({"x": [1.5]}) == b'{"x":[1.5]}'
    with pytest.raises(ValueError):
        encode_json({"x": math.nan})


def test_rate_limit_publishes_first_change_at_once_then_at_most_once_per_interval() -> None:
    limit = RateLimit(4.0)  # interval 0.25 s
    assert limit.due() is None
    limit.changed()
    assert limit.due() == 0.0
    limit.published(10.0)
    assert limit.due() is None
    for _ in range(50):  # a burst of changes: one publication, one interval later
        limit.changed()
    assert limit.due() == pytest.approx(10.25)
    limit.published(10.3)
    limit.changed()
    assert limit.due() == pytest.approx(10.55)


def test_rate_limit_count_over_a_simulated_stream() -> None:
    """Changes every 10 ms for 2 s at 5 Hz: at most 1 + 2 s x 5 Hz publications, the last
    change published."""
    limit = RateLimit(5.0)
    published: list[float] = []
    now = 0.0
    for step in range(201):
        now = step * 0.01
        limit.changed()
        due = limit.due()
        if due is not None and due <= now:
            limit.published(now)
            published.append(now)
    while (due := limit.due()) is not None:  # the trailing publication
        limit.published(due)
        published.append(due)
    assert len(published) <= 1 + math.floor(published[-1] * 5.0 + 1e-9)
    assert all(b - a >= 0.2 - 1e-9 for a, b in itertools.pairwise(published))
    assert published[-1] >= 2.0


def test_unlimited_rate_and_bad_rate() -> None:
    limit = RateLimit(math.inf)
    limit.changed()
    limit.published(1.0)
    limit.changed()
    assert limit.due() == 1.0
    with pytest.raises(ValueError, match="rate must be > 0"):
        RateLimit(0.0)


def test_recent_messages_forget_the_oldest() -> None:
    recent = RecentMessages(size=2)
    keys = [RecentMessages.digest("t", bytes([i])) for i in range(3)]
    assert len(set(keys)) == 3
    assert RecentMessages.digest("t", b"x") != RecentMessages.digest("u", b"x")
    for key in keys:
        recent.add(key)
    assert not recent.seen(keys[0])
    assert recent.seen(keys[1]) and recent.seen(keys[2])
