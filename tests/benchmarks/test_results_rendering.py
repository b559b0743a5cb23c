"""Benchmark results: the committed tables are the rendering of the committed results,
and a benchmark run writes to the untracked benchmarks/out/ unless asked otherwise."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import pytest

BENCHMARKS = Path(__file__).resolve().parents[2] / "benchmarks"
sys.path.insert(0, str(BENCHMARKS))

import baselines  # noqa: E402
import render_tables as render  # noqa: E402


def test_committed_tables_equal_the_rendering_of_the_committed_results() -> None:
    expected = render.expected_files()
    assert BENCHMARKS / "README.md" in expected
    assert {p.name for p in expected} >= {"trackers.md", "scaling.md", "api.md", "README.md"}
    for path, text in expected.items():
        assert path.read_text(encoding="utf-8") == text, (
            f"{path} differs from its results: run python benchmarks/render_tables.py"
        )


def test_readme_section_is_replaced_between_the_markers_only() -> None:
    readme = f"head\n{render.BEGIN}\nstale\n{render.END}\ntail\n"
    out = render.rendered_readme(readme, {"a": "# A\n\n| x |\n", "b": "# B\n"})
    assert out == f"head\n{render.BEGIN}\n\n## A\n\n| x |\n\n## B\n\n{render.END}\ntail\n"
    with pytest.raises(ValueError, match="markers"):
        render.rendered_readme("no markers", {})


def test_write_results_goes_to_out_unless_updating(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    out, committed = tmp_path / "out", tmp_path / "results"
    monkeypatch.setattr(baselines, "OUT", out)
    renders: list[list[str]] = []
    monkeypatch.setattr(render, "main", lambda argv: renders.append(argv) or 0)
    doc = {"benchmark": "x"}
    assert baselines.write_results(committed, "x", doc, "| t |\n", False) == out
    assert json.loads((out / "x.json").read_text()) == doc
    assert (out / "x.md").read_text() == "| t |\n"
    assert not committed.exists() and renders == []
    baselines.write_results(committed, "x", doc, "| t |\n", True, update_results=True)
    assert (committed / "x_quick.json").is_file() and renders == [[]]
    assert "| t |" in capsys.readouterr().out


def test_out_is_git_ignored() -> None:
    ignored = (BENCHMARKS.parent / ".gitignore").read_text().splitlines()
    assert "benchmarks/out/" in ignored
    assert baselines.OUT == BENCHMARKS / "out"
