"""The JSON of ``GET /world`` and ``GET /world/objects/{id}``, written directly.

Through the response model each answer was validated into :class:`~api.schemas.WorldOut`
from the world's dicts and then serialised: the validation alone cost 9 ms for a world
of 1,000 objects, half the query. The world model's values are already the schema's
types, so here they go straight to pydantic-core's serialiser, in the schema's field
order and with its settings (aliases, ``NaN`` and infinities as ``null``): the same
bytes as ``WorldOut(...).model_dump_json()``, which ``tests/api/test_world_json.py``
holds on real worlds. The routes keep ``response_model`` for the OpenAPI document.
"""

from __future__ import annotations

from typing import Any

import pydantic_core

from semwm.world_types import WorldObject, WorldState


def _number(value: float | None) -> float | None:
    """A float field's value as the schema's validation gives it (an int as a float)."""
    return None if value is None else float(value)


def object_value(obj: WorldObject) -> dict[str, Any]:
    """An object in :class:`~api.schemas.WorldObjectOut`'s field order and names."""
    confidence = obj.confidence
    return {
        "id": obj.id,
        "class": obj.cls,
        "label": obj.label,
        "position": obj.position,
        "velocity": obj.velocity,
        "covariance": obj.covariance,
        "existence": float(obj.existence),
        "last_seen": float(obj.last_seen),
        "created": _number(obj.created),
        "mode_probabilities": obj.mode_probabilities,
        "class_probabilities": obj.class_probabilities,
        "confidence": (
            None
            if confidence is None
            else {"value": float(confidence.value), "state": confidence.state}
        ),
        "tentative": obj.tentative,
    }


def _json(value: Any) -> bytes:
    return pydantic_core.to_json(value, inf_nan_mode="null")


def world_json(state: WorldState) -> bytes:
    """``GET /world``'s body (:class:`~api.schemas.WorldOut`)."""
    return _json({"time": _number(state.time), "objects": [object_value(o) for o in state.objects]})


def object_json(obj: WorldObject) -> bytes:
    """``GET /world/objects/{id}``'s body (:class:`~api.schemas.WorldObjectOut`)."""
    return _json(object_value(obj))
