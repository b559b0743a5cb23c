"""Public ids stay consistent when a replay (a late report, the reorder window) brings a
lineage back that had been lost: it takes its own lost id back, and a lost id handed
over to another object never takes the id of an object shown now (a KeyError in
``WorldModel._publish`` stopped a two-level RoboCup run: seed 10, ``information``
reports, at 1.7 s)."""

from __future__ import annotations

from semwm.knowledge.loader import load_knowledge
from semwm.knowledge.shipped import shipped_knowledge_path
from semwm.sim.scenarios import make_scenario
from semwm.sim.team_run import Network, run_team


def test_a_two_level_run_whose_replays_bring_lineages_back_keeps_one_id_each() -> None:
    knowledge = load_knowledge(shipped_knowledge_path("robocup.yaml"))
    scenario = make_scenario("robocup", 10, duration=2.0)
    team = run_team(
        scenario,
        knowledge,
        levels=2,
        network=Network(0.0, (0.02, 0.15)),
        strategy="information",
        seed=10,
    )
    for world in team.result.worlds:
        ids = [o.id for o in world.objects]
        assert len(ids) == len(set(ids))
