"""Class knowledge: the model, its resolution, the taxonomy and the file loaders."""

from semwm.knowledge.loader import load_document, load_knowledge
from semwm.knowledge.model import (
    AppearanceRelation,
    ClassSpec,
    DetectorSpec,
    IMMFilterSpec,
    KalmanFilterSpec,
    Knowledge,
    KnowledgeDocument,
    KnownObject,
    MotionModelSpec,
    ResolvedClass,
    WorldSettings,
)
from semwm.knowledge.problems import KnowledgeError, Problem
from semwm.knowledge.resolve import resolve
from semwm.knowledge.taxonomy import Taxonomy

__all__ = [
    "AppearanceRelation",
    "ClassSpec",
    "DetectorSpec",
    "IMMFilterSpec",
    "KalmanFilterSpec",
    "Knowledge",
    "KnowledgeDocument",
    "KnowledgeError",
    "KnownObject",
    "MotionModelSpec",
    "Problem",
    "ResolvedClass",
    "Taxonomy",
    "WorldSettings",
    "load_document",
    "load_knowledge",
    "resolve",
]
