"""Lazy prediction of stored object versions to a given time, batched per class filter."""

from __future__ import annotations

from collections import defaultdict
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np
import numpy.typing as npt

from semwm.filters.factory import ClassFilter, FilterFactory
from semwm.filters.motion import FloatArray
from semwm.mhf.existence import Region, inside_probability
from semwm.mhf.state import Track

InsideKernel = Callable[[FloatArray, FloatArray, Region | None, FloatArray | None], FloatArray]
"""The signature of :func:`~semwm.mhf.existence.inside_probability`."""

IndexArray = npt.NDArray[np.intp]


def conform(
    x: FloatArray, P: FloatArray, mu: FloatArray, source: ClassFilter | None, target: ClassFilter
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Carry a state over to another class's filter when its structure differs (a track
    refined from ``Can`` to ``CokeCan``, or knowledge edited while running).

    The combined position (and velocity, when both filters have one) and their
    covariances are kept; other entries start as a new object's would.
    """
    if x.shape == (target.modes, target.state_size):
        return x, P, mu
    d = target.dim
    if x.shape[0] == 1:
        x_hat, P_hat = x[0], P[0]
    else:
        x_hat = mu @ x
        spread = x - x_hat
        P_hat = np.einsum("m,mij->ij", mu, P) + np.einsum("m,mi,mj->ij", mu, spread, spread)
    keep = min(x_hat.shape[0], target.state_size)
    new_x = np.zeros(target.state_size)
    new_x[:keep] = x_hat[:keep]
    new_P = target.initial_covariance.copy()
    new_P[:keep, :keep] = P_hat[:keep, :keep]
    if keep < d:  # pragma: no cover - every filter measures the whole position
        raise ValueError("a filter state must hold the position")
    modes = target.modes
    return (
        np.repeat(new_x[None], modes, axis=0),
        np.repeat(new_P[None], modes, axis=0),
        target.initial_mode_probabilities.copy(),
    )


Shape = tuple[int, int]


@dataclass(frozen=True)
class Predicted:
    """Object versions predicted to one time, in the order they were given.

    ``position`` ``(N, d)`` and ``position_covariance`` ``(N, d, d)`` are stacked.
    ``batches`` holds the states stacked per filter shape (``(M, n)`` -> ``(x, P,
    mu, mean)`` with ``(K, M, n)``, ``(K, M, n, n)``, ``(K, M)`` and the combined
    means ``(K, n)``); track ``i`` has filter shape ``shapes[i]`` and is row
    ``batch_row[i]`` of its shape's batch, so that batched updates (the same equations
    for every class of one shape) index them instead of stacking rows again. The
    per-track lists ``x``, ``P``, ``mu`` and ``state_mean`` (filters differ in size)
    are made when first read.
    """

    tracks: tuple[Track, ...]
    position: FloatArray
    position_covariance: FloatArray
    batches: dict[Shape, tuple[FloatArray, FloatArray, FloatArray, FloatArray]] = field(
        default_factory=dict
    )
    batch_row: IndexArray = field(default_factory=lambda: np.zeros(0, dtype=np.intp))
    shapes: tuple[Shape, ...] = ()
    _inside: dict[Region | None, FloatArray] = field(
        default_factory=dict, compare=False, repr=False
    )

    def _rows(self, part: int) -> list[FloatArray]:
        batches = self.batches
        return [
            batches[shape][part][row]
            for shape, row in zip(self.shapes, self.batch_row.tolist(), strict=True)
        ]

    @cached_property
    def x(self) -> list[FloatArray]:
        """Each track's mode states ``(M, n)``."""
        return self._rows(0)

    @cached_property
    def P(self) -> list[FloatArray]:
        """Each track's mode covariances ``(M, n, n)``."""
        return self._rows(1)

    @cached_property
    def mu(self) -> list[FloatArray]:
        """Each track's mode probabilities ``(M,)``."""
        return self._rows(2)

    @cached_property
    def state_mean(self) -> list[FloatArray]:
        """Each track's combined state mean ``(n,)``."""
        return self._rows(3)

    def inside_region(
        self,
        region: Region | None,
        margin: FloatArray | None = None,
        kernel: InsideKernel = inside_probability,
        variance_cap: FloatArray | None = None,
    ) -> FloatArray:
        """Each object's probability of being inside ``region`` widened by ``margin``
        ``(N, d)`` (:func:`semwm.mhf.existence.inside_probability`, or the engine's
        ``kernel``), its position variances capped per axis at ``variance_cap``
        ``(N, d)``; computed once per region (one caller passes one object's margins
        and caps: its class's)."""
        known = self._inside.get(region)
        if known is None:
            covariance = self.position_covariance
            if variance_cap is not None and len(self.tracks):
                variances = np.minimum(covariance.diagonal(axis1=1, axis2=2), variance_cap)
                covariance = variances[:, :, None] * np.eye(variances.shape[1])
            known = self._inside[region] = kernel(self.position, covariance, region, margin)
        return known

    def velocity(self, dim: int) -> FloatArray:
        """``(N, dim)``: each object's predicted velocity (its combined state mean's
        entries after the position; zero for a filter without velocity)."""
        result = np.zeros((len(self.tracks), dim))
        for shape, (_, _, _, mean) in self.batches.items():
            if mean.shape[-1] >= 2 * dim:
                rows = [i for i, s in enumerate(self.shapes) if s == shape]
                result[rows] = mean[self.batch_row[rows], dim : 2 * dim]
        return result

    def subset(self, rows: list[int]) -> Predicted:
        """The predictions of ``rows``, in that order."""
        return Predicted(
            tuple(self.tracks[i] for i in rows),
            self.position[rows],
            self.position_covariance[rows],
            self.batches,
            self.batch_row[rows],
            tuple(self.shapes[i] for i in rows),
        )

    def stacked(self, rows: IndexArray) -> tuple[FloatArray, FloatArray, FloatArray]:
        """``x``, ``P``, ``mu`` of ``rows`` (tracks of one filter shape), stacked."""
        x, P, mu, _ = self.batches[self.shapes[int(rows[0])]]
        in_batch = self.batch_row[rows]
        return x[in_batch], P[in_batch], mu[in_batch]

    def shape(self, row: int) -> Shape:
        """``(M, n)``: modes and state size of track ``row``'s filter."""
        return self.shapes[row]


