"""Execute every example notebook (examples/*.ipynb) and fail on any cell error;
every notebook is published with its outputs in docs/examples/, and the published
page is what this fresh run publishes (text and figures): a page left stale by a
change of the code fails here, saying to run ``python examples/render.py``.

Notebooks run as ``python examples/render.py`` runs them (its ``pinned_kernel``:
the interpreter running pytest, so a fresh venv needs no registered kernel).
"""

from __future__ import annotations

import importlib.util
import re
from pathlib import Path
from types import ModuleType

import pytest

pytest.importorskip("nbformat")
pytest.importorskip("nbclient")
pytest.importorskip("ipykernel")
pytest.importorskip("matplotlib")

ROOT = Path(__file__).resolve().parents[2]
EXAMPLES = ROOT / "examples"
DOCS = ROOT / "docs" / "examples"
NOTEBOOKS = sorted(EXAMPLES.glob("*.ipynb"))


def _load_render() -> ModuleType:
    """examples/render.py, by path (a unique module name: no clash on sys.path)."""
    spec = importlib.util.spec_from_file_location("semwm_examples_render", EXAMPLES / "render.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


render = _load_render()


@pytest.fixture(scope="module")
def kernel_here() -> str:
    with render.pinned_kernel() as name:
        yield name


def test_examples_exist() -> None:
    assert len(NOTEBOOKS) >= 4, NOTEBOOKS


@pytest.mark.parametrize("path", NOTEBOOKS, ids=[p.name for p in NOTEBOOKS])
def test_notebook_runs(path: Path, kernel_here: str) -> None:
    nb = render.execute(path, kernel_here)  # raises CellExecutionError on the first failing cell
    errors = [
        out
        for cell in nb.cells
        if cell.cell_type == "code"
        for out in cell.get("outputs", [])
        if out.get("output_type") == "error"
    ]
    assert not errors
    stale = render.differences(nb, path.stem)
    assert not stale, (
        f"docs/examples/{path.stem}.md is not what a fresh run of {path.name} publishes; "
        f"regenerate the published examples with: {render.REGENERATE}\n" + "\n".join(stale)
    )


@pytest.mark.parametrize("path", NOTEBOOKS, ids=[p.name for p in NOTEBOOKS])
def test_notebook_is_published_with_its_figures(path: Path) -> None:
    page = DOCS / f"{path.stem}.md"
    assert page.is_file(), f"{page} missing: run python examples/render.py"
    text = page.read_text(encoding="utf-8")
    figures = re.findall(r"!\[[^\]]*\]\(([^)]+\.png)\)", text)
    assert figures, f"{page} has no figure"
    for figure in figures:
        assert (DOCS / figure).is_file(), figure


def test_committed_notebooks_carry_no_outputs() -> None:
    import nbformat

    for path in NOTEBOOKS:
        nb = nbformat.read(path, as_version=4)
        assert all(not c.get("outputs") for c in nb.cells if c.cell_type == "code"), path
