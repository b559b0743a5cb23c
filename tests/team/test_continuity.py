"""Two levels (issue 28 item 7): a robot's report stays on the global object its local
object went to before (:class:`semwm.team.Continuity`), instead of starting a duplicate.

The scene is seed 9's (docs/team.md): robot ``peer2`` tracks ``peer1`` and reports it
(unlabelled, local id 7) while ``peer1`` reports its own precise pose. Then a few of
``peer2``'s detections stray and their combination, precise, lies 0.9 m off: outside
the gate of ``peer1``'s global object. Associated afresh, it starts a second object
(the old behaviour); kept on the object it went to, the world holds one ``peer1``.
Both engines (``SEMWM_ENGINE``) run it: nothing in the MHF changed.
"""

from __future__ import annotations

import numpy as np
import pytest

from semwm.detection import Detection
from semwm.knowledge.loader import load_knowledge
from semwm.knowledge.shipped import shipped_knowledge_path
from semwm.team import LOCAL_DETECTOR, Continuity, global_knowledge
from semwm.world import WorldModel
from semwm.world_types import WorldState


@pytest.fixture(scope="module")
def robocup():  # type: ignore[no-untyped-def]
    return load_knowledge(shipped_knowledge_path("robocup.yaml"))


def own_pose(t: float) -> list[Detection]:
    """``peer1``'s report of itself at (0, 0): labelled, precise."""
    return [
        Detection.model_validate(
            {
                "time": t,
                "class": "Peer",
                "position": [0.0, 0.0],
                "covariance": [[0.01, 0.0], [0.0, 0.01]],
                "source": "peer1",
                "detector": LOCAL_DETECTOR,
                "label": "peer1",
            }
        )
    ]


def seen(t: float, x: float, variance: float) -> list[Detection]:
    """``peer2``'s report of the robot it tracks at ``(x, 0)``."""
    return [
        Detection.model_validate(
            {
                "time": t,
                "class": "Robot",
                "position": [x, 0.0],
                "covariance": [[variance, 0.0], [0.0, variance]],
                "source": "peer2",
                "detector": LOCAL_DETECTOR,
            }
        )
    ]


def play(robocup, keep: Continuity | None, stray: tuple[int, ...] = (6, 8)) -> list[WorldState]:  # type: ignore[no-untyped-def]
    """The reports in time order, ``peer2``'s of the steps ``stray`` stray (precise, 0.9 m
    off); the world after each step from the first stray one."""
    model = WorldModel(global_knowledge(robocup))

    def report(detections: list[Detection]) -> None:
        if keep is not None and detections[0].source == "peer2":
            keep.ingest(model, "peer2", detections, [7])
        else:
            model.ingest(detections)

    worlds = []
    for step in range(11):  # peer2's object 7 joins peer1's global object, then strays
        t = 0.1 * step
        report(own_pose(t))
        report(seen(t + 0.05, 0.9, 0.01) if step in stray else seen(t + 0.05, 0.1, 0.05))
        if step >= stray[0]:
            worlds.append(model.world())
    return worlds


def test_a_robots_stray_report_starts_a_duplicate_when_associated_afresh(robocup) -> None:  # type: ignore[no-untyped-def]
    """Without continuity (the old behaviour): the duplicate this guards against."""
    worlds = play(robocup, None)
    assert len(worlds[0].objects) == 2


def test_a_robots_report_stays_on_the_global_object_it_went_to(robocup) -> None:  # type: ignore[no-untyped-def]
    keep = Continuity(robocup.world.dimension)
    worlds = play(robocup, keep)
    assert keep.widened >= 1
    for world in worlds:
        assert len(world.objects) == 1, [(o.label, o.position) for o in world.objects]
        (obj,) = world.objects
        assert obj.label == "peer1"
        assert float(np.linalg.norm(obj.position)) < 0.3  # the precise pose still leads


def test_a_local_object_that_stays_off_its_global_object_becomes_another(robocup) -> None:  # type: ignore[no-untyped-def]
    """Patience: one report in a row is widened; a local object still outside the gate
    at its next report is another object (two robots close together), not forced on."""
    keep = Continuity(robocup.world.dimension)
    worlds = play(robocup, keep, stray=(6, 7, 8, 9, 10))
    assert keep.widened == 1
    assert len(worlds[0].objects) == 1  # the first stray report: kept on peer1
    assert len(worlds[-1].objects) == 2


def test_widen_brings_the_report_to_the_gate_edge_along_the_offset_only(robocup) -> None:  # type: ignore[no-untyped-def]
    keep = Continuity(2, probability=0.99)
    model = WorldModel(global_knowledge(robocup))
    for step in range(3):
        model.ingest(own_pose(0.1 * step))
    keep.ingest(model, "peer2", seen(0.25, 0.1, 0.05), [7])  # noted: peer1's object
    world = model.world(time=0.3)
    (obj,) = world.objects
    (far,) = keep.widen("peer2", seen(0.3, 2.0, 0.01), [7], world)
    (near,) = keep.widen("peer2", seen(0.3, 0.05, 0.01), [7], world)
    (other,) = keep.widen("peer3", seen(0.3, 2.0, 0.01), [7], world)
    assert near.covariance == other.covariance == ((0.01, 0.0), (0.0, 0.01))
    assert far.covariance is not None
    delta = np.asarray(far.position) - np.asarray(obj.position)
    S = np.asarray(obj.covariance) + np.asarray(far.covariance)
    assert float(delta @ np.linalg.solve(S, delta)) == pytest.approx(keep.gate)
    assert far.covariance[1][1] == pytest.approx(0.01)  # across the offset: unchanged


def test_the_memory_forgets_local_objects_no_longer_reported(robocup) -> None:  # type: ignore[no-untyped-def]
    """A long-running team reports new local objects all the time (ids are not reused):
    the memory keeps only those reported within ``memory`` s, not every one ever."""
    keep = Continuity(robocup.world.dimension, memory=1.0)
    model = WorldModel(global_knowledge(robocup))
    for step in range(60):  # a new local object every 0.1 s for 6 s
        t = 0.1 * step
        model.ingest(own_pose(t))
        keep.ingest(model, "peer2", seen(t + 0.01, 0.05, 0.01), [step])
    assert 1 <= len(keep) <= 30  # about 2 x memory of 0.1 s reports at most, not 60
    assert len(keep._reported) <= 30
