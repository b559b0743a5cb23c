"""Types of the Rust core ``semwm._core`` (built from ``core/``; docs/engines.md).

Every function takes and returns float64 arrays with the shapes of its Python
counterpart in :mod:`semwm.filters.batched` and :mod:`semwm.filters.small`, and raises
``ValueError`` (shapes) or ``numpy.linalg.LinAlgError`` (a matrix that is not positive
definite) as the Python engine does.
"""

from collections.abc import Callable, Iterator, Mapping, Sequence
from typing import Any, overload

import numpy as np
from numpy.typing import NDArray

from semwm.mhf.measurement import Measurement

_F = NDArray[np.float64]

__version__: str

class ClassFilter:
    def __init__(
        self,
        dim: int,
        f0: _F,
        f1: _F,
        c: _F,
        transition: _F,
        first_order: list[bool],
        velocity_decay: float,
        period: tuple[float, _F, _F, _F] | None = None,
    ) -> None: ...
    def predict(self, x: _F, p: _F, mu: _F, dt: _F, /) -> tuple[_F, _F, _F]: ...
    @property
    def modes(self) -> int: ...
    @property
    def state_size(self) -> int: ...

def imm_mix(x: _F, p: _F, mu: _F, t: _F, /) -> tuple[_F, _F, _F]: ...
def predict(x: _F, p: _F, mu: _F, f: _F, q: _F, t: _F, /) -> tuple[_F, _F, _F]: ...
def update(x: _F, p: _F, mu: _F, z: _F, r: _F, /) -> tuple[_F, _F, _F, _F]: ...
def combine(x: _F, p: _F, mu: _F, /) -> tuple[_F, _F]: ...
def mahalanobis_squared(residual: _F, covariance: _F, /) -> _F: ...

# existence and coverage (core/src/existence.rs, core/src/coverage.rs)
def survive(r: _F, mu: _F, f: _F, dt: float, /) -> tuple[_F, _F]: ...
def missed(r: _F, p: _F, /) -> tuple[_F, _F]: ...
def inside_probability(
    position: _F, covariance: _F, low: _F, high: _F, margin: _F | None = None
) -> _F: ...
def in_view_probability(
    position: _F,
    covariance: _F,
    sensor: _F,
    heading: float,
    range: float | None = None,
    half_angle: float | None = None,
    margin: _F | None = None,
) -> _F: ...
def gauss_hermite_rule() -> tuple[_F, _F]: ...
def ndtr(values_: _F, /) -> _F: ...
def range_coverage(positions: _F, sensor: _F, reach: float, spread: _F | None = None) -> _F: ...
def hull_distance(points: _F, corners: _F, /) -> _F: ...

# the expansion of one scan (core/src/expansion.rs, core/src/hypotheses.rs)
class ScanExpansion:
    def __init__(
        self, ratio: float, max_hypotheses: int, association_model: str, log_label_error: float
    ) -> None: ...
    def scan(
        self,
        counters: tuple[int, int, int],
        tracks: tuple[list[int], list[float], list[str | None]],
        clusters: tuple[list[int], list[int], list[int], list[int], list[float], list[float]],
        options: tuple[list[int], list[str | None], list[int], list[float]],
        presence: tuple[list[int], list[int], list[float]],
        existing: tuple[list[int], list[int], list[float]],
    ) -> tuple[
        list[int],
        tuple[list[int], list[int], list[int]],
        tuple[list[int], list[int], list[float], list[float]],
        tuple[list[int], list[int], list[int], list[float]],
        int,
    ]: ...

def merge_prune(
    sizes: list[int],
    keys: list[int],
    log_weights: list[float],
    rates: list[float],
    ratio: float,
    max_hypotheses: int,
) -> tuple[list[int], list[int], list[float], list[float]]: ...

# twin merging (core/src/mhf/similar.rs), bound for its parity test
def merge_similar(
    hypothesis_keys: list[list[int]],
    log_weights: list[float],
    rates: list[float],
    keys: list[int],
    lineages: list[int],
    classes: list[int],
    labels: list[int | None],
    x: list[_F],
    p: list[_F],
    mu: list[_F],
    class_probs: list[_F],
    existence: list[float],
    max_distance: float,
) -> tuple[list[list[int]], list[float], list[float]] | None: ...

# the observed rates (core/src/mhf/rates.rs)
_ClockRow = tuple[str, float, float | None, list[float] | None, float]
_CountRow = tuple[str, str, str, float, float, list[int]]
_SeenRow = tuple[int, list[tuple[str, str, float]]]
_AlarmRow = tuple[str, str, float, list[int], int]

class ObservedRates:
    def __init__(self) -> None: ...
    @staticmethod
    def of(
        sources: list[_ClockRow],
        streams: list[_CountRow],
        seen: list[_SeenRow],
        false_alarms: list[_AlarmRow],
    ) -> ObservedRates: ...
    def state(
        self,
    ) -> tuple[list[_ClockRow], list[_CountRow], list[_SeenRow], list[_AlarmRow]]: ...

# the whole scan, the state kept in the core (core/src/mhf/filter.rs, state.rs)
_VersionRow = tuple[
    tuple[int, int, int, str | None],
    tuple[int, int, list[float], list[float], list[float]],
    tuple[float, float, float, float],
    tuple[list[float], list[str], float],
]
_VersionOut = tuple[
    tuple[int, int, int, str | None],
    tuple[_F, _F, _F],
    tuple[float, float, float, float],
    tuple[_F, list[str], float],
]
_ClusterRow = list[tuple[float, list[int], float]]

