"""Pass/fail checks of a run against issue 9's per-scenario acceptance criteria.

Each check looks at a finished run (the truth frames and the world published at
every truth time) and answers one yes/no question with a one-line reason:

* :func:`final_objects_match`: the last frame holds one object per real object,
  each with the right class (sim1: "ends with one object per real object with the
  right class").
* :func:`no_id_switch`: no truth object changes estimate id (CLEAR MOT's IDSW).
* :func:`one_id_each`: every real object is published under one id the whole run
  (sim2: "keeps the person under one id").
* :func:`inside_region`: no published object lies outside the region (sim2: "shows
  no object outside the room").
* :func:`labels_kept`: every labelled real object (a peer robot) is published in
  every frame under its label and one id (robocup: "peers keep label and id for
  the whole run").
* :func:`static_objects_kept`: every static real object, once reported, stays
  published under one id with its class while the sensor looks elsewhere (patrol).
* leftbehind (issue 28): :func:`semwm.sim.leftbehind.acceptance`'s checks of the
  run's variant, (a) and (b) with sensor poses, (c) without.

:data:`SCENARIO_CHECKS` says which checks apply to which scenario. Frames are
matched by the GOSPA assignment of :func:`semwm.sim.metrics.gospa_frame` with the
scenario's cut-off ``c``, so "one object per real object" means "within ``c``".
"""

from __future__ import annotations

from collections.abc import Callable, Hashable, Sequence
from dataclasses import dataclass

import numpy as np

from semwm.sim.leftbehind import ViewCheck, acceptance
from semwm.sim.metrics import gospa_frame
from semwm.sim.runner import RunResult, truth_points, world_points
from semwm.sim.scenarios import Region, TruthFrame
from semwm.world_types import WorldState


@dataclass(frozen=True)
class CheckResult:
    """One check of one run: its name, whether it passed, and why (one line)."""

    name: str
    passed: bool
    detail: str

    def to_dict(self) -> dict[str, object]:
        return {"name": self.name, "passed": self.passed, "detail": self.detail}


def _assignments(
    truth: Sequence[TruthFrame], worlds: Sequence[WorldState], c: float
) -> list[dict[Hashable, Hashable]]:
    """Per frame: truth id -> estimate id of the GOSPA assignment (pairs closer than c)."""
    result = []
    for frame, state in zip(truth, worlds, strict=True):
        t, e = truth_points(frame), world_points(state)
        assignment = gospa_frame(t, e, c=c).assignment
        result.append({t[i].id: e[j].id for i, j in assignment})
    return result


def final_objects_match(
    truth: Sequence[TruthFrame], worlds: Sequence[WorldState], *, c: float
) -> CheckResult:
    """The last frame: every real object matched within ``c``, no extra object, and
    every match with exactly the real object's class."""
    name = "final objects: one per real object, right class"
    if not truth:
        return CheckResult(name, False, "no truth frames")
    t, e = truth_points(truth[-1]), world_points(worlds[-1])
    frame = gospa_frame(t, e, c=c)
    wrong = [(t[i].cls, e[j].cls) for i, j in frame.assignment if t[i].cls != e[j].cls]
    problems = []
    if frame.n_missed:
        problems.append(f"{frame.n_missed} missed")
    if frame.n_false:
        problems.append(f"{frame.n_false} extra")
    if wrong:
        problems.append("wrong class " + ", ".join(f"{a} as {b}" for a, b in wrong))
    detail = f"{len(e)} objects for {len(t)} real"
    if problems:
        detail += f" ({'; '.join(problems)})"
    return CheckResult(name, not problems, detail)


def no_id_switch(id_switches: int) -> CheckResult:
    """No ID switch over the run (``Metrics.id_switches == 0``)."""
    return CheckResult("no id switch", id_switches == 0, f"{id_switches} id switches")


