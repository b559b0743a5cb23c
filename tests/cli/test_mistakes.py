"""A user's common mistakes at the command line (issue 31, case 2), each run as the
user runs it (a subprocess): one clear message, a non-zero exit, no traceback and
no file left behind.

A missing optional extra is simulated by hiding its module (``sys.modules[name] =
None``, which ``importlib.util.find_spec`` reports as not installed), so the test
runs in the test environment that has every extra.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from semwm.knowledge.shipped import shipped_knowledge_path

BROKEN = """\
world:
  dimension: 2
  pruning_ratio: -1
classes:
  - name: Thing
    bogus: 3
    detection_frequency: 10.0
    new_frequency: 0.05
    filter:
      type: kalman
      model:
        motion_model: zeroth_order
        system_noise: [[0.0001, 0], [0, 0.0001]]
    measurement_noise: [[0.0025, 0], [0, 0.0025]]
detectors:
  - name: camera
    clutter_frequency: 0.1
"""


def semwm(
    cwd: Path, *argv: str, hide: str | None = None, timeout: float = 120.0
) -> subprocess.CompletedProcess[str]:
    """``semwm ARGV`` in ``cwd``; ``hide`` makes that module look not installed."""
    hiding = f"sys.modules[{hide!r}] = None; " if hide else ""
    code = f"import sys; {hiding}from semwm.cli import main; sys.exit(main(sys.argv[1:]))"
    return subprocess.run(
        [sys.executable, "-c", code, *argv],
        cwd=cwd,
        capture_output=True,
        text=True,
        timeout=timeout,
        check=False,
    )


def assert_clean(result: subprocess.CompletedProcess[str], *messages: str) -> None:
    output = result.stdout + result.stderr
    assert result.returncode != 0, output
    assert "Traceback" not in output, output
    for message in messages:
        assert message in output, output


@pytest.fixture
def folder(tmp_path: Path) -> Path:
    (tmp_path / "broken.yaml").write_text(BROKEN, encoding="utf-8")
    (tmp_path / "warehouse.yaml").write_text(
        shipped_knowledge_path("grid.yaml").read_text(encoding="utf-8"), encoding="utf-8"
    )
    return tmp_path


def test_serve_with_a_broken_knowledge_file_prints_its_problems(folder: Path) -> None:
    result = semwm(folder, "serve", "--knowledge", "broken.yaml", "--port", "0")
    assert_clean(
        result,
        "broken.yaml:3: expected a number >= 0, found -1 (at world.pruning_ratio)",
        "broken.yaml:6: unknown key 'bogus'",
        "semwm serve: broken.yaml: 2 problems (above); the server did not start",
    )
    # the same lines as `knowledge validate`
    validate = semwm(folder, "knowledge", "validate", "broken.yaml")
    for line in validate.stdout.splitlines():
        assert line in result.stderr


def test_simulate_with_knowledge_lacking_the_scenarios_classes(folder: Path) -> None:
    result = semwm(folder, "simulate", "sim1", "--knowledge", "warehouse.yaml", "--out", "run")
    assert_clean(
        result,
        "semwm simulate: warehouse.yaml has no class 'BeerCan', class 'Can', class 'CokeCan', "
        "class 'Cup', class 'Table' that scenario sim1 detects",
    )
    assert len(result.stderr.strip().splitlines()) == 1
    assert not (folder / "run").exists()


def test_simulate_duration_of_a_fixed_length_scenario_is_ignored_with_a_note(
    folder: Path,
) -> None:
    result = semwm(
        folder, "simulate", "corner_occlusion", "--duration", "2", "--no-progress", "--out", "r"
    )
    assert result.returncode == 0, result.stderr
    assert "Traceback" not in result.stderr
    assert "corner_occlusion has a fixed duration; --duration ignored" in result.stderr


def test_serve_record_without_the_mcap_extra(folder: Path) -> None:
    result = semwm(
        folder,
        "serve",
        "--knowledge",
        "warehouse.yaml",
        "--record",
        "x.mcap",
        "--port",
        "0",
        hide="mcap",
    )
    assert_clean(result, 'semwm serve: --record needs mcap: pip install "semwm[mcap]"')
    assert not (folder / "x.mcap").exists()


def test_record_without_the_mcap_extra(folder: Path) -> None:
    result = semwm(folder, "record", "sim1", "out.mcap", "--no-progress", hide="mcap")
    assert_clean(result, 'semwm record: recording needs mcap: pip install "semwm[mcap]"')
    assert sorted(p.name for p in folder.iterdir()) == ["broken.yaml", "warehouse.yaml"]


def test_replay_of_an_mcap_file_without_the_mcap_extra(folder: Path) -> None:
    result = semwm(folder, "replay", "old.mcap", "--out", "r", hide="mcap")
    assert_clean(result, 'replaying an MCAP file needs mcap: pip install "semwm[mcap]"')


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--token", "short"], "semwm serve: token must have at least 8 characters"),
        (["--port", "99999"], "semwm serve: --port: Input should be less than or equal to 65535"),
        (["--max-body", "-3"], "semwm serve: --max-body: "),
    ],
)
def test_serve_setting_mistakes_name_the_option(
    folder: Path, argv: list[str], message: str
) -> None:
    result = semwm(folder, "serve", "--knowledge", "warehouse.yaml", *argv)
    assert_clean(result, message)
    assert ": :" not in result.stderr and "Value error" not in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["serve", "--knowledge", "nothere.yaml"], "semwm serve: nothere.yaml: no such file"),
        (["replay", "nothere.jsonl", "--out", "r"], "nothere.jsonl: No such file or directory"),
        (["replay", "nothere", "--out", "r"], "nothere: no such file or directory, and not a"),
        (["replay", "nothere.mcap"], "nothere.mcap: No such file or directory"),
        (
            ["simulate", "sim1", "--knowledge", "nothere.yaml"],
            "semwm simulate: nothere.yaml: No such file or directory",
        ),
    ],
)
def test_missing_files_are_one_line(folder: Path, argv: list[str], message: str) -> None:
    result = semwm(folder, *argv)
    assert_clean(result, message)
    assert "[Errno" not in result.stderr
    assert sorted(p.name for p in folder.iterdir()) == ["broken.yaml", "warehouse.yaml"]


def test_help_lists_every_scenario(folder: Path) -> None:
    from semwm.sim.scenarios import SCENARIOS

    result = semwm(folder, "--help")
    assert result.returncode == 0
    listed = " ".join(result.stdout.split())  # the list is wrapped
    for name in [*SCENARIOS, "kick"]:
        assert f" {name}," in listed or f" {name};" in listed, name


def test_replay_of_a_ros2_bag_without_the_ros2_extra(folder: Path) -> None:
    result = semwm(
        folder, "replay", "bag", "--ros2-detections", "/detections", "--out", "r", hide="rosbags"
    )
    assert_clean(result, 'reading a ROS 2 bag needs rosbags: pip install "semwm[ros2]"')
    assert not (folder / "r").exists()


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--data-dir", "warehouse.yaml"], "--data-dir warehouse.yaml: exists and is not a folder"),
        (["--record", "nothere/x.mcap"], "--record nothere/x.mcap: no such folder nothere/"),
    ],
)
def test_serve_paths_that_cannot_be_used(folder: Path, argv: list[str], message: str) -> None:
    result = semwm(folder, "serve", "--knowledge", "warehouse.yaml", "--port", "0", *argv)
    assert_clean(result, f"semwm serve: {message}")
    assert not (folder / "nothere").exists()


def test_replay_into_knowledge_that_refuses_everything_says_why(folder: Path) -> None:
    result = semwm(folder, "replay", "sim1", "--knowledge", "warehouse.yaml", "--out", "r",
                   "--no-progress")  # fmt: skip
    assert result.returncode == 0 and "Traceback" not in result.stderr
    assert "0 batches, 0 detections, 51 refused" in result.stdout
    assert (
        "warning: the first refused batch: 0.class: unknown class 'Cup'; known classes: Thing; "
        "1.class: unknown class 'CokeCan'; known classes: Thing (and 2 more)"
    ) in result.stdout


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--speed", "-1"], "argument --speed: expected a number > 0, found '-1'"),
        (["--ros2-out", "nothere/bag"], "--ros2-out nothere/bag: no such folder nothere/"),
    ],
)
def test_replay_option_mistakes(folder: Path, argv: list[str], message: str) -> None:
    result = semwm(folder, "replay", "sim1", "--out", "r", "--no-progress", *argv)
    assert_clean(result, message)
    assert sorted(p.name for p in folder.iterdir()) == ["broken.yaml", "warehouse.yaml"]
