"""`semwm knowledge validate` warnings: knowledge that loads but will not do what its
author wants, each at its FILE:LINE (semwm/knowledge/advice.py)."""

from __future__ import annotations

from pathlib import Path

import pytest

from semwm.cli import main
from semwm.knowledge.loader import analyse_text

BASE = """\
world:
  dimension: 2
  region: [[0, 10], [0, 10]]{world}
classes:
  - name: Cup
    detection_frequency: {f}
    new_frequency: {new}{cls}
    filter:
      type: kalman
      model: {{motion_model: zeroth_order, system_noise: [[1.0e-6, 0], [0, 1.0e-6]]}}
    measurement_noise: [[{r}, 0], [0, {r}]]
detectors:
  - name: camera
    clutter_frequency: {c}
"""


def _warnings(**values: object) -> list[str]:
    fields = {"world": "", "f": 5.0, "new": 0.05, "cls": "", "r": 0.0025, "c": 1.0} | values
    analysis = analyse_text(BASE.format(**fields), "yaml", "mine.yaml")
    assert analysis.knowledge is not None, analysis.problems
    return [str(w) for w in analysis.warnings]


def test_datasheet_values_give_no_warning() -> None:
    assert _warnings() == []


def test_a_class_that_can_never_appear() -> None:
    (warning,) = _warnings(new=0.0)
    assert warning.startswith("mine.yaml:7: warning: no object of class 'Cup' can ever appear")


def test_objects_that_are_never_removed() -> None:
    (warning,) = _warnings(f=0.0, cls="\n    leave_frequency: 0")
    assert "mine.yaml:5: warning: objects of class 'Cup' are never removed" in warning


def test_detections_that_never_confirm_an_object() -> None:
    """Noise 1 m^2 against 50 Hz of clutter over 100 m^2: a detection fits an object no
    better than clutter."""
    (warning,) = _warnings(r=1.0, c=50.0)
    assert "is never confirmed" in warning and warning.startswith("mine.yaml:13: warning:")


def test_newborns_removed_before_their_second_detection() -> None:
    (warning,) = _warnings(world="\n  removal_existence: 0.01")
    assert "removal_existence" in warning and warning.startswith("mine.yaml:4: warning:")


def test_the_literal_paper_model() -> None:
    (warning,) = _warnings(world="\n  association_model: paper")
    assert warning.startswith("mine.yaml:4: warning: association_model 'paper'")


def test_validate_prints_warnings_and_exits_0(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = tmp_path / "mine.yaml"
    fields = {"world": "", "f": 5.0, "new": 0.0, "cls": "", "r": 0.0025, "c": 1.0}
    path.write_text(BASE.format(**fields), encoding="utf-8")
    assert main(["knowledge", "validate", str(path)]) == 0
    out = capsys.readouterr().out
    assert f"{path}:7: warning: no object of class 'Cup' can ever appear" in out
    assert f"{path}: OK" in out


def test_removed_unseen_before_its_confidence_turns_invalid_is_warned() -> None:
    """Issue 28: C3 at 1 s with the default decay (0.1/s: invalid after 14 s) removes an
    unseen cup long before a robot could learn that it should go and look."""
    (warning,) = _warnings(cls="\n    max_time_without_update: 1.0")
    assert "removed by C3 about 1 s" in warning and warning.startswith("mine.yaml:")
    assert _warnings(cls="\n    max_time_without_update: 1.0\n    confidence_decay: 2.0") == []


def test_p_max_reached_before_invalid_is_warned() -> None:
    """A walking person's covariance passes P_max within seconds of its last detection."""
    person = (
        "\n    max_position_variance: 0.01\n    initial_velocity_covariance: [[1.0, 0], [0, 1.0]]"
    )
    text = BASE.format(world="", f=5.0, new=0.05, cls=person, r=0.0025, c=1.0).replace(
        "motion_model: zeroth_order, system_noise: [[1.0e-6, 0], [0, 1.0e-6]]",
        "motion_model: first_order, system_noise: [[1.0, 0], [0, 1.0]]",
    )
    analysis = analyse_text(text, "yaml", "mine.yaml")
    assert analysis.knowledge is not None, analysis.problems
    (warning,) = [str(w) for w in analysis.warnings]
    assert "removed by P_max" in warning and "max_position_variance" in warning