def one_id_each(
    truth: Sequence[TruthFrame], worlds: Sequence[WorldState], *, c: float
) -> CheckResult:
    """Every real object is matched (within ``c``) to one estimate id only over the
    whole run, and at least once; no estimate id is matched to two real objects."""
    ids: dict[Hashable, set[Hashable]] = {o.id: set() for f in truth for o in f.objects}
    for frame in _assignments(truth, worlds, c):
        for truth_id, estimate_id in frame.items():
            ids[truth_id].add(estimate_id)
    bad = [f"{k}: {len(v)} ids" for k, v in sorted(ids.items(), key=str) if len(v) != 1]
    owners: dict[Hashable, set[Hashable]] = {}
    for truth_id, estimate_ids in ids.items():
        for estimate_id in estimate_ids:
            owners.setdefault(estimate_id, set()).add(truth_id)
    bad += [
        f"id {k} on {len(v)} real objects" for k, v in sorted(owners.items(), key=str) if len(v) > 1
    ]
    detail = "; ".join(bad) if bad else f"{len(ids)} real objects, one id each"
    return CheckResult("one id per real object", not bad, detail)


def inside_region(worlds: Sequence[WorldState], region: Region, *, margin: float) -> CheckResult:
    """No published object further than ``margin`` (m) outside ``region`` in any frame."""
    low = np.array([lo for lo, _ in region]) - margin
    high = np.array([hi for _, hi in region]) + margin
    outside = 0
    worst = 0.0
    for state in worlds:
        for obj in state.objects:
            p = np.asarray(obj.position[: len(region)], dtype=float)
            excess = float(np.max(np.concatenate([low - p, p - high])))
            if excess > 0.0:
                outside += 1
                worst = max(worst, excess + margin)
    detail = (
        f"{outside} object-frames outside the region by more than {margin} m "
        f"(furthest {worst:.2f} m out)"
        if outside
        else f"none outside the region (margin {margin} m)"
    )
    return CheckResult("no object outside the region", outside == 0, detail)


def labels_kept(
    truth: Sequence[TruthFrame], worlds: Sequence[WorldState], *, c: float
) -> CheckResult:
    """Every labelled real object is, in every frame it exists, published as exactly
    one object carrying its label, within ``c`` of it, always under the same id."""
    failures: dict[str, str] = {}
    first_id: dict[str, int] = {}
    for frame, state in zip(truth, worlds, strict=True):
        for real in frame.objects:
            label = real.label
            if label is None or label in failures:
                continue
            holders = [o for o in state.objects if o.label == label]
            if len(holders) != 1:
                failures[label] = f"{len(holders)} objects labelled at t={frame.time:g}"
                continue
            obj = holders[0]
            d = float(np.linalg.norm(np.subtract(obj.position[:2], real.position[:2])))
            if d >= c:
                failures[label] = f"{d:.2f} m away at t={frame.time:g}"
            elif first_id.setdefault(label, obj.id) != obj.id:
                failures[label] = f"id {first_id[label]} -> {obj.id} at t={frame.time:g}"
    labels = {o.label for f in truth for o in f.objects if o.label is not None}
    detail = (
        "; ".join(f"{k}: {v}" for k, v in sorted(failures.items()))
        if failures
        else f"{len(labels)} labelled objects kept label and id"
    )
    return CheckResult("labels and ids kept", bool(labels) and not failures, detail)


STATIC_GRACE = 1.0
"""Seconds after a static object's first report by which :func:`static_objects_kept`
wants it published (a few detections at the datasheet rates)."""


