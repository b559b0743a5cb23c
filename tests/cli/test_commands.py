"""The ``semwm`` command line as a user meets it: one regression test per defect of issue 14.

Every usage error is one line on stderr with no traceback; ``--help`` and
``--version`` are current; ``simulate`` variants write their own folders and record
what was changed; ``knowledge convert`` names a missing folder.
"""

from __future__ import annotations

import json
import subprocess
import sys
from importlib import metadata
from pathlib import Path

import pytest
import yaml

from semwm.cli import COMMANDS, build_parser, main
from semwm.cli.simulate import default_out
from semwm.knowledge.shipped import shipped_knowledge_path
from semwm.sim.scenarios import make_scenario


def run(capsys: pytest.CaptureFixture[str], *argv: str) -> tuple[int, str, str]:
    status = main(list(argv))
    captured = capsys.readouterr()
    return status, captured.out, captured.err


def test_help_lists_every_command_and_no_stale_text(capsys: pytest.CaptureFixture[str]) -> None:
    status, out, _ = run(capsys, "--help")
    assert status == 0
    assert "minimal" not in out and "so far" not in out
    commands = ("serve", "simulate", "knowledge", "replay", "record", "journal")
    for command in commands:
        assert f"\n    {command}" in out  # argparse's list of sub-commands
    for command in ("serve", "simulate", "knowledge", "replay|record|journal"):
        assert f"semwm {command}" in out  # the description
    assert "--version" in out and "--log-level" in out
    assert len(COMMANDS) == len(commands)


@pytest.mark.parametrize(
    ("argv", "expected"),
    [
        (["simulate", "--help"], ["--knowledge FILE", "--no-knowledge NAME", "door-relation"]),
        (["serve", "--help"], ["--knowledge", "--port", "--log-level"]),
        (["knowledge", "convert", "--help"], ["OUT's folder must exist"]),
    ],
)
def test_every_command_help_is_current(
    capsys: pytest.CaptureFixture[str], argv: list[str], expected: list[str]
) -> None:
    status, out, _ = run(capsys, *argv)
    assert status == 0
    for text in expected:
        assert text in out


def test_version(capsys: pytest.CaptureFixture[str]) -> None:
    status, out, _ = run(capsys, "--version")
    assert status == 0
    assert out.strip().startswith(f"semwm {metadata.version('semwm')} (engine: ")
    from semwm.filters.engine import rust_core

    built = "Rust core: built" if rust_core() is not None else "Rust core: not built"
    assert built in out


