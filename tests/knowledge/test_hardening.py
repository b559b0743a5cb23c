"""Knowledge that would break the model is refused at its line: bounds, alias bombs,
encodings; and a written file is replaced atomically."""

from __future__ import annotations

import os
from pathlib import Path

import pytest
import yaml

from semwm.knowledge.loader import check_file, dump_document, load_document
from semwm.knowledge.model import MAX_HYPOTHESES, MAX_RATE
from semwm.knowledge.yaml_format import MAX_VALUES

KNOWLEDGE = Path(__file__).parents[2] / "knowledge"
SIM1 = (KNOWLEDGE / "sim1.yaml").read_text(encoding="utf-8")


def edited(tmp_path: Path, old: str, new: str) -> tuple[Path, int]:
    """sim1.yaml with ``old`` replaced by ``new``, and the line ``new`` is on."""
    assert old in SIM1
    text = SIM1.replace(old, new, 1)
    path = tmp_path / "edited.yaml"
    path.write_text(text, encoding="utf-8")
    line = text[: text.index(new)].count("\n") + 1
    return path, line


@pytest.mark.parametrize(
    ("old", "new", "words"),
    [
        ("region: [[0, 4], [0, 3]]", "region: [[0, .nan], [0, 3]]", "finite"),
        ("region: [[0, 4], [0, 3]]", "region: [[0, .inf], [0, 3]]", "finite"),
        ("region: [[0, 4], [0, 3]]", "region: [[0, 1e300], [0, 3]]", "<= 1e+06"),
        ("region: [[0, 4], [0, 3]]", "region: [[4, 0], [0, 3]]", "min < max"),
        ("max_hypotheses: 100", "max_hypotheses: 1000000000000", f"<= {MAX_HYPOTHESES:g}"),
        ("new_frequency: 0.05", "new_frequency: 1e308", f"<= {MAX_RATE:g}"),
        ("detection_frequency: 2.0", "detection_frequency: .nan", "finite"),
        ("pruning_ratio: 0.01", "pruning_ratio: .nan", "finite"),
    ],
)
def test_values_outside_physical_ranges_are_problems_at_their_line(
    tmp_path: Path, old: str, new: str, words: str
) -> None:
    path, line = edited(tmp_path, old, new)
    problems = [str(p) for p in check_file(path)]
    assert problems, f"{new!r} was accepted"
    assert any(p.startswith(f"{path}:{line}:") and words in p for p in problems), problems


def test_a_non_finite_matrix_entry_is_a_problem_at_its_line(tmp_path: Path) -> None:
    text = SIM1
    start = text.index("measurement_noise: [[")
    old = text[start : text.index("\n", start)]
    path, line = edited(tmp_path, old, "measurement_noise: [[.nan, 0], [0, 0.01]]")
    problems = [str(p) for p in check_file(path)]
    assert any(p.startswith(f"{path}:{line}:") and "finite" in p for p in problems), problems


ALIAS_BOMB = "a: &a [x, x, x, x, x, x, x, x, x]\n" + "".join(
    f"{b}: &{b} [{', '.join([f'*{a}'] * 9)}]\n" for a, b in zip("abcdefgh", "bcdefghi", strict=True)
)
MERGE_BOMB = "a: &a {a0: 1, a1: 1, a2: 1, a3: 1, a4: 1, a5: 1, a6: 1, a7: 1, a8: 1}\n" + "".join(
    f"{b}: &{b} {{<<: [{', '.join([f'*{a}'] * 9)}]}}\n"
    for a, b in zip("abcdefgh", "bcdefghi", strict=True)
)


def _bomb_problems(tmp_path: Path, text: str) -> list[str]:
    assert len(text) < 1000  # names 9^9 values
    path = tmp_path / "bomb.yaml"
    path.write_text(text, encoding="utf-8")
    problems = [str(p) for p in check_file(path)]
    for problem in problems:
        assert problem.startswith(f"{path}:"), problem
        assert 1 <= int(problem.split(":")[1]) <= text.count("\n"), problem
    return problems


def test_an_alias_bomb_is_a_located_problem(tmp_path: Path) -> None:
    problems = _bomb_problems(tmp_path, ALIAS_BOMB)
    assert len(problems) == 1
    assert f"more than {MAX_VALUES} values" in problems[0]


def _merges_repeat_keys() -> bool:
    """Whether this PyYAML copies a key once per merged mapping that holds it
    (PyYAML < 6.0.4; from 6.0.4 on a merge keeps each key once)."""
    node = yaml.compose("a: &a {x: 1}\nb: {<<: [*a, *a]}\n")
    merged = node.value[1][1]
    yaml.SafeLoader("").flatten_mapping(merged)
    return len(merged.value) > 1


def test_a_merge_key_bomb_is_refused_or_stays_small(tmp_path: Path) -> None:
    """9 levels of 9 merges: with a PyYAML whose merges repeat keys it would expand to
    9^9 entries and is refused at a line; with one that keeps each key once it is 9
    keys per mapping, and the file's real problems are reported at their lines."""
    problems = _bomb_problems(tmp_path, MERGE_BOMB)
    if _merges_repeat_keys():
        assert len(problems) == 1
        assert f"more than {MAX_VALUES} values" in problems[0]
    else:
        assert not any("more than" in p for p in problems), problems
        assert any("unknown key 'i'" in p for p in problems), problems


def test_a_file_that_is_not_utf8_is_a_problem_at_the_line_of_the_bad_byte(tmp_path: Path) -> None:
    path = tmp_path / "latin1.yaml"
    path.write_bytes(SIM1.encode("utf-8") + "# café\n".encode("latin-1"))
    problems = [str(p) for p in check_file(path)]
    assert problems == [
        f"{path}:{SIM1.count(chr(10)) + 1}: the file is not UTF-8 text: byte 0xe9 cannot be decoded"
    ]


def test_dump_document_replaces_the_file_whole_and_keeps_it_on_failure(tmp_path: Path) -> None:
    document = load_document(KNOWLEDGE / "sim1.yaml")
    path = tmp_path / "k.yaml"
    path.write_text("old", encoding="utf-8")
    os.chmod(path, 0o640)
    dump_document(document, path)
    assert load_document(path) == document
    assert path.stat().st_mode & 0o777 == 0o640
    assert sorted(p.name for p in tmp_path.iterdir()) == ["k.yaml"]  # no temporary left
    gone = tmp_path / "gone" / "k.yaml"
    with pytest.raises(OSError):
        dump_document(document, gone)
    assert not gone.parent.exists()
