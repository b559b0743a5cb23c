"""semwm.client.Client: one keep-alive connection to the real server."""

from __future__ import annotations

import math
import time
from pathlib import Path
from typing import Any

import pytest

from api.settings import Settings
from api.testing import running_server
from semwm.client import Client, ServiceError


def cup(t: float, x: float = 1.0) -> dict[str, object]:
    return {"time": t, "class": "Cup", "position": [x, 2.0], "source": "r1"}


def test_requests_share_one_connection_and_refusals_carry_the_field_paths(
    knowledge_file: Path,
) -> None:
    with running_server(Settings(knowledge=knowledge_file, port=0)) as url, Client(url) as client:
        assert client.post_detections([cup(1.0)]) == {
            "applied": 1,
            "time": 1.0,
            "ignored": 0,
            "ignored_detections": [],
        }
        connection = client._connection
        assert client.post_detections([cup(1.1), cup(1.1, 3.0)])["applied"] == 2
        assert client.last_headers["x-semwm-commit"] == "2"
        assert client.get("/health")["time"] == 1.1
        assert client._connection is connection  # kept alive
        with pytest.raises(ServiceError) as refused:
            client.post_detections([cup(1.2), {**cup(1.2), "position": [1.0]}])
        assert refused.value.status == 422
        assert [item["loc"] for item in refused.value.body["detail"]] == [
            ["body", "detections", 1, "position"]
        ]
        assert "position" in str(refused.value)
        assert client.get("/health")["commit"] == 2  # nothing applied
        assert client._connection is connection  # a 422 keeps the connection
        metrics = client.get_text("/metrics")  # text, on the same connection
        assert "\nsemwm_detections_accepted_total 3.0\n" in metrics
        assert client._connection is connection
        with pytest.raises(ServiceError) as missing:
            client.get_text("/no-such-page")
        assert missing.value.status == 404


def test_a_connection_the_server_closed_while_idle_is_opened_again(knowledge_file: Path) -> None:
    settings = Settings(knowledge=knowledge_file, port=0, timeout_keep_alive=0.2)
    with running_server(settings) as url:
        # idle_reconnect above the server's keep-alive: the client finds the socket closed
        with Client(url, idle_reconnect=60.0) as client:
            client.post_detections([cup(1.0)], idempotency_key="a")
            time.sleep(0.6)
            assert client.get("/health")["commit"] == 1  # a read is sent again
            time.sleep(0.6)
            answer = client.post_detections([cup(1.1)], idempotency_key="b")  # keyed: again
            assert answer["applied"] == 1
            assert client.get("/health")["commit"] == 2  # applied once
        # below it (the default): a fresh connection before the socket is stale
        with Client(url, idle_reconnect=0.1) as client:
            client.get("/health")
            time.sleep(0.6)
            assert client.post_detections([cup(1.2)])["applied"] == 1


def test_a_token_is_sent_and_a_bad_url_is_refused(knowledge_file: Path) -> None:
    settings = Settings(knowledge=knowledge_file, port=0, token="secret-token")
    with running_server(settings) as url:
        with Client(url) as anonymous, pytest.raises(ServiceError) as refused:
            anonymous.post_detections([cup(1.0)])
        assert refused.value.status == 401
        with Client(url, token="secret-token") as client:
            assert client.post_detections([cup(1.0)])["applied"] == 1
    with pytest.raises(ValueError, match="base_url"):
        Client("127.0.0.1:8000")


def test_an_answer_is_read_as_the_standard_library_reads_it() -> None:
    """The client reads answers with orjson, and those orjson refuses with the standard
    library: NaN and infinities, integers beyond 64 bits; a body that is no JSON raises
    the standard library's error, as before."""
    import json

    from semwm.client import decode_json

    world = b'{"objects":[{"id":1,"position":[0.1,-2.5e-3],"existence":0.9999999999999999}]}'
    assert decode_json(world) == json.loads(world)
    assert repr(decode_json(b"[0.1, 1e-320, 1.7976931348623157e308]")) == repr(
        json.loads(b"[0.1, 1e-320, 1.7976931348623157e308]")
    )
    nan = decode_json(b'{"x": NaN, "y": -Infinity}')
    assert math.isnan(nan["x"]) and nan["y"] == -math.inf
    assert decode_json(b'{"n": %d}' % 2**70) == {"n": 2**70}
    with pytest.raises(json.JSONDecodeError):
        decode_json(b"<html>bad gateway</html>")


def test_a_large_answer_is_read_with_the_collector_paused(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """An answer over ``PAUSED_BODY`` bytes is read with the cyclic garbage collector
    paused (by orjson and by the standard library alike), and resumed after, also when
    the body is no JSON; a small answer is read with it running."""
    import gc
    import json

    import semwm.client as client_module

    during: list[bool] = []
    standard = json.loads

    def watched(body: bytes) -> Any:
        during.append(gc.isenabled())
        return standard(body)

    monkeypatch.setattr(client_module.json, "loads", watched)
    objects = [{"id": i, "position": [0.5 * i, 1.0], "existence": 0.9} for i in range(2000)]
    large = json.dumps({"x": float("nan"), "objects": objects}).encode()  # orjson refuses NaN
    assert len(large) > client_module.PAUSED_BODY
    assert client_module.decode_json(large)["objects"] == objects
    assert during == [False] and gc.isenabled()
    assert client_module.decode_json(b'{"x": NaN}')["x"] != 0.0
    assert during == [False, True]
    with pytest.raises(json.JSONDecodeError):
        client_module.decode_json(b"<" * (client_module.PAUSED_BODY + 1))
    assert during == [False, True, False] and gc.isenabled()


def test_a_batch_is_sent_as_the_robot_gave_it_bad_values_included(knowledge_file: Path) -> None:
    """The client's JSON (orjson, else the standard library) carries every value as
    given: numpy arrays as lists, and a NaN the service refuses, never as an absent
    value (orjson alone would write it as null, and a null time_std is none at all)."""
    import json

    import numpy as np

    from semwm.client import encode_json

    batch = [{**cup(1.0), "position": np.array([1.0, 2.0]), "time_std": np.float64(0.01)}]
    assert json.loads(encode_json({"detections": batch}))["detections"][0]["position"] == [1.0, 2.0]
    assert b"NaN" in encode_json({"detections": [{**cup(1.0), "time_std": float("nan")}]})
    assert json.loads(encode_json({"n": 2**70})) == {"n": 2**70}  # beyond orjson's 64 bits
    with running_server(Settings(knowledge=knowledge_file, port=0)) as url, Client(url) as client:
        assert client.post_detections(batch)["applied"] == 1
        with pytest.raises(ServiceError) as refused:
            client.post_detections([{**cup(1.1), "time_std": float("nan")}])
        assert refused.value.status == 422
        assert client.get("/health")["commit"] == 1  # nothing applied
