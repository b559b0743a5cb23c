"""A private Mosquitto broker on a free loopback port: for tests and benchmarks.

Never the system's service: each :class:`PrivateBroker` writes its own configuration
into a directory of its own (persistence on, so a restart keeps sessions and queued
QoS 1 messages) and runs ``mosquitto -c`` as a child process.
"""

from __future__ import annotations

import getpass
import shutil
import signal
import socket
import subprocess
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from semwm.mqtt.protocol import Broker


def mosquitto_path() -> str | None:
    """The ``mosquitto`` executable, or ``None`` when it is not installed."""
    return shutil.which("mosquitto") or next(
        (p for p in ("/usr/sbin/mosquitto", "/usr/local/sbin/mosquitto") if Path(p).exists()),
        None,
    )


def free_port() -> int:
    """A TCP port on 127.0.0.1 that was free a moment ago."""
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        port: int = sock.getsockname()[1]
        return port


def _accepts(port: int) -> bool:
    try:
        with socket.create_connection(("127.0.0.1", port), timeout=0.2):
            return True
    except OSError:
        return False


class PrivateBroker:
    """A Mosquitto on 127.0.0.1 with a configuration in ``directory``.

    Parameters
    ----------
    directory
        Holds ``mosquitto.conf``, the persistence database and the log.
    persistence
        Keep sessions and queued messages in a file across restarts (saved on a
        clean stop and every second).
    """

    def __init__(self, directory: Path, persistence: bool = True) -> None:
        executable = mosquitto_path()
        if executable is None:
            raise FileNotFoundError("mosquitto is not installed (Debian package 'mosquitto')")
        self.executable = executable
        self.directory = directory
        self.persistence = persistence
        self.port = 0
        self.process: subprocess.Popen[bytes] | None = None
        self.log = directory / "mosquitto.log"

    @property
    def broker(self) -> Broker:
        return Broker("127.0.0.1", self.port)

    @property
    def url(self) -> str:
        return self.broker.url

    def _write_config(self) -> Path:
        lines = [
            f"listener {self.port} 127.0.0.1",
            "allow_anonymous true",
            f"user {getpass.getuser()}",
            "max_queued_messages 1000000",
            "max_inflight_messages 100",
            "log_type error",
            "log_type warning",
            "log_type notice",
            f"log_dest file {self.log}",
        ]
        if self.persistence:
            lines += [
                "persistence true",
                f"persistence_location {self.directory}/",
                "autosave_interval 1",
            ]
        path = self.directory / "mosquitto.conf"
        path.write_text("\n".join(lines) + "\n")
        return path

    def start(self, timeout: float = 10.0) -> None:
        """Start on a free port (the same port again after :meth:`stop`)."""
        if self.process is not None:
            raise RuntimeError("the broker is already running")
        attempts = 5 if self.port == 0 else 1
        for _ in range(attempts):
            if attempts > 1:
                self.port = free_port()
            config = self._write_config()
            self.process = subprocess.Popen(
                [self.executable, "-c", str(config)],
                stdout=subprocess.DEVNULL,
                stderr=subprocess.DEVNULL,
            )
            deadline = time.monotonic() + timeout
            while time.monotonic() < deadline and self.process.poll() is None:
                if _accepts(self.port):
                    return
                time.sleep(0.02)
            self._kill()
        log = self.log.read_text(errors="replace")[-2000:] if self.log.exists() else ""
        raise RuntimeError(f"mosquitto did not start on 127.0.0.1:{self.port}: {log}")

    def stop(self, timeout: float = 10.0) -> None:
        """Stop cleanly (SIGTERM: Mosquitto saves its persistence database first)."""
        if self.process is None:
            return
        self.process.send_signal(signal.SIGTERM)
        try:
            self.process.wait(timeout)
        except subprocess.TimeoutExpired:
            self.process.kill()
            self.process.wait(timeout)
        self.process = None

    def restart(self) -> None:
        self.stop()
        self.start()

    def _kill(self) -> None:
        if self.process is not None:
            self.process.kill()
            self.process.wait(5.0)
            self.process = None


@contextmanager
def private_broker(directory: Path, persistence: bool = True) -> Iterator[PrivateBroker]:
    """A started :class:`PrivateBroker`, stopped when the block exits."""
    broker = PrivateBroker(directory, persistence)
    broker.start()
    try:
        yield broker
    finally:
        broker.stop()