def test_version_says_the_engine(
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("SEMWM_ENGINE", "python")
    assert "(engine: python; " in run(capsys, "--version")[1]
    monkeypatch.setenv("SEMWM_ENGINE", "fortran")
    status, out, _ = run(capsys, "--version")
    assert status == 0 and "engine: none: SEMWM_ENGINE: expected one of python, rust" in out


BAD_VALUES = [
    (
        ["--log-level", "loud", "knowledge", "show", "x.yaml"],
        "argument --log-level: invalid choice",
    ),
    (["serve", "--log-level", "loud"], "argument --log-level: invalid choice: 'loud'"),
    (["simulate", "sim9"], "argument NAME: invalid choice: 'sim9'"),
    (["simulate", "sim1", "--seed", "one"], "argument --seed: invalid int value: 'one'"),
    (["simulate", "sim1", "--duration", "-2"], "expected a number > 0, found '-2'"),
    (["simulate", "sim1", "--duration", "nan"], "expected a number > 0, found 'nan'"),
    (["simulate", "sim1", "--no-knowledge", "all"], "argument --no-knowledge: invalid choice"),
    (["knowledge"], "the following arguments are required: COMMAND"),
    (["launch"], "argument COMMAND: invalid choice: 'launch'"),
    ([], "the following arguments are required: COMMAND"),
]


@pytest.mark.parametrize(("argv", "message"), BAD_VALUES, ids=[" ".join(a) for a, _ in BAD_VALUES])
def test_bad_option_values_are_one_line_errors(
    capsys: pytest.CaptureFixture[str], argv: list[str], message: str
) -> None:
    status, out, err = run(capsys, *argv)
    assert status == 2
    assert out == ""
    assert len(err.splitlines()) == 1, err
    assert message in err and "Traceback" not in err
    assert err.startswith("semwm") and "--help)" in err


def test_log_level_error_from_the_installed_entry_point() -> None:
    """The real process: ``python -m semwm --log-level loud`` (was a KeyError traceback)."""
    result = subprocess.run(
        [sys.executable, "-m", "semwm", "--log-level", "loud", "simulate", "sim1"],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert result.returncode == 2
    assert result.stdout == ""
    assert result.stderr.count("\n") == 1 and "invalid choice: 'loud'" in result.stderr


def test_convert_to_a_missing_folder_names_it(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    target = tmp_path / "no" / "such" / "sim1.yaml"
    status, out, err = run(
        capsys, "knowledge", "convert", str(shipped_knowledge_path("sim1.xml")), str(target)
    )
    assert status == 1 and out == ""
    assert err == (
        f"semwm knowledge: cannot write {target}: no such folder {tmp_path / 'no' / 'such'}/\n"
    )
    assert not (tmp_path / "no").exists()


def test_simulate_with_a_missing_or_broken_knowledge_file(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    status, _, err = run(capsys, "simulate", "sim1", "--knowledge", str(tmp_path / "none.yaml"))
    assert (
        status == 1
        and err == f"semwm simulate: {tmp_path / 'none.yaml'}: No such file or directory\n"
    )
    broken = tmp_path / "broken.yaml"
    broken.write_text(
        "world:\n  dimension: 2\nclasses:\n  - name: Cup\n    new_frequency: -1\n"
        "detectors:\n  - name: camera\n    clutter_frequency: 0.5\n"
    )
    status, _, err = run(capsys, "simulate", "sim1", "--knowledge", str(broken))
    assert status == 1 and len(err.splitlines()) == 1
    assert err == (
        f"semwm simulate: {broken}:5: expected a number >= 0, found -1 "
        "(at classes.0.new_frequency)\n"
    )


@pytest.mark.parametrize("name", ["datasheet", "patrol"])
def test_simulate_a_variant_with_its_datasheet_knowledge(
    capsys: pytest.CaptureFixture[str], tmp_path: Path, name: str
) -> None:
    """Their knowledge files are in benchmarks/knowledge/ of the checkout, not shipped
    (``semwm simulate datasheet`` used to stop with a FileNotFoundError traceback)."""
    out_dir = tmp_path / name
    status, out, err = run(
        capsys, "simulate", name, "--duration", "5", "--out", str(out_dir), "--no-progress"
    )
    assert status == 0, err
    metrics = json.loads((out_dir / "metrics.json").read_text(encoding="utf-8"))
    assert Path(metrics["knowledge"]).name == f"{name}.yaml"
    assert Path(metrics["knowledge"]).parent.name == "knowledge"
    assert "GOSPA" in out


def test_default_out_gives_every_variant_its_own_folder() -> None:
    assert default_out("sim2", 0, [], None) == Path("runs/sim2-seed0")
    assert default_out("sim2", 0, ["door-relation"], None) == Path(
        "runs/sim2-seed0-no-door-relation"
    )
    assert default_out("sim1", 3, ["taxonomy", "door-relation"], Path("k/my.yaml")) == Path(
        "runs/sim1-seed3-knowledge-my-no-taxonomy-no-door-relation"
    )


def _simulate(capsys: pytest.CaptureFixture[str], *extra: str) -> tuple[str, str]:
    status, out, err = run(capsys, "simulate", "sim1", "--duration", "2", *extra)
    assert status == 0, err
    return out, err


def test_an_ablation_writes_its_own_folder_and_records_itself(
    capsys: pytest.CaptureFixture[str], tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.chdir(tmp_path)
    _simulate(capsys, "--no-progress", "--no-knowledge", "taxonomy")
    assert [p.name for p in (tmp_path / "runs").iterdir()] == ["sim1-seed0-no-taxonomy"]
    metrics = json.loads((tmp_path / "runs/sim1-seed0-no-taxonomy/metrics.json").read_text())
    assert metrics["ablations"] == ["taxonomy"]
    _simulate(capsys, "--no-progress")
    baseline = json.loads((tmp_path / "runs/sim1-seed0/metrics.json").read_text())
    assert baseline["ablations"] == []
    assert baseline["knowledge"] == str(shipped_knowledge_path("sim1.yaml"))


def _no_new_objects(source: Path, target: Path) -> Path:
    """``source`` with every class's ``new_frequency`` 0: no object can ever be born."""
    document = yaml.safe_load(source.read_text())
    for spec in document["classes"]:
        if "new_frequency" in spec:
            spec["new_frequency"] = 0.0
    target.write_text(yaml.safe_dump(document, sort_keys=False))
    return target


def _expected_all_missed(duration: float) -> int:
    """Missed object-frames of an empty world: every true object in every frame."""
    scenario = make_scenario("sim1", 0, duration=duration)
    return sum(len(frame.objects) for frame in scenario.truth)


def test_simulate_knowledge_file_is_used_and_recorded(
    capsys: pytest.CaptureFixture[str], tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.chdir(tmp_path)
    mine = _no_new_objects(shipped_knowledge_path("sim1.yaml"), tmp_path / "mine.yaml")
    out, _ = _simulate(capsys, "--no-progress", "--knowledge", str(mine))
    folder = tmp_path / "runs" / "sim1-seed0-knowledge-mine"
    assert f"knowledge {mine}: wrote runs/sim1-seed0-knowledge-mine" in out
    metrics = json.loads((folder / "metrics.json").read_text())
    assert metrics["knowledge"] == str(mine)
    assert metrics["missed_objects"]["total"] == _expected_all_missed(2.0)
    assert metrics["false_objects"]["total"] == 0


def test_editing_knowledge_in_a_checkout_takes_effect(
    capsys: pytest.CaptureFixture[str], tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A (fake) checkout: ``pyproject.toml`` of project semwm and an edited
    ``knowledge/sim1.yaml``; ``semwm simulate sim1`` run from a sub-folder reads it."""
    (tmp_path / "pyproject.toml").write_text('[project]\nname = "semwm"\n')
    (tmp_path / "knowledge").mkdir()
    edited = _no_new_objects(shipped_knowledge_path("sim1.yaml"), tmp_path / "knowledge/sim1.yaml")
    (tmp_path / "examples").mkdir()
    monkeypatch.chdir(tmp_path / "examples")
    assert shipped_knowledge_path("sim1.yaml") == edited
    _simulate(capsys, "--no-progress", "--out", "run")
    metrics = json.loads((tmp_path / "examples/run/metrics.json").read_text())
    assert metrics["knowledge"] == str(edited)
    assert metrics["missed_objects"]["total"] == _expected_all_missed(2.0)


def test_another_projects_knowledge_folder_is_not_taken(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    (tmp_path / "pyproject.toml").write_text('[project]\nname = "other"\n')
    (tmp_path / "knowledge").mkdir()
    (tmp_path / "knowledge/sim1.yaml").write_text("not knowledge")
    monkeypatch.chdir(tmp_path)
    assert shipped_knowledge_path("sim1.yaml") != tmp_path / "knowledge/sim1.yaml"


def test_simulate_shows_a_progress_bar(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    _, err = _simulate(capsys, "--out", str(tmp_path / "run"))
    assert "sim1:" in err and "det/s" in err  # tqdm on stderr
    _, err = _simulate(capsys, "--out", str(tmp_path / "run"), "--no-progress")
    assert err == ""


def test_serve_does_not_import_the_service_until_it_runs() -> None:
    """The core's command line imports ``api`` (FastAPI) only inside ``semwm serve``."""
    code = "import sys, semwm.cli; semwm.cli.build_parser(); print('api' in sys.modules)"
    result = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=60, check=True
    )
    assert result.stdout.strip() == "False"
    assert build_parser().prog == "semwm"
