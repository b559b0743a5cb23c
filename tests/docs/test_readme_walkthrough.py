"""A newcomer's walkthrough of README.md's quickstart, run as written: the Python
example, the HTTP example against a real ``semwm serve`` (on a free port instead of
8000) and the command-line example must print the lines the README shows after
each command (its ``# ...`` lines).

If one fails after a change to the tracking core, the README's quickstart no longer
shows what semwm does: run the example and update the README's ``# ...`` lines.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
import threading
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
README = (ROOT / "README.md").read_text(encoding="utf-8")
QUICKSTART = README[README.index("## Quickstart") : README.index("## What else it does")]
BIN = Path(sys.executable).parent


def block(language: str, index: int = 0) -> str:
    found = re.findall(rf"^```{language}\n(.*?)^```$", QUICKSTART, re.MULTILINE | re.DOTALL)
    return str(found[index])


def shown(code: str) -> list[str]:
    """The output the README shows: its ``# `` lines that follow a command."""
    return [line[2:] for line in code.splitlines() if line.startswith("# ")]


def run_shell(code: str, cwd: Path, port: int | None = None) -> list[str]:
    if port is not None:
        code = code.replace("localhost:8000", f"127.0.0.1:{port}")
    code = code.replace(".venv/bin/", f"{BIN}/")
    result = subprocess.run(
        ["bash", "-euo", "pipefail", "-c", code],
        cwd=cwd, capture_output=True, text=True, timeout=300, check=False,
        env={**os.environ, "PATH": f"{BIN}:{os.environ['PATH']}"},
    )  # fmt: skip
    assert result.returncode == 0, result.stderr
    return result.stdout.strip().splitlines()


def bound_port(server: subprocess.Popen[str], timeout: float = 60.0) -> int:
    """The port ``semwm serve --port 0`` bound, from uvicorn's "running on" line."""
    assert server.stderr is not None
    deadline = time.monotonic() + timeout
    seen = []
    while time.monotonic() < deadline:
        line = server.stderr.readline()
        if not line and server.poll() is not None:
            break
        seen.append(line)
        found = re.search(r"running on http://127\.0\.0\.1:(\d+)", line)
        if found:  # keep reading its log, so that a full pipe never blocks the server
            threading.Thread(target=server.stderr.read, daemon=True).start()
            return int(found.group(1))
    raise AssertionError("semwm serve did not start:\n" + "".join(seen))


def test_the_python_example_prints_what_the_readme_shows(tmp_path: Path) -> None:
    code = block("python")
    result = subprocess.run(
        [sys.executable, "-c", code],
        cwd=ROOT, capture_output=True, text=True, timeout=120, check=False,
    )  # fmt: skip
    assert result.returncode == 0, result.stderr
    assert result.stdout.strip().splitlines() == shown(code)
    assert len(shown(code)) >= 3  # objects are listed


def test_the_http_example_against_a_real_server_prints_what_the_readme_shows(
    tmp_path: Path,
) -> None:
    code = block("bash", 0)
    assert "curl" in code
    server = subprocess.Popen(
        [str(BIN / "semwm"), "serve", "--knowledge", "knowledge/sim1.yaml", "--port", "0"],
        cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    try:
        port = bound_port(server)
        printed = run_shell(code, tmp_path, port)
    finally:
        server.terminate()
        server.wait(timeout=30)
    assert printed == shown(code)
    assert any("Cup" in line for line in printed) and any("CokeCan" in line for line in printed)


def test_the_command_line_example_prints_what_the_readme_shows(tmp_path: Path) -> None:
    code = block("bash", 1)
    assert "semwm simulate" in code
    printed = run_shell(code, tmp_path)
    objects = shown(code)
    assert len(objects) >= 2
    assert printed[-len(objects) :] == objects  # after the metrics table
    assert (tmp_path / "runs" / "sim1-seed0" / "plot.png").is_file()
