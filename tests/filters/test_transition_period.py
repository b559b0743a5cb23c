"""An IMM transition stated over a time (``transition_period``): T(dt) = T^(dt / period),
so how often modes mix does not depend on how often scans come."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from semwm.filters import batched
from semwm.knowledge.loader import knowledge_from_text
from semwm.knowledge.problems import KnowledgeError

from ._oracle import class_filter, make_scenario

T = np.array([[0.9, 0.1], [0.3, 0.7]])


def imm_filter(period: float | None):  # type: ignore[no-untyped-def]
    flt = class_filter(make_scenario(np.random.default_rng(0), "imm", 2))
    return replace(flt, transition=T, transition_period=period)


def test_one_period_is_the_stated_matrix_and_steps_compose() -> None:
    flt = imm_filter(0.2)
    np.testing.assert_allclose(flt.transitions(np.array([0.2]))[0], T, atol=1e-12)
    a, b = flt.transitions(np.array([0.05, 0.13]))
    np.testing.assert_allclose(a @ b, flt.transitions(np.array([0.18]))[0], atol=1e-12)
    tiny = flt.transitions(np.array([1e-6]))[0]
    np.testing.assert_allclose(tiny, np.eye(2), atol=1e-4)
    np.testing.assert_allclose(tiny.sum(axis=1), 1.0)


def test_without_a_period_the_matrix_applies_once_per_step() -> None:
    flt = imm_filter(None)
    assert flt.transitions(np.array([0.001, 5.0])) is flt.transition


def test_five_small_steps_mix_like_one_frame_with_a_period_and_five_times_without() -> None:
    x, P, mu = (a[:1] for a in imm_filter(None).initial_states(np.zeros((1, 2))))
    mu = np.array([[1.0, 0.0]])
    for period, expected in ((1 / 30, T[0]), (None, np.linalg.matrix_power(T, 5)[0])):
        flt = imm_filter(period)
        m = mu
        xs, Ps = x, P
        for _ in range(5):  # five sources 1/150 s apart: one 30 Hz frame
            xs, Ps, m = flt.predict(xs, Ps, m, np.array([1 / 150]))
        np.testing.assert_allclose(m[0], expected, atol=1e-9)


def test_mixing_with_one_matrix_per_object_equals_mixing_each_alone() -> None:
    flt = imm_filter(0.2)
    rng = np.random.default_rng(0)
    x = rng.normal(size=(3, 2, flt.state_size))
    P = np.broadcast_to(np.eye(flt.state_size), (3, 2, flt.state_size, flt.state_size)).copy()
    mu = np.array([[0.2, 0.8], [0.5, 0.5], [0.9, 0.1]])
    Ts = flt.transitions(np.array([0.1, 0.2, 0.7]))
    together = batched.imm_mix(x, P, mu, Ts)
    for n in range(3):
        alone = batched.imm_mix(x[n : n + 1], P[n : n + 1], mu[n : n + 1], Ts[n])
        for got, want in zip(together, alone, strict=True):
            np.testing.assert_allclose(got[n], want[0], atol=1e-12)


def test_a_matrix_that_cannot_be_scaled_in_time_is_a_knowledge_error_with_its_line() -> None:
    text = """world: {dimension: 2, region: [[0, 10], [0, 10]]}
classes:
- name: Robot
  detection_frequency: 10
  filter:
    type: imm
    models:
    - {motion_model: zeroth_order, system_noise: [[0.01, 0], [0, 0.01]]}
    - {motion_model: first_order, system_noise: [[1, 0], [0, 1]]}
    transition_matrix: [[0.2, 0.8], [0.8, 0.2]]
    transition_period: 0.1
  measurement_noise: [[0.01, 0], [0, 0.01]]
detectors:
- {name: camera, clutter_frequency: 1}
"""
    with pytest.raises(KnowledgeError) as caught:
        knowledge_from_text(text, "yaml", source="robots.yaml")
    message = str(caught.value)
    assert "robots.yaml:10" in message and "positive eigenvalues" in message