def predict_tracks(tracks: Sequence[Track], time: float, factory: FilterFactory) -> Predicted:
    """Predict every track to ``time`` (s), one batched call per class filter."""
    d = factory.dim
    count = len(tracks)
    position = np.zeros((count, d))
    position_covariance = np.zeros((count, d, d))
    batch_row = np.zeros(count, dtype=np.intp)
    shapes: list[Shape] = [(0, 0)] * count
    by_shape: dict[Shape, list[tuple[list[int], FloatArray, FloatArray, FloatArray, FloatArray]]]
    by_shape = defaultdict(list)
    groups: dict[str, list[int]] = defaultdict(list)
    for i, track in enumerate(tracks):
        groups[track.cls].append(i)
    for cls, members in groups.items():
        flt = factory.filter_for(cls)
        shape = (flt.modes, flt.state_size)
        group = [tracks[i] for i in members]
        if all(t.x.shape == shape for t in group):
            x = np.array([t.x for t in group])
            P = np.array([t.P for t in group])
            mu = np.array([t.mu for t in group])
        else:
            states = [conform(t.x, t.P, t.mu, None, flt) for t in group]
            x = np.array([s[0] for s in states])
            P = np.array([s[1] for s in states])
            mu = np.array([s[2] for s in states])
        dt = np.array([time - t.time for t in group])
        x, P, mu = flt.predict(x, P, mu, dt)
        x_hat, P_hat = flt.combine(x, P, mu)
        idx = np.asarray(members)
        position[idx] = x_hat[:, :d]
        position_covariance[idx] = P_hat[:, :d, :d]
        by_shape[shape].append((members, x, P, mu, x_hat))
        for i in members:
            shapes[i] = shape
    batches = {shape: _stack_shape(parts, batch_row) for shape, parts in by_shape.items()}
    return Predicted(
        tuple(tracks), position, position_covariance, batches, batch_row, tuple(shapes)
    )


def _stack_shape(
    parts: list[tuple[list[int], FloatArray, FloatArray, FloatArray, FloatArray]],
    batch_row: IndexArray,
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """One filter shape's batch from its classes' batches; sets ``batch_row`` of their
    tracks."""
    if len(parts) == 1:
        members, x, P, mu, mean = parts[0]
        batch_row[members] = np.arange(len(members))
        return x, P, mu, mean
    start = 0
    for members, *_ in parts:
        batch_row[members] = np.arange(start, start + len(members))
        start += len(members)
    return (
        np.concatenate([part[1] for part in parts]),
        np.concatenate([part[2] for part in parts]),
        np.concatenate([part[3] for part in parts]),
        np.concatenate([part[4] for part in parts]),
    )
