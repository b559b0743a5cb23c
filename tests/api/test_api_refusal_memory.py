"""Issue 13 item 3: memory after 1,000 refused large requests stays within 10% of
the start, measured on a real ``semwm serve`` process (its own RSS from /proc)."""

from __future__ import annotations

import os
import socket
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import httpx
import pytest

SIM1 = Path(__file__).parents[2] / "knowledge" / "sim1.yaml"
LIMIT = 4 * 1024 * 1024  # the default body limit
pytestmark = pytest.mark.skipif(
    not Path("/proc/self/status").exists(), reason="RSS is read from /proc (Linux)"
)


def free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        port: int = sock.getsockname()[1]
        return port


def rss_bytes(pid: int) -> int:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) * 1024
    raise AssertionError("no VmRSS")


def lying_length(port: int) -> int:
    """Announce a 20 MB body, send 64 KiB of it: the guard answers 413 from the header."""
    with socket.create_connection(("127.0.0.1", port), timeout=10) as sock:
        head = (
            "POST /detections HTTP/1.1\r\nHost: 127.0.0.1\r\n"
            "Content-Type: application/json\r\nContent-Length: 20000000\r\n\r\n"
        )
        sock.sendall(head.encode() + b" " * 65536)
        answer = sock.recv(4096).decode("latin-1")
    return int(answer.split()[1])


def cut_off(client: httpx.Client) -> int:
    """A chunked body (no length) of 5 MiB: read up to the limit, then 413."""

    def chunks() -> Iterator[bytes]:
        for _ in range(5):
            yield b" " * (1024 * 1024)

    headers = {"content-type": "application/json"}
    return client.post("/detections", content=chunks(), headers=headers).status_code


def long_strings(client: httpx.Client, k: int) -> int:
    body = {"time": 1.0, "class": "Cup", "position": [1, 1], "source": f"{k}" + "s" * 10_000}
    return client.post("/detections", json=body).status_code


def test_memory_after_1000_refused_large_requests_stays_within_10_percent() -> None:
    port = free_port()
    env = {k: v for k, v in os.environ.items() if not k.startswith("SEMWM_")}
    command = [sys.executable, "-m", "semwm.cli", "serve", "--knowledge", str(SIM1)]
    process = subprocess.Popen(
        [*command, "--port", str(port)],
        env=env,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.STDOUT,
    )
    url = f"http://127.0.0.1:{port}"
    try:
        deadline = time.monotonic() + 30
        while True:
            assert process.poll() is None, "semwm serve exited"
            try:
                httpx.get(f"{url}/health", timeout=1)
                break
            except httpx.TransportError:
                assert time.monotonic() < deadline, "semwm serve did not start"
                time.sleep(0.1)
        with httpx.Client(base_url=url, timeout=30) as client:
            ok = {"time": 1.0, "class": "Cup", "position": [1, 1], "source": "cam"}
            assert client.post("/detections", json=ok).status_code == 200
            # warm up every refusal path once, so lazily built code paths are counted
            assert {lying_length(port), cut_off(client), long_strings(client, 0)} == {413, 422}
            start = rss_bytes(process.pid)
            codes: dict[int, int] = {}
            for k in range(1000):
                kind = k % 10
                if kind < 4:
                    code = lying_length(port)
                elif kind == 4:
                    code = cut_off(client)
                else:
                    code = long_strings(client, k)
                codes[code] = codes.get(code, 0) + 1
            end = rss_bytes(process.pid)
            print(f"RSS before {start / 2**20:.1f} MiB, after 1000 refusals {end / 2**20:.1f} MiB")
            assert codes == {413: 500, 422: 500}
            world = client.get("/world").json()
        assert [o["class"] for o in world["objects"]] in ([], ["Cup"])  # nothing else applied
        assert end <= 1.10 * start, f"RSS {start / 2**20:.1f} MiB -> {end / 2**20:.1f} MiB"
    finally:
        process.terminate()
        process.wait(10)