def static_objects_kept(
    truth: Sequence[TruthFrame],
    worlds: Sequence[WorldState],
    *,
    static_ids: Sequence[str],
    first_seen: dict[str, float],
    c: float,
) -> CheckResult:
    """Every static real object, from ``STATIC_GRACE`` s after its first report to the
    end of the run, has a published object of its class within ``c`` in every frame,
    and the nearest such object has the same id throughout. Static objects never
    reported are not asked for.

    Matched by class and distance rather than by the GOSPA assignment, which ignores
    classes: a person walking past a pallet may take the pallet's GOSPA match for a
    frame without the pallet's estimate changing."""
    failures: dict[str, str] = {}
    ids: dict[str, set[int]] = {}
    for frame, state in zip(truth, worlds, strict=True):
        real_objects = {o.id: o for o in frame.objects}
        for real_id in static_ids:
            seen = first_seen.get(real_id)
            real = real_objects.get(real_id)
            if seen is None or real is None or frame.time < seen + STATIC_GRACE:
                continue
            if real_id in failures:
                continue
            distances = [
                (float(np.linalg.norm(np.subtract(o.position[:2], real.position[:2]))), o.id)
                for o in state.objects
                if o.cls == real.cls
            ]
            near = [(d, i) for d, i in distances if d < c]
            if not near:
                failures[real_id] = f"no {real.cls} published within {c:g} m at t={frame.time:g}"
                continue
            ids.setdefault(real_id, set()).add(min(near)[1])
    for real_id, estimate_ids in ids.items():
        if real_id not in failures and len(estimate_ids) > 1:
            listed = ", ".join(map(str, sorted(estimate_ids)))
            failures[real_id] = f"{len(estimate_ids)} ids ({listed})"
    asked = [r for r in static_ids if r in first_seen]
    detail = (
        "; ".join(f"{k}: {v}" for k, v in sorted(failures.items()))
        if failures
        else f"{len(asked)} static objects seen, each kept under one id with its class"
    )
    return CheckResult("static objects kept", not failures, detail)


REGION_MARGIN = 0.25
"""How far (m) outside the region a published object may be before
:func:`inside_region` fails it in :data:`SCENARIO_CHECKS`: about 1.7 sigma of the
person detector's noise (0.15 m), so a person in the doorway estimated just past
the wall does not count, one walking off does."""


def _c(result: RunResult) -> float:
    return float(str(result.scenario.metadata.get("gospa_c", 1.0)))


def _sim1_like(result: RunResult) -> list[CheckResult]:
    s = result.scenario
    return [
        final_objects_match(s.truth, result.worlds, c=_c(result)),
        no_id_switch(result.metrics.id_switches),
    ]


def _room(result: RunResult) -> list[CheckResult]:
    s = result.scenario
    return [
        one_id_each(s.truth, result.worlds, c=_c(result)),
        inside_region(result.worlds, s.region, margin=REGION_MARGIN),
    ]


def _robocup(result: RunResult) -> list[CheckResult]:
    return [labels_kept(result.scenario.truth, result.worlds, c=_c(result))]


def _datasheet(result: RunResult) -> list[CheckResult]:
    s = result.scenario
    return [
        final_objects_match(s.truth, result.worlds, c=_c(result)),
        inside_region(result.worlds, s.region, margin=REGION_MARGIN),
    ]


def _patrol(result: RunResult) -> list[CheckResult]:
    s = result.scenario
    static_ids = s.metadata.get("static_ids", [])
    first_seen = s.metadata.get("first_seen", {})
    if not isinstance(static_ids, list) or not isinstance(first_seen, dict):
        raise TypeError("a patrol run's metadata needs static_ids (a list) and first_seen (a dict)")
    return [
        static_objects_kept(
            s.truth, result.worlds, static_ids=static_ids, first_seen=first_seen, c=_c(result)
        ),
        inside_region(result.worlds, s.region, margin=REGION_MARGIN),
    ]


def view_check(check: ViewCheck) -> CheckResult:
    """A :class:`semwm.sim.leftbehind.ViewCheck` as a pass/fail line."""
    return CheckResult(check.name, check.passed, check.detail())


def _leftbehind(result: RunResult) -> list[CheckResult]:
    return [view_check(c) for c in acceptance(result.scenario, result.worlds)]


SCENARIO_CHECKS: dict[str, Callable[[RunResult], list[CheckResult]]] = {
    "sim1": _sim1_like,
    "tabletop_wrong_labels": _sim1_like,
    "sim2": _room,
    "corner_occlusion": _room,
    "door_exits": _room,
    "robocup": _robocup,
    "datasheet": _datasheet,
    "patrol": _patrol,
    "leftbehind": _leftbehind,
    "region_edge": _sim1_like,
}
"""Issue 9's acceptance checks per scenario name (sim1, sim2, robocup as the issue
states them; each variant gets the checks of the scenario it hardens)."""


def run_checks(result: RunResult) -> list[CheckResult]:
    """The checks of :data:`SCENARIO_CHECKS` for ``result``'s scenario (none if unknown)."""
    check = SCENARIO_CHECKS.get(result.scenario.name)
    return check(result) if check else []
