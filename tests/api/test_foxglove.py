"""``serve --foxglove PORT``: a Foxglove WebSocket client on loopback receives the scene.

The client speaks the Foxglove WebSocket protocol by hand (``websockets``): it
reads the ``advertise`` of ``/semwm/world``, subscribes, and waits for a binary
message-data frame (opcode 1) after a POST. The SceneUpdate payload is protobuf;
its strings (entity ids, texts) appear in it verbatim.
"""

from __future__ import annotations

import json
import math
import struct
import time
from pathlib import Path
from typing import Any

import httpx
import pytest
from api_helpers import scene

from api.app import create_app
from api.settings import Settings
from api.testing import serving

pytest.importorskip("foxglove", reason="foxglove-sdk is not installed: pip install '.[foxglove]'")
sync_client = pytest.importorskip("websockets.sync.client", reason="websockets is not installed")

from api.foxglove_bridge import principal_axes, scene_update  # noqa: E402

TIMEOUT = 20.0


def test_principal_axes_of_a_rotated_covariance() -> None:
    # R(30 deg) diag(4, 1) R^T: the axes are 2 and 1 m, the first at 30 degrees.
    c, s = math.cos(math.pi / 6), math.sin(math.pi / 6)
    a, b, d = 4 * c * c + s * s, 3 * c * s, 4 * s * s + c * c
    sigma_1, sigma_2, theta = principal_axes([[a, b], [b, d]])
    assert (sigma_1, sigma_2, theta) == pytest.approx((2.0, 1.0, math.pi / 6))


def test_scene_update_has_an_entity_per_object() -> None:
    world = {
        "time": 2.0,
        "objects": [
            {"id": 4, "class": "Cup", "label": None, "position": [1.0, 2.0], "velocity": None,
             "covariance": [[0.01, 0.0], [0.0, 0.01]], "existence": 0.9},
            {"id": 5, "class": "Robot", "label": "r1", "position": [0.0, 0.0, 0.5],
             "velocity": [1.0, 0.0, 0.0],
             "covariance": [[0.01, 0, 0], [0, 0.01, 0], [0, 0, 0.04]], "existence": 1.0},
        ],
    }  # fmt: skip
    encoded = scene_update(world).encode()
    for text in (b"object/4", b"#4 Cup", b"object/5", b"#5 Robot r1", b"world"):
        assert text in encoded


def subscribe_to_world(ws: Any) -> int:
    """Read until ``/semwm/world`` is advertised; subscribe to it; return the subscription id."""
    deadline = time.monotonic() + TIMEOUT
    while time.monotonic() < deadline:
        message = ws.recv(timeout=TIMEOUT)
        if isinstance(message, str):
            body = json.loads(message)
            if body.get("op") == "advertise":
                for channel in body["channels"]:
                    if channel["topic"] == "/semwm/world":
                        assert channel["schemaName"] == "foxglove.SceneUpdate"
                        ws.send(json.dumps({"op": "subscribe", "subscriptions": [
                            {"id": 1, "channelId": channel["id"]}]}))  # fmt: skip
                        return 1
    raise AssertionError("/semwm/world was not advertised")


def test_a_foxglove_client_receives_the_scene_after_a_post(knowledge_file: Path) -> None:
    settings = Settings(knowledge=knowledge_file, port=0, foxglove_port=0)
    app = create_app(settings)
    with (
        serving(app, settings) as url,
        httpx.Client(base_url=url, timeout=TIMEOUT) as client,
    ):
        bridge = app.state.foxglove  # it bound a free port (foxglove_port 0)
        with sync_client.connect(
            f"ws://127.0.0.1:{bridge.port}", subprotocols=["foxglove.sdk.v1"], open_timeout=TIMEOUT
        ) as ws:
            subscription = subscribe_to_world(ws)
            time.sleep(0.2)  # let the subscription reach the server before the POST
            assert client.post("/detections", json={"detections": scene(0.0)}).status_code == 200
            ids = [f"object/{o['id']}".encode() for o in client.get("/world").json()["objects"]]
            deadline = time.monotonic() + TIMEOUT
            while time.monotonic() < deadline:
                message = ws.recv(timeout=TIMEOUT)
                if isinstance(message, bytes) and message[0] == 1:
                    (sub,) = struct.unpack_from("<I", message, 1)
                    assert sub == subscription
                    payload = message[1 + 4 + 8 :]
                    if all(i in payload for i in ids):
                        break
            else:
                raise AssertionError("no scene with the posted objects")
    assert len(ids) == 3
    assert b"Robot r1" in payload