class State:
    @staticmethod
    def empty() -> State: ...
    @staticmethod
    def of(
        clusters: list[_ClusterRow],
        versions: list[_VersionRow],
        time: float | None,
        next_key: int,
        observed: ObservedRates,
    ) -> State: ...
    @property
    def time(self) -> float | None: ...
    @property
    def next_key(self) -> int: ...
    @property
    def hypothesis_count(self) -> int: ...
    @property
    def cluster_count(self) -> int: ...
    @property
    def track_count(self) -> int: ...
    def cluster_ids(self) -> list[int]: ...
    def cluster_sizes(self) -> list[int]: ...
    def clusters(self, indices: list[int] | None = None) -> list[_ClusterRow]: ...
    def entries(self) -> tuple[list[int], list[int], list[float]]: ...
    def serials(self, keys: list[int]) -> list[int]: ...
    def lineages(self) -> list[int]: ...
    def best_keys(self) -> list[int]: ...
    def versions(self, keys: list[int]) -> list[_VersionOut]: ...
    def observed(self) -> ObservedRates: ...

class Book:
    def __init__(self) -> None: ...
    @staticmethod
    def of(
        values: list[tuple[int, float, float]],
        poses: list[tuple[str, float, float]],
        scans: list[tuple[str, float]],
    ) -> Book: ...
    def state(
        self,
    ) -> tuple[
        list[tuple[int, float, float]], list[tuple[str, float, float]], list[tuple[str, float]]
    ]: ...
    def entry(self, lineage: int) -> tuple[float, float] | None: ...

class Engine:
    def __init__(self, tables: dict[str, object]) -> None: ...
    def process_measurements(
        self,
        state: State,
        measurements: Sequence[Measurement],
        view: tuple[object, ...] | None = None,
    ) -> State: ...
    def process_and_advance(
        self,
        state: State,
        book: Book,
        measurements: Sequence[Measurement],
        view: tuple[object, ...] | None = None,
        source: str | None = None,
    ) -> tuple[State, Book]: ...
    def process_and_publish(
        self,
        state: State,
        book: Book,
        measurements: Sequence[Measurement],
        published: Mapping[int, Any],
        ids: Mapping[int, int],
        lost: bool,
        next_id: int,
        waiting: Sequence[tuple[int, int]],
        make_state: Callable[[State], Any],
    ) -> tuple[
        Any,
        Book,
        dict[int, VersionRef] | None,
        tuple[dict[int, int], Published, int] | None,
    ]: ...
    def class_names(self) -> list[str]: ...
    def advance(
        self,
        book: Book,
        state: State,
        detectors: list[int],
        view: tuple[object, ...] | None = None,
        source: str | None = None,
    ) -> Book: ...
    def current(
        self, state: Any, published: Mapping[int, Any], ids: Mapping[int, int]
    ) -> dict[int, VersionRef]: ...
    def may_return(self, state: State, key: int, cls: str) -> bool: ...
    def world_at(
        self,
        state: Any,
        latest: Any,
        at: float,
        published: Mapping[int, Any],
        ids: Mapping[int, int],
        book: Book | None,
        tentative_ids: int,
        class_floor: float,
    ) -> list[tuple[int, float, float, tuple[float, ...], dict[str, Any], float | None]]: ...
    def publish(
        self,
        state: Any,
        published: Mapping[int, Any],
        ids: Mapping[int, int],
        lost: bool,
        next_id: int,
        waiting: Sequence[tuple[int, int]] = ...,
    ) -> tuple[dict[int, VersionRef] | None, tuple[dict[int, int], Published, int] | None]: ...

class Published(Mapping[int, VersionRef]):
    """The published world of a scan (id -> ``VersionRef``), its values made on first
    read."""

    def __len__(self) -> int: ...
    def __getitem__(self, key: int) -> VersionRef: ...
    def __iter__(self) -> Iterator[int]: ...
    def lineages(self) -> list[int]: ...

class VersionRef:
    """A version of a core state (``state``: the ``CoreState`` holding it)."""

    def __init__(self, lineage: int, cls: str, key: int, serial: int, state: Any) -> None: ...
    @property
    def lineage(self) -> int: ...
    @property
    def cls(self) -> str: ...
    @property
    def key(self) -> int: ...
    @property
    def serial(self) -> int: ...
    @property
    def state(self) -> Any: ...

class DetectionReader:
    """The Rust engine's reader of plain batches (``semwm.validation.core_reader``)."""

    def __init__(
        self,
        engine: Engine,
        measurement: type,
        detection: type,
        dimension: int,
        max_time: float,
        max_time_std: float,
        default_detector: str,
        pairs: dict[tuple[str, str], Any],
    ) -> None: ...
    def read(
        self, batch: list[Any], first_seq: int
    ) -> tuple[int, dict[tuple[float, str], Sequence[Measurement]], list[int]] | None: ...

class Scan(Sequence[Measurement]):
    """A scan's detections as read: the core's rows, and the ``Measurement`` values
    they stand for, made on first read."""

    def __len__(self) -> int: ...
    @overload
    def __getitem__(self, index: int) -> Measurement: ...
    @overload
    def __getitem__(self, index: slice) -> list[Measurement]: ...
    def rows(
        self,
    ) -> list[
        tuple[
            int,
            float,
            int,
            list[float],
            list[float],
            int,
            str,
            str | None,
            float,
            list[float] | None,
            float,
        ]
    ]: ...
