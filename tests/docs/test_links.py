"""The front door: README.md is at most 150 lines and its first screen gives the two
commands; every relative link in README.md, docs/*.md, examples/README.md and
benchmarks/README.md resolves (the file exists, and an ``#anchor`` names a heading)."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
PAGES = sorted(
    [ROOT / "README.md", *(ROOT / "docs").glob("*.md"), ROOT / "examples" / "README.md",
     ROOT / "benchmarks" / "README.md"]
)  # fmt: skip
LINK = re.compile(r"(?<!!)\[[^\]]*\]\(([^)\s]+)\)|!\[[^\]]*\]\(([^)\s]+)\)")
INSTALL = "python3 -m venv .venv && .venv/bin/pip install . && .venv/bin/semwm serve --knowledge knowledge/sim1.yaml"
TEST = 'python3 -m venv .venv && .venv/bin/pip install ".[test]" && .venv/bin/pytest -n 2'


def prose(text: str) -> str:
    """``text`` without fenced code blocks and inline code (no links there)."""
    text = re.sub(r"^```.*?^```", "", text, flags=re.MULTILINE | re.DOTALL)
    return re.sub(r"`[^`\n]*`", "", text)


def slug(heading: str) -> str:
    """GitHub's anchor of a heading: lower case, punctuation dropped, spaces -> '-'."""
    text = heading.strip().lower().replace("`", "")
    text = re.sub(r"[^\w\- ]", "", text)
    return text.replace(" ", "-")


def anchors(path: Path) -> set[str]:
    text = re.sub(
        r"^```.*?^```", "", path.read_text(encoding="utf-8"), flags=re.MULTILINE | re.DOTALL
    )
    return {slug(m.group(1)) for m in re.finditer(r"^#{1,6} (.+)$", text, re.MULTILINE)}


def links(page: Path) -> list[str]:
    found = []
    for match in LINK.finditer(prose(page.read_text(encoding="utf-8"))):
        target = match.group(1) or match.group(2)
        if not re.match(r"^[a-z]+:", target):  # http:, https:, mailto:
            found.append(target)
    return found


@pytest.mark.parametrize("page", PAGES, ids=lambda p: str(p.relative_to(ROOT)))
def test_every_relative_link_resolves(page: Path) -> None:
    broken = []
    for target in links(page):
        path_part, _, anchor = target.partition("#")
        path = (page.parent / path_part).resolve() if path_part else page
        if not path.exists():
            broken.append(f"{target}: no such file {path}")
        elif anchor and path.suffix == ".md" and anchor not in anchors(path):
            broken.append(f"{target}: no heading #{anchor} in {path.name}")
    assert broken == [], f"{page.relative_to(ROOT)}: " + "; ".join(broken)


def test_the_link_check_finds_a_broken_link(tmp_path: Path) -> None:
    page = tmp_path / "page.md"
    page.write_text("# Title\n\n[a](missing.md) [b](#title) [c](#nope) `[d](code.md)`\n")
    assert links(page) == ["missing.md", "#title", "#nope"]
    assert "title" in anchors(page) and "nope" not in anchors(page)


def test_readme_is_a_front_door() -> None:
    lines = (ROOT / "README.md").read_text(encoding="utf-8").splitlines()
    assert len(lines) <= 150, f"README.md has {len(lines)} lines; at most 150"
    first_screen = lines[:24]
    commands = [line for line in first_screen if line.startswith("python3 -m venv")]
    assert commands == [INSTALL, TEST]  # byte-identical: CI runs them
    for name in ("benchmarks/README.md", "docs/operations.md", "docs/ros2.md",
                 "docs/limitations.md", "docs/moving-objects.md"):  # fmt: skip
        assert f"]({name}" in "\n".join(lines), name


def test_the_shipped_files_table_lists_every_shipped_knowledge_file() -> None:
    table = (ROOT / "docs" / "knowledge.md").read_text(encoding="utf-8")
    for path in sorted((ROOT / "knowledge").glob("*.yaml")):
        assert f"| `knowledge/{path.stem}.*` |" in table, path.name
