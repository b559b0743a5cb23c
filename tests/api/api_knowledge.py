"""A small 2-d knowledge base for the API tests, built in code."""

from __future__ import annotations

from typing import Any

from semwm.knowledge import Knowledge, KnowledgeDocument, resolve

NOISE = [[0.0025, 0.0], [0.0, 0.0025]]


def kalman(q: float = 1e-4) -> dict[str, Any]:
    return {
        "type": "kalman",
        "model": {"motion_model": "zeroth_order", "system_noise": [[q, 0.0], [0.0, q]]},
    }


DOCUMENT: dict[str, Any] = {
    "world": {
        "dimension": 2,
        "pruning_ratio": 0.01,
        "max_hypotheses": 50,
        "region": [[-20.0, 20.0], [-20.0, 20.0]],
    },
    "classes": [
        {
            "name": "Can",
            "detection_frequency": 2.0,
            "new_frequency": 0.5,
            "filter": kalman(),
            "measurement_noise": NOISE,
        },
        {"name": "CokeCan", "is_a": ["Can"]},
        {"name": "BeerCan", "is_a": ["Can"]},
        {
            "name": "Cup",
            "detection_frequency": 2.0,
            "new_frequency": 0.5,
            "filter": kalman(),
            "measurement_noise": NOISE,
        },
        {
            "name": "Robot",
            "detection_frequency": 10.0,
            "new_frequency": 0.5,
            "filter": {
                "type": "imm",
                "models": [
                    {"motion_model": "zeroth_order", "system_noise": [[1e-3, 0], [0, 1e-3]]},
                    {"motion_model": "first_order", "system_noise": [[0.1, 0], [0, 0.1]]},
                ],
                "transition_matrix": [[0.9, 0.1], [0.1, 0.9]],
            },
            "measurement_noise": NOISE,
        },
    ],
    "detectors": [
        {"name": "camera", "clutter_frequency": 0.01},
        {"name": "lidar", "clutter_frequency": 0.01, "range": 5.0},
    ],
}


def document() -> KnowledgeDocument:
    return KnowledgeDocument.model_validate(DOCUMENT)


def knowledge(source: str | None = None) -> Knowledge:
    return resolve(document(), source)
