"""``semwm knowledge validate|convert|show`` through ``semwm.cli.main``."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from semwm.cli import main
from semwm.knowledge import load_document
from semwm.knowledge.shipped import shipped_knowledge_path

BROKEN = """\
world:
  {dimension: 2, region: [[0, 10], [0, 10]]}
classes:
  - name: Cup
    is_a: [Mug]
    detection_frequency: -2
detectors:
  - name: camera
    clutter_frequency: 0.5
"""


def run(capsys: pytest.CaptureFixture[str], *argv: str) -> tuple[int, str, str]:
    status = main(["knowledge", *argv])
    captured = capsys.readouterr()
    return status, captured.out, captured.err


def test_validate_valid_files(capsys: pytest.CaptureFixture[str]) -> None:
    sim1, robocup = shipped_knowledge_path("sim1.xml"), shipped_knowledge_path("robocup.yaml")
    status, out, _ = run(capsys, "validate", str(sim1), str(robocup))
    assert status == 0
    assert out.splitlines() == [
        f"{sim1}: OK (5 classes, 1 detector, dimension 2)",
        f"{robocup}: OK (4 classes, 2 detectors, dimension 2)",
    ]


def test_validate_prints_one_line_per_problem(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    broken = tmp_path / "broken.yaml"
    broken.write_text(BROKEN)
    status, out, _ = run(capsys, "validate", str(broken), str(shipped_knowledge_path("sim2.xml")))
    assert status == 1
    lines = out.splitlines()
    assert (
        lines[0]
        == f"{broken}:6: expected a number >= 0, found -2 (at classes.0.detection_frequency)"
    )
    assert len(lines) == 2 and lines[1].endswith(
        "sim2.xml: OK (2 classes, 1 detector, dimension 2)"
    )


def test_validate_a_missing_file_or_unknown_extension(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    status, out, _ = run(capsys, "validate", str(tmp_path / "none.xml"), str(tmp_path / "a.ini"))
    assert status == 1
    assert re.match(
        rf"{re.escape(str(tmp_path / 'none.xml'))}: .*No such file", out.splitlines()[0]
    )
    assert "unknown knowledge file extension '.ini'" in out.splitlines()[1]


@pytest.mark.parametrize(
    ("source", "target"), [("sim2.xml", "out.yaml"), ("robocup.yaml", "out.xml")]
)
def test_convert(
    capsys: pytest.CaptureFixture[str], tmp_path: Path, source: str, target: str
) -> None:
    status, out, _ = run(
        capsys, "convert", str(shipped_knowledge_path(source)), str(tmp_path / target)
    )
    assert status == 0 and out.strip() == f"wrote {tmp_path / target}"
    assert load_document(tmp_path / target) == load_document(shipped_knowledge_path(source))


def test_convert_a_broken_file_fails_with_its_problems(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    broken = tmp_path / "broken.yaml"
    broken.write_text(BROKEN)
    status, out, _ = run(capsys, "convert", str(broken), str(tmp_path / "out.xml"))
    assert status == 1 and f"{broken}:6:" in out
    assert not (tmp_path / "out.xml").exists()


def test_show_a_class_with_where_each_value_comes_from(capsys: pytest.CaptureFixture[str]) -> None:
    status, out, _ = run(capsys, "show", str(shipped_knowledge_path("sim1.yaml")), "CokeCan")
    assert status == 0
    lines = out.splitlines()
    assert lines[0] == "CokeCan (is-a Can)"
    assert "  detection_frequency: 2 Hz  (from Can)" in lines
    assert "  max_position_variance: 0.25 m^2  (from Can)" in lines
    assert "  max_time_without_update: not set  (default)" in lines


def test_show_summary_has_the_taxonomy_tree(capsys: pytest.CaptureFixture[str]) -> None:
    status, out, _ = run(capsys, "show", str(shipped_knowledge_path("sim1.xml")))
    assert status == 0
    tree = out.split("taxonomy:\n", 1)[1].splitlines()
    assert [line.split("  [")[0] for line in tree] == [
        "  Can",
        "    CokeCan",
        "    BeerCan",
        "  Cup",
        "  Table",
    ]


def test_show_an_unknown_class_lists_the_known_ones(capsys: pytest.CaptureFixture[str]) -> None:
    status, out, err = run(capsys, "show", str(shipped_knowledge_path("sim1.xml")), "Mug")
    assert status == 2 and out == ""
    assert "unknown class 'Mug'; known classes: Can, CokeCan, BeerCan, Cup, Table" in err
