"""Paper 004 categories: defaults per category, passive velocity decay, static has no
velocity, foreign-controlled labels are not identities."""

from __future__ import annotations

import numpy as np
import pytest

from semwm import WorldModel
from semwm.filters.factory import build_class_filter
from semwm.filters.motion import decay_factors
from semwm.knowledge import KnowledgeError
from semwm.knowledge.loader import knowledge_from_text as load_knowledge_text
from semwm.knowledge.model import CATEGORY_DEFAULTS

BALL = """
world: {dimension: 2, region: [[-10, 10], [-10, 10]]}
classes:
- name: Ball
  category: passive
  detection_frequency: 10
  filter: {type: kalman, model: {motion_model: first_order, system_noise: [[0.01, 0], [0, 0.01]]}}
  measurement_noise: [[0.01, 0], [0, 0.01]]
  velocity_decay: {alpha}
- name: Opponent
  category: foreign_controlled
  detection_frequency: 10
  filter: {type: kalman, model: {motion_model: zeroth_order, system_noise: [[0.01, 0], [0, 0.01]]}}
  measurement_noise: [[0.01, 0], [0, 0.01]]
- name: Post
  category: static
  detection_frequency: 10
  filter: {type: kalman, model: {motion_model: zeroth_order, system_noise: [[0.01, 0], [0, 0.01]]}}
  measurement_noise: [[0.01, 0], [0, 0.01]]
detectors: [{name: camera, clutter_frequency: 0.1}]
"""


def closed_form(p0: np.ndarray, v0: np.ndarray, alpha: float, t: float) -> tuple[np.ndarray, ...]:
    """Constant deceleration alpha along v0 until the object stops at t = |v0| / alpha."""
    speed = float(np.linalg.norm(v0))
    direction = v0 / speed
    tau = min(t, speed / alpha)
    travelled = speed * tau - alpha * tau**2 / 2.0
    return p0 + direction * travelled, direction * max(0.0, speed - alpha * t)


@pytest.mark.parametrize("step", [0.05, 0.1, 0.7])
def test_passive_velocity_decays_as_the_closed_form(step: float) -> None:
    knowledge = load_knowledge_text(BALL.replace("{alpha}", "0.5"), "yaml")
    flt = build_class_filter(knowledge.classes["Ball"], 2)
    p0, v0 = np.array([1.0, -2.0]), np.array([1.2, 1.6])  # 2 m/s: stops after 4 s, 4 m
    x = np.concatenate([p0, v0])[None, None, :]
    P = np.eye(4)[None, None] * 0.01
    mu = np.ones((1, 1))
    t = 0.0
    while t < 6.0:
        x, P, mu = flt.predict(x, P, mu, np.array([step]))
        t += step
        position, velocity = closed_form(p0, v0, 0.5, t)
        np.testing.assert_allclose(x[0, 0, :2], position, atol=1e-9)
        np.testing.assert_allclose(x[0, 0, 2:], velocity, atol=1e-9)
        assert np.all(np.linalg.eigvalsh(P[0, 0]) > 0.0)
    np.testing.assert_allclose(x[0, 0, :2], p0 + np.array([0.6, 0.8]) * 4.0, atol=1e-9)


def test_the_papers_discrete_rule_converges_to_the_same_motion() -> None:
    alpha, dt = 0.5, 1e-4
    p, v = np.zeros(2), np.array([2.0, 0.0])
    for _ in range(int(3.0 / dt)):
        p = p + v * dt
        speed = float(np.linalg.norm(v))
        v = v / speed * max(0.0, speed - alpha * dt) if speed > 0 else v
    g, k = decay_factors(np.array([2.0]), np.array([3.0]), alpha)
    np.testing.assert_allclose(p, np.array([2.0, 0.0]) * g[0], atol=1e-3)
    np.testing.assert_allclose(v, np.array([2.0, 0.0]) * k[0], atol=1e-9)


def test_no_decay_is_constant_velocity() -> None:
    knowledge = load_knowledge_text(BALL.replace("{alpha}", "0.0"), "yaml")
    flt = build_class_filter(knowledge.classes["Ball"], 2)
    x = np.array([[[0.0, 0.0, 1.0, 2.0]]])
    x2, _, _ = flt.predict(x, np.eye(4)[None, None], np.ones((1, 1)), np.array([3.0]))
    np.testing.assert_allclose(x2[0, 0], [3.0, 6.0, 1.0, 2.0])


def test_category_defaults_apply_and_a_class_overrides_them() -> None:
    knowledge = load_knowledge_text(BALL.replace("  velocity_decay: {alpha}\n", ""), "yaml")
    ball, opponent, post = (knowledge.classes[n] for n in ("Ball", "Opponent", "Post"))
    assert ball.velocity_decay == CATEGORY_DEFAULTS["passive"]["velocity_decay"] > 0.0
    assert post.confidence_decay == 0.0 and post.confidence_decay_distance > 0.0
    assert opponent.trust_labels is False and ball.trust_labels is True
    overridden = load_knowledge_text(BALL.replace("{alpha}", "1.25"), "yaml")
    assert overridden.classes["Ball"].velocity_decay == 1.25


def test_a_static_class_with_velocity_is_refused() -> None:
    text = BALL.replace("{alpha}", "0.5").replace("category: passive", "category: static")
    with pytest.raises(KnowledgeError, match="static"):
        load_knowledge_text(text, "yaml")


def test_thresholds_must_be_ordered() -> None:
    text = BALL.replace(
        "  velocity_decay: {alpha}",
        "  suspicious_confidence: 0.2\n  invalid_confidence: 0.4",
    )
    with pytest.raises(KnowledgeError, match="invalid_confidence"):
        load_knowledge_text(text, "yaml")


def test_foreign_controlled_labels_are_not_identities() -> None:
    wm = WorldModel(load_knowledge_text(BALL.replace("{alpha}", "0.5"), "yaml"))
    wm.ingest({"time": 0.0, "class": "Opponent", "position": [1.0, 1.0], "label": "r7"})
    wm.ingest({"time": 0.0, "class": "Ball", "position": [3.0, 1.0], "label": "b"})
    labels = {o.cls: o.label for o in wm.world(min_existence=0.01).objects}
    assert labels == {"Opponent": None, "Ball": "b"}
