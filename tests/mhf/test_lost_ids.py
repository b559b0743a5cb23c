"""Ids of objects that left the published world (``WorldModel._publish_changed``): an id
waits ``id_memory`` seconds for its object, and goes to a new object found where the
lost one was, unless the lost one left: next to a target it leaves by (a disappearance
relation, ``_may_return``). Whether a lost id may return depends on its object and the
knowledge only, so it is tested once per lost id (``_returnable``) and again after a
knowledge change."""

from __future__ import annotations

from pathlib import Path

import yaml

from semwm.filters.engine import Engine
from semwm.knowledge.loader import load_knowledge
from semwm.knowledge.shipped import shipped_knowledge_path
from semwm.world import WorldModel

DOOR = (0.8, 7.2)  # sim2.yaml: people leave by the door at (0.5, 7.5), within 0.7 m
MIDDLE = (5.0, 4.0)
OTHER = (8.0, 2.0)  # seen all along, so the camera's scans miss the one that left
STEP = 0.2


class _Camera:
    """Scans of one camera every 0.2 s, each with a person at ``OTHER``."""

    def __init__(self, model: WorldModel) -> None:
        self.model = model
        self.time = 0.0

    def scans(self, until: float, *spots: tuple[float, float]) -> None:
        while self.time < until - 1e-9:
            self.model.ingest(
                [
                    {"time": round(self.time, 6), "class": "Person", "position": list(p),
                     "source": "cam"}
                    for p in (*spots, OTHER)
                ]
            )  # fmt: skip
            self.time += STEP


def _id_at(model: WorldModel, spot: tuple[float, float]) -> int:
    (found,) = [
        o.id
        for o in model.world().objects
        if (o.position[0] - spot[0]) ** 2 + (o.position[1] - spot[1]) ** 2 < 0.25
    ]
    return found


def _seen_gone_seen(model: WorldModel, spot: tuple[float, float]) -> tuple[int, bool, int]:
    """A person at ``spot`` for 2 s, gone for 2 s (no longer shown), back for 1.5 s: its
    id before, whether the id waited for it meanwhile, and the id after."""
    camera = _Camera(model)
    camera.scans(2.0, spot)
    before = _id_at(model, spot)
    camera.scans(4.0)
    assert before not in {o.id for o in model.world().objects}
    waited = before in model._lost
    camera.scans(5.5, spot)
    return before, waited, _id_at(model, spot)


def test_an_id_lost_in_the_room_goes_to_who_is_found_there(engine: Engine) -> None:
    model = WorldModel(load_knowledge(shipped_knowledge_path("sim2.yaml")), engine=engine)
    before, waited, after = _seen_gone_seen(model, MIDDLE)
    assert waited and after == before


def test_an_id_lost_at_the_door_does_not_return(engine: Engine) -> None:
    """Someone found where a person left by the door is someone else: a new id."""
    model = WorldModel(load_knowledge(shipped_knowledge_path("sim2.yaml")), engine=engine)
    before, waited, after = _seen_gone_seen(model, DOOR)
    assert not waited and after != before


def test_a_knowledge_change_tests_waiting_ids_again(engine: Engine, tmp_path: Path) -> None:
    """An id lost in the middle of the room may return (tested then); a knowledge change
    puts a second door there while it waits: the person found there is someone else."""
    path = shipped_knowledge_path("sim2.yaml")
    model = WorldModel(load_knowledge(path), engine=engine)
    camera = _Camera(model)
    camera.scans(2.0, MIDDLE)
    before = _id_at(model, MIDDLE)
    camera.scans(4.0)
    assert before in model._lost  # tested: it may return
    document = yaml.safe_load(path.read_text())
    document["known_objects"].append(
        {"class": "Door", "position": list(MIDDLE), "name": "second door"}
    )
    edited = tmp_path / "sim2_two_doors.yaml"
    edited.write_text(yaml.safe_dump(document))
    model.replace_knowledge(load_knowledge(edited))
    camera.scans(4.2)  # one scan: the waiting id is tested again, and no longer waits
    assert before not in model._lost
    camera.scans(5.5, MIDDLE)
    assert _id_at(model, MIDDLE) != before


def test_an_id_waits_id_memory_seconds(engine: Engine) -> None:
    """An id lost in the room waits ``id_memory`` (5 s) for its object while other
    objects are seen, and no longer: whoever is found there afterwards gets a new id."""
    model = WorldModel(load_knowledge(shipped_knowledge_path("sim2.yaml")), engine=engine)
    camera = _Camera(model)
    camera.scans(2.0, MIDDLE)
    before = _id_at(model, MIDDLE)
    camera.scans(6.0)
    assert before in model._lost
    camera.scans(9.0)
    assert before not in model._lost
    camera.scans(10.5, MIDDLE)
    assert _id_at(model, MIDDLE) != before


def test_the_core_decides_whether_a_lost_object_may_return_as_the_specification() -> None:
    """The Rust engine tests its lost versions in the core (``Engine.may_return``): the
    same answer as the specification's test of the same version as a ``Track``, for
    every object lost in the room, the door scenario and RoboCup, both answers met."""
    from semwm.mhf.core_engine import track_of
    from semwm.sim.runner import scans
    from semwm.sim.scenarios import make_scenario

    answers: list[tuple[bool, bool]] = []
    for name, sizes in (("sim2", {}), ("door_exits", {}), ("robocup", {"duration": 4.0})):
        for seed in (0, 1):
            scenario = make_scenario(name, seed, **sizes)
            knowledge = load_knowledge(shipped_knowledge_path(scenario.knowledge_file))
            model = WorldModel(knowledge, engine="rust")
            decide = model._may_return

            def both(pub, decide=decide):  # type: ignore[no-untyped-def]
                core_answer = decide(pub)
                answers.append((core_answer, decide(pub._replace(track=track_of(pub.track)))))
                return core_answer

            model._may_return = both  # type: ignore[method-assign]
            for scan in scans(scenario.detections):
                model.ingest(scan)
    assert answers and all(core == spec for core, spec in answers), answers
    assert {core for core, _ in answers} == {True, False}
