"""Two levels within 10 % of flat (issue 28, item 7).

A short robocup team match (5 peers, 5 opponents, 2 s, latency 20-150 ms, ideal
clocks) played flat and through local models reporting to a global one. Before the
fix the two-level GOSPA was 20 % (seed 3) and 31 % (seed 15) above flat: robots'
tracked estimates of other robots, sent with their filtered covariance, fell
outside the global gate of the peer's own pose and started duplicates, and the
global view, which learns velocity from reported positions only, lagged
accelerating robots until the next periodic report.
"""

from __future__ import annotations

import numpy as np
import pytest

from semwm.knowledge.loader import load_knowledge
from semwm.knowledge.shipped import shipped_knowledge_path
from semwm.sim.scenarios import make_scenario
from semwm.sim.team_run import Network, run_team
from semwm.team import TRACKED_FACTOR, LocalModel, Strategy


@pytest.mark.parametrize("seed", [3, 15])
def test_two_levels_are_within_ten_percent_of_flat(seed: int) -> None:
    knowledge = load_knowledge(shipped_knowledge_path("robocup.yaml"))
    scenario = make_scenario("robocup", seed, duration=2.0)
    network = Network(0.0, (0.02, 0.15))
    flat = run_team(scenario, knowledge, levels=1, network=network, seed=seed)
    two = run_team(scenario, knowledge, levels=2, network=network, seed=seed)
    flat_gospa = flat.result.metrics.gospa.total
    two_gospa = two.result.metrics.gospa.total
    assert two_gospa <= 1.10 * flat_gospa, (seed, flat_gospa, two_gospa)
    assert two.messages < flat.messages  # still fewer messages than flat


def test_updated_widens_tracked_objects_but_not_the_robots_own_pose() -> None:
    robocup = load_knowledge(shipped_knowledge_path("robocup.yaml"))
    local = LocalModel("peer1", robocup, Strategy.UPDATED)
    for i in range(4):
        t = i / 30
        local.ingest(
            [
                {"time": t, "class": "Peer", "position": [0.0, 0.0], "source": "peer1",
                 "detector": "self_localization", "label": "peer1"},
                {"time": t, "class": "Robot", "position": [2.0, 1.0], "source": "peer1"},
            ]
        )  # fmt: skip
    report = local.report()
    assert report is not None
    sent = {str(d["class"]): np.asarray(d["covariance"]) for d in report.detections}
    objects = {o.cls: np.asarray(o.covariance) for o in local.world().objects}
    np.testing.assert_allclose(sent["Peer"], objects["Peer"])
    np.testing.assert_allclose(sent["Robot"], TRACKED_FACTOR * objects["Robot"])


def test_a_horizon_reports_an_accelerating_object_before_it_has_drifted() -> None:
    # A ball lying still, reported every 0.1 s, then rolling off: the global view
    # (no velocity yet) is still inside the gate now but will not be at the next
    # periodic report. With the horizon the robot reports at the first scans of the
    # roll, without it only once the view has drifted.
    robocup = load_knowledge(shipped_knowledge_path("robocup.yaml"))

    def first_due(horizon: float) -> int:
        local = LocalModel("r1", robocup)
        for i in range(60):
            x = 0.0 if i < 30 else 3.0 * (i - 30) / 30
            local.ingest([{"time": i / 30, "class": "Ball", "position": [x, 0.0], "source": "r1"}])
            if i % 3 == 0:
                local.report()
            elif local.due(drift_gate=0.95, horizon=horizon):
                if i >= 30:  # (before: the ball's first report, once it is published)
                    return i
                local.report()
        return 60

    assert 30 < first_due(0.1) < first_due(0.0) < 60
