"""``/knowledge``: the running knowledge, class edits and reloading the file."""

from __future__ import annotations

from typing import Annotated, Any

from fastapi import APIRouter, Body, Path, Response

from api.deps import WorldDep
from api.schemas import ClassOut, KnowledgeFileErrorOut, MessageOut, ReloadOut, ValidationErrorOut
from api.service import COMMIT_HEADER
from semwm.knowledge import ClassSpec, KnowledgeDocument

router = APIRouter(prefix="/knowledge", tags=["knowledge"])

ClassName = Annotated[str, Path(description="A class name, e.g. 'Cup'.")]

_CLASS_EXAMPLES: dict[str, Any] = {
    "kalman": {
        "summary": "A static class with a Kalman filter (2-d world)",
        "value": {
            "name": "Cup",
            "is_a": ["Object"],
            "detection_frequency": 1.0,
            "new_frequency": 0.1,
            "filter": {
                "type": "kalman",
                "model": {
                    "motion_model": "zeroth_order",
                    "system_noise": [[0.001, 0.0], [0.0, 0.001]],
                },
            },
            "measurement_noise": [[0.01, 0.0], [0.0, 0.01]],
        },
    },
    "inherit": {
        "summary": "A subclass taking everything else from its parent",
        "value": {"name": "Mug", "is_a": ["Cup"], "detection_frequency": 2.0},
    },
}


@router.get("", response_model=KnowledgeDocument, summary="The running knowledge document")
def get_knowledge(world: WorldDep) -> KnowledgeDocument:
    """The knowledge document as JSON (the same fields as a YAML knowledge file)."""
    return world.knowledge.document


@router.get(
    "/classes/{name}",
    response_model=ClassOut,
    summary="One class, resolved and as written",
    responses={404: {"model": MessageOut, "description": "Unknown class"}},
)
def get_class(world: WorldDep, name: ClassName) -> ClassOut:
    """The class with inheritance applied (``resolved``) and as written (``spec``)."""
    knowledge, spec = world.class_view(name)
    return ClassOut(name=name, resolved=knowledge.classes[name], spec=spec)


@router.put(
    "/classes/{name}",
    response_model=ClassOut,
    summary="Replace or add a class",
    responses={
        409: {
            "model": MessageOut,
            "description": "Conflicts with the tracked objects, or write-back failed",
        },
        422: {"model": ValidationErrorOut, "description": "Rejected; nothing changed"},
    },
)
def put_class(
    world: WorldDep,
    name: ClassName,
    spec: Annotated[ClassSpec, Body(openapi_examples=_CLASS_EXAMPLES)],
    response: Response,
) -> ClassOut:
    """Replace class ``name`` (or add it), checked like a knowledge file.

    The whole knowledge is resolved again with the new class; any problem (in this
    class, or in a subclass it breaks) gives 422 with its path and nothing changes.
    An accepted edit applies from the next detection, and is written to the
    knowledge file when the service runs with write-back.
    """
    committed = world.put_class(name, spec)
    knowledge, written = committed.value
    response.headers[COMMIT_HEADER] = str(committed.commit)
    return ClassOut(name=name, resolved=knowledge.classes[name], spec=spec, written=written)


@router.post(
    "/reload",
    response_model=ReloadOut,
    summary="Re-read the knowledge file",
    responses={
        409: {
            "model": MessageOut,
            "description": "No knowledge file, or it lacks classes tracked objects hold",
        },
        422: {"model": KnowledgeFileErrorOut, "description": "Broken file; nothing changed"},
    },
)
def reload_knowledge(world: WorldDep, response: Response) -> ReloadOut:
    """Re-read the knowledge file; it applies from the next detection.

    A broken file gives 422 with one ``FILE:LINE: message`` per problem, and the
    running knowledge stays. A file without a class that tracked objects hold gives
    409 naming them (reset first, or keep the class).
    """
    committed = world.reload()
    knowledge = committed.value
    response.headers[COMMIT_HEADER] = str(committed.commit)
    return ReloadOut(knowledge=str(world.knowledge_path), classes=list(knowledge.classes))
