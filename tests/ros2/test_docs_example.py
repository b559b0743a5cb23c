"""docs/ros2.md's worked example, run as the page says: its class map, its
command's output lines and its Python snippet's printed lines must be today's."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

pytest.importorskip("rosbags")

ROOT = Path(__file__).resolve().parents[2]
PAGE = (ROOT / "docs" / "ros2.md").read_text(encoding="utf-8")


def blocks(language: str) -> list[str]:
    return re.findall(rf"^```{language}\n(.*?)^```$", PAGE, re.MULTILINE | re.DOTALL)


def test_the_worked_example_gives_what_the_page_shows(tmp_path: Path) -> None:
    script = blocks("sh")[1]
    class_map = re.search(r"<<'EOF'\n(.*?)\nEOF\n", script, re.DOTALL)
    assert class_map is not None
    (tmp_path / "classes.yaml").write_text(class_map.group(1) + "\n", encoding="utf-8")
    (tmp_path / "knowledge").symlink_to(ROOT / "knowledge")
    bin_dir = Path(sys.executable).parent
    subprocess.run(
        [sys.executable, str(ROOT / "examples" / "ros2_demo_bag.py"), "demo_bag"],
        cwd=tmp_path, check=True, capture_output=True, timeout=120,
    )  # fmt: skip
    command = script[script.index("semwm replay") :].replace("\\\n", " ").split()
    assert command[:2] == ["semwm", "replay"]
    replay = subprocess.run(
        [str(bin_dir / "semwm"), *command[1:]],
        cwd=tmp_path, check=True, capture_output=True, text=True, timeout=300,
    )  # fmt: skip
    shown = blocks("text")[0].strip().splitlines()
    assert replay.stdout.strip().splitlines() == shown

    snippet = blocks("python")[0]
    printed = subprocess.run(
        [sys.executable, "-c", snippet],
        cwd=tmp_path, check=True, capture_output=True, text=True, timeout=120,
    )  # fmt: skip
    expected = [line[2:] for line in snippet.splitlines() if line.startswith("# ")]
    assert printed.stdout.strip().splitlines() == expected
