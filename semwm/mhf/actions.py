"""Action hypotheses (paper 004 IV-B): a reported kick splits the hypotheses.

A robot that kicks a passive object (a ball) says so: time, direction, speed. The
world model cannot know that the kick connected, so every hypothesis holding the
object is split into two children (hypotheses in the MHF tree):

* **kicked** (prior ``kick_probability`` of the class): a new version of the
  object, at its position predicted to the kick time, with velocity
  ``speed * direction`` and a velocity covariance of ``(kick_speed_spread *
  speed)^2`` along the direction and ``(speed * kick_direction_spread)^2`` across
  it; an IMM's first-order modes take all the mode probability;
* **not kicked** (``1 - kick_probability``): the object as it was.

Both versions share the object's lineage, so the world shows one object: the one
the more probable branch holds. Later detections resolve the branches through the
ordinary association likelihoods: a ball seen along the kicked direction makes
the kicked branch win, a ball seen where it was the other. Compared with a
per-track mixture of velocity components, the branches reuse the MHF's own
machinery (weights, merging, pruning, existence), and a detection that fits
neither leaves both to the usual clutter and birth alternatives.
"""

from __future__ import annotations

import math
from collections.abc import Collection
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

import numpy as np

from semwm.filters.motion import FloatArray
from semwm.mhf.core_engine import as_python
from semwm.mhf.prune import merge, prune
from semwm.mhf.state import Cluster, Hypothesis, MHFState, StateView, Track

if TYPE_CHECKING:
    from semwm.mhf.filter import MultipleHypothesisFilter


@dataclass(frozen=True)
class Kick:
    """A kick: at ``time`` (s) the objects of ``lineages`` may have been given velocity
    ``speed`` (m/s) along the unit vector ``direction`` ``(d,)``."""

    time: float
    lineages: Collection[int]
    direction: FloatArray
    speed: float


def kicked_version(mhf: MultipleHypothesisFilter, state: StateView, key: int, kick: Kick) -> Track:
    """The version of ``key`` that the kick moved: predicted to the kick time, velocity set."""
    track = state.tracks[key]
    flt = mhf.factory.filter_for(track.cls)
    spec = mhf.knowledge.classes[track.cls]
    d = flt.dim
    predicted = mhf.predict(state, [key], kick.time)
    mean = predicted.state_mean[0]
    x = np.repeat(mean[None], flt.modes, axis=0)
    u = kick.direction
    along = (spec.kick_speed_spread * kick.speed) ** 2
    across = (kick.speed * math.radians(spec.kick_direction_spread)) ** 2
    outer = np.outer(u, u)
    velocity_cov = along * outer + across * (np.eye(d) - outer) + 1e-6 * np.eye(d)
    P = np.zeros((flt.modes, flt.state_size, flt.state_size))
    position_cov = predicted.position_covariance[0]
    P[:, :d, :d] = position_cov
    P[:, d:, d:] = velocity_cov
    x[:, d:] = kick.speed * u
    rolling = np.array([order == "first_order" for order in flt.orders], dtype=float)
    mu = rolling / rolling.sum()
    return Track(
        key=-1,
        lineage=track.lineage,
        cls=track.cls,
        label=track.label,
        x=x,
        P=P,
        mu=mu,
        time=kick.time,
        last_seen=track.last_seen,
        created=track.created,
        rate=track.rate,
        class_probs=track.class_probs,
        sources=track.sources,
    )


def apply_kick(mhf: MultipleHypothesisFilter, state: StateView, kick: Kick) -> MHFState:
    """Split every hypothesis holding a kicked object into kicked / not kicked children
    (weights ``p`` and ``1 - p``, the class's ``kick_probability``), merged and pruned
    as the tree is (paper 002 eq. 3, n_hyp,max)."""
    state = as_python(state)  # a kick makes new Python values (either engine)
    targets = [k for k, t in state.tracks.items() if t.lineage in kick.lineages]
    if not targets:
        return state
    tracks = dict(state.tracks)
    existence = dict(state.existence)
    next_key = state.next_key
    kicked: dict[int, int] = {}
    for key in targets:
        version = kicked_version(mhf, state, key, kick)
        new = Track(
            next_key,
            version.lineage,
            version.cls,
            version.label,
            version.x,
            version.P,
            version.mu,
            version.time,
            version.last_seen,
            version.created,
            version.rate,
            version.class_probs,
            version.sources,
        )
        tracks[new.key] = new
        existence[new.key] = state.existence.get(key, 1.0)
        kicked[key] = new.key
        next_key += 1
    clusters: list[Cluster] = []
    for cluster in state.clusters:
        if not cluster.keys & kicked.keys():
            clusters.append(cluster)
            continue
        children: list[tuple[frozenset[int], float, float]] = []
        for h in cluster.hypotheses:
            branches = [(h.tracks, h.log_weight)]
            for old in sorted(h.tracks & kicked.keys()):
                p = mhf.knowledge.classes[tracks[old].cls].kick_probability
                grown = []
                for held, weight in branches:
                    if p > 0.0:
                        grown.append(((held - {old}) | {kicked[old]}, weight + math.log(p)))
                    if p < 1.0:
                        grown.append((held, weight + math.log1p(-p)))
                branches = grown
            children.extend((held, weight, h.rate) for held, weight in branches)
        hypotheses: tuple[Hypothesis, ...] = prune(merge(children), mhf.ratio, mhf.max_hypotheses)
        clusters.extend(mhf._split(hypotheses, tracks))
    referenced = sorted(set().union(*(c.keys for c in clusters)))
    return replace(
        state,
        clusters=tuple(clusters),
        tracks={k: tracks[k] for k in referenced},
        next_key=next_key,
        existence={k: existence.get(k, 1.0) for k in referenced},
    )
