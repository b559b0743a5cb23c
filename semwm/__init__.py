"""semwm: a knowledge-driven semantic world model (Multiple Hypothesis Filter) for robots.

>>> from semwm import WorldModel, load_knowledge
"""

from semwm.detection import BeforeHistoryError, Detection, DetectionError, OutOfOrderError
from semwm.knowledge.loader import load_knowledge
from semwm.world import IngestResult, WorldModel
from semwm.world_types import HypothesisSummary, WorldObject, WorldState

__version__ = "0.1.0"

__all__ = [
    "BeforeHistoryError",
    "Detection",
    "DetectionError",
    "HypothesisSummary",
    "IngestResult",
    "OutOfOrderError",
    "WorldModel",
    "WorldObject",
    "WorldState",
    "load_knowledge",
]
