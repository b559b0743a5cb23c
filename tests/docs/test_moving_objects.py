"""docs/moving-objects.md's worked examples, run as the page gives them: each Python
block must print exactly the text block that follows it. When the tracking core
changes a result, this says which line: rerun the block and update the page (and
its sentences about the numbers)."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
PAGE = (ROOT / "docs" / "moving-objects.md").read_text(encoding="utf-8")
PAIRS = re.findall(r"^```python\n(.*?)^```\n\n```text\n(.*?)^```$", PAGE, re.MULTILINE | re.DOTALL)


def test_the_page_has_the_vehicle_and_the_person() -> None:
    assert len(PAIRS) == 2
    assert "first_order" in PAIRS[0][0] and "type: imm" in PAIRS[1][0]


@pytest.mark.parametrize("index", range(len(PAIRS)), ids=["forklift", "person"])
def test_each_block_prints_what_the_page_shows(index: int) -> None:
    code, shown = PAIRS[index]
    result = subprocess.run(
        [sys.executable, "-c", code],
        cwd=ROOT, capture_output=True, text=True, timeout=600, check=False,
    )  # fmt: skip
    assert result.returncode == 0, result.stderr
    assert result.stdout.rstrip().splitlines() == shown.rstrip().splitlines()
