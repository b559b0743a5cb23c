"""Knowledge ablations and the simulate command's argument parsing."""

from __future__ import annotations

import pytest

from semwm.cli.common import Parser
from semwm.cli.simulate import add_simulate_command
from semwm.knowledge.loader import load_document
from semwm.knowledge.resolve import resolve
from semwm.knowledge.shipped import shipped_knowledge_path
from semwm.sim.ablations import ablate, without_appearance_relations, without_taxonomy
from semwm.sim.runner import taxonomy_of


def test_without_appearance_relations_removes_the_door_relation_only() -> None:
    document = load_document(shipped_knowledge_path("sim2.yaml"))
    before = resolve(document)
    assert before.classes["Person"].appearance  # the shipped file has the door relation
    after = resolve(without_appearance_relations(document))
    assert after.classes["Person"].appearance == ()
    assert after.classes["Person"].new_frequency == before.classes["Person"].new_frequency
    assert after.known_objects == before.known_objects


def test_without_taxonomy_keeps_inherited_settings_but_no_is_a() -> None:
    document = load_document(shipped_knowledge_path("sim1.yaml"))
    before = resolve(document)
    after = resolve(without_taxonomy(document))
    assert taxonomy_of(before).compatible("Can", "CokeCan")
    assert not taxonomy_of(after).compatible("Can", "CokeCan")
    for name, resolved in before.classes.items():
        other = after.classes[name]
        assert other.parents == ()
        assert other.filter == resolved.filter
        assert other.measurement_noise == resolved.measurement_noise
        assert other.detection_frequency == resolved.detection_frequency


def test_simulate_arguments() -> None:
    parser = Parser()
    add_simulate_command(parser.add_subparsers())
    args = parser.parse_args(
        ["simulate", "sim2", "--seed", "3", "--no-knowledge", "door-relation", "--no-progress"]
    )
    assert (args.name, args.seed, args.no_knowledge, args.no_progress) == (
        "sim2",
        3,
        ["door-relation"],
        True,
    )
    assert args.out is None and args.duration is None
    with pytest.raises(SystemExit):
        parser.parse_args(["simulate", "sim2", "--no-knowledge", "everything"])


def test_ablate_applies_each_name_and_rejects_unknown_ones() -> None:
    document = load_document(shipped_knowledge_path("sim2.yaml"))
    assert ablate(document, ["door-relation"]) == without_appearance_relations(document)
    assert ablate(document, []) == document
    with pytest.raises(KeyError, match="unknown ablation 'doors'; known: door-relation, taxonomy"):
        ablate(document, ["doors"])
