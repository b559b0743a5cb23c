"""Two levels within 10 % of flat (issue 28, item 7).

A robot's filtered estimate re-sent every period is filtered again by the global
model, whose gain on it is about 0.4: the global view lags the robot's own. The
``detections`` strategy sends the detections behind an estimate instead (each once),
so the global filters independent measurements once, as flat does.

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
from semwm.knowledge.model import Knowledge
from semwm.knowledge.shipped import shipped_knowledge_path
from semwm.sim.scenarios import make_scenario
from semwm.sim.team_run import Network, run_team
from semwm.team import (
    TRACKED_FACTOR,
    LocalModel,
    Strategy,
    Taken,
    combine_detections,
    global_knowledge,
)
from semwm.world import WorldModel


@pytest.fixture(scope="module")
def robocup() -> Knowledge:
    return load_knowledge(shipped_knowledge_path("robocup.yaml"))


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


def test_combined_detections_are_the_least_squares_position_at_the_report_time() -> None:
    R1 = np.array([[0.09, 0.0], [0.0, 0.04]])
    R2 = np.array([[0.04, 0.01], [0.01, 0.09]])
    taken = [Taken(0.9, np.array([1.0, 2.0]), R1), Taken(1.0, np.array([1.5, 1.8]), R2)]
    z, C = combine_detections(taken, (2.0, -1.0), 1.0)
    # moved to t = 1.0 by v = (2, -1): (1.2, 1.9) and (1.5, 1.8); weighted by R^-1
    W1, W2 = np.linalg.inv(R1), np.linalg.inv(R2)
    expected_C = np.linalg.inv(W1 + W2)
    np.testing.assert_allclose(C, expected_C, atol=1e-15)
    np.testing.assert_allclose(z, expected_C @ (W1 @ [1.2, 1.9] + W2 @ [1.5, 1.8]))
    # three equal noises: the mean, R / 3
    same = [Taken(1.0, np.array([x, 0.0]), R1) for x in (0.0, 0.3, 0.9)]
    z, C = combine_detections(same, None, 1.0)
    np.testing.assert_allclose(z, [0.4, 0.0])
    np.testing.assert_allclose(C, R1 / 3.0)


def test_detections_reports_each_detection_once(robocup: Knowledge) -> None:
    # A robot at the origin sees itself and a robot standing at (2, 1), three scans
    # per report: each report holds that period's three detections, combined, never
    # an earlier period's again (the global model counts nothing twice).
    local = LocalModel("peer1", robocup, Strategy.DETECTIONS)
    rng = np.random.default_rng(3)
    seen: list[list[float]] = []
    for period in range(3):
        for i in range(3):
            t = (3 * period + i) / 30
            z = np.array([2.0, 1.0]) + rng.normal(0.0, 0.3, 2)
            seen.append(list(z))
            local.ingest(
                [
                    {"time": t, "class": "Peer", "position": [0.0, 0.0], "source": "peer1",
                     "detector": "self_localization", "label": "peer1"},
                    {"time": t, "class": "Robot", "position": list(z), "source": "peer1"},
                ]
            )  # fmt: skip
        report = local.report()
        assert report is not None
        if period == 0:
            continue  # the robot is published from its second detection on
        sent = {str(d["class"]): d for d in report.detections}
        robot = next(o for o in local.world().objects if o.label is None)
        velocity = np.asarray(robot.velocity)
        moved = [np.add(z, velocity * (report.time - (len(seen) - 3 + k) / 30)) for k, z in
                 enumerate(seen[-3:])]  # fmt: skip
        np.testing.assert_allclose(sent["Robot"]["position"], np.mean(moved, axis=0))
        R = np.asarray(robocup.classes["Robot"].measurement_noise)
        np.testing.assert_allclose(sent["Robot"]["covariance"], R / 3.0, atol=1e-15)
        own = np.asarray(robocup.detectors["self_localization"].measurement_noise["Peer"])
        np.testing.assert_allclose(sent["Peer"]["covariance"], own / 3.0, atol=1e-15)


def _alone(strategy: Strategy, seed: int, robocup: Knowledge) -> tuple[float, float]:
    """One robot tracks a robot that starts and stops; it reports every third scan.
    Mean error (m) at the reports of its own estimate and of the global model's."""
    rng = np.random.default_rng(seed)
    local = LocalModel("r1", robocup, strategy)
    global_model = WorldModel(global_knowledge(robocup))
    p, v = np.zeros(2), np.zeros(2)
    own, team = [], []
    for k in range(120):
        t = k / 30
        if k % 20 == 0:
            v = rng.uniform(-3.0, 3.0, 2) if rng.random() < 0.7 else np.zeros(2)
        p = p + v / 30
        z = p + rng.normal(0.0, 0.3, 2)
        local.ingest([{"time": t, "class": "Opponent", "position": list(z), "source": "r1"}])
        if k % 3:
            continue
        report = local.report()
        if report is not None:
            global_model.ingest(list(report.detections))
        if t > 0.5:
            (mine,) = local.world().objects
            (ours,) = global_model.world(time=t).objects
            own.append(float(np.linalg.norm(np.subtract(mine.position, p))))
            team.append(float(np.linalg.norm(np.subtract(ours.position, p))))
    return float(np.mean(own)), float(np.mean(team))


@pytest.mark.parametrize("strategy", [Strategy.DETECTIONS, Strategy.SCANS])
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_the_global_view_of_an_object_one_robot_sees_is_as_good_as_the_robots(
    seed: int, strategy: Strategy, robocup: Knowledge
) -> None:
    # With "updated" the global view lags the robot's own estimate (seeds 0-5: 0.227
    # against 0.167 m): it filters the robot's filtered estimate again.
    own, team = _alone(strategy, seed, robocup)
    assert team <= 1.05 * own, (own, team)
