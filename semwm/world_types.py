"""Values the world model answers with: objects of the world and hypothesis summaries."""

from __future__ import annotations

from dataclasses import asdict, dataclass


@dataclass(frozen=True)
class WorldObject:
    """An object of the maximum a posteriori hypothesis, predicted to the query time.

    ``covariance`` is the position covariance (m^2); ``velocity`` is ``None`` for
    classes whose filter has no velocity; ``existence`` is the total probability of
    the hypotheses that hold this object; ``mode_probabilities`` maps each motion
    model of an IMM to its probability.
    """

    id: int
    cls: str
    label: str | None
    position: tuple[float, ...]
    velocity: tuple[float, ...] | None
    covariance: tuple[tuple[float, ...], ...]
    existence: float
    last_seen: float
    created: float
    mode_probabilities: dict[str, float] | None

    def to_dict(self) -> dict[str, object]:
        data = asdict(self)
        data["class"] = data.pop("cls")
        return data


@dataclass(frozen=True)
class WorldState:
    """The world at ``time``: the MAP hypothesis's objects."""

    time: float | None
    objects: tuple[WorldObject, ...]

    def to_dict(self) -> dict[str, object]:
        return {"time": self.time, "objects": [o.to_dict() for o in self.objects]}


@dataclass(frozen=True)
class HypothesisObject:
    """An object of a hypothesis: its public id if it was ever published, its track."""

    id: int | None
    track: int
    cls: str
    label: str | None
    position: tuple[float, ...]

    def to_dict(self) -> dict[str, object]:
        data = asdict(self)
        data["class"] = data.pop("cls")
        return data


@dataclass(frozen=True)
class HypothesisSummary:
    """One hypothesis: its probability and its objects."""

    probability: float
    objects: tuple[HypothesisObject, ...]

    def to_dict(self) -> dict[str, object]:
        return {"probability": self.probability, "objects": [o.to_dict() for o in self.objects]}
