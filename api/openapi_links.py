"""The OpenAPI document's links: which answer gives the values of which next request.

A link (OpenAPI 3.1, Link Object) sits under a response of its source operation and
names its target by ``operationId``; its ``parameters`` map the target's parameters
to runtime expressions on the source's answer (``$response.body#/objects/0/id``: the
first object's id). They tell a client, and a stateful tester such as schemathesis
(tests/api/test_api_schemathesis.py), how calls chain: ``GET /world`` then one of its
objects, a class read then written back or detected, ``POST /reset`` then the (empty)
world.

The operationIds are the route functions' names (:func:`operation_id`), so they stay
the same when a path or its parameters change. :data:`LINKS` is the one table of
links; :func:`add_links` puts them into the generated document and fails on a
source, status or target the document does not have.
"""

from __future__ import annotations

from typing import Any

from fastapi.routing import APIRoute

# x-schemathesis merge_body=false: the linked body replaces the generated one whole
# (schemathesis' extension; other tools ignore it). A request body given as an object
# holding expressions is how schemathesis fills single fields of the generated body.
_REPLACE_BODY = {"x-schemathesis": {"merge_body": False}}

_GET_OBJECT = {
    "operationId": "get_object",
    "parameters": {
        "path.object_id": "$response.body#/objects/0/id",
        "query.time": "$response.body#/time",
    },
    "description": "The first object of the answer, predicted to the same time.",
}
_DETECT_CLASS = {
    "operationId": "post_detections",
    "requestBody": {"class": "$response.body#/name"},
    "description": "A detection of this class.",
}

# (source operationId, status) -> {link name: Link Object}
LINKS: dict[tuple[str, str], dict[str, dict[str, Any]]] = {
    ("get_world", "200"): {"GetObject": _GET_OBJECT},
    ("post_detections", "200"): {
        "GetWorld": {
            "operationId": "get_world",
            "parameters": {"query.time": "$response.body#/time"},
            "description": "The world at the time the detections brought it to.",
        },
    },
    ("post_action", "200"): {
        "GetObject": {
            "operationId": "get_object",
            "parameters": {"path.object_id": "$response.body#/objects/0"},
            "description": "An object the action may have moved.",
        },
    },
    ("get_knowledge", "200"): {
        "GetClass": {
            "operationId": "get_class",
            "parameters": {"path.name": "$response.body#/classes/0/name"},
            "description": "The first class of the document, resolved and as written.",
        },
    },
    ("reload_knowledge", "200"): {
        "GetClass": {
            "operationId": "get_class",
            "parameters": {"path.name": "$response.body#/classes/0"},
            "description": "The first class of the reloaded knowledge.",
        },
    },
    ("get_class", "200"): {
        "PutClass": {
            "operationId": "put_class",
            "parameters": {"path.name": "$response.body#/name"},
            "requestBody": "$response.body#/spec",
            "description": "Write the class back as written (edit the spec first).",
            **_REPLACE_BODY,
        },
        "PostDetection": _DETECT_CLASS,
    },
    ("put_class", "200"): {
        "GetClass": {
            "operationId": "get_class",
            "parameters": {"path.name": "$response.body#/name"},
            "description": "The class just written, resolved and as written.",
        },
        "PostDetection": _DETECT_CLASS,
    },
    ("reset", "200"): {
        "GetWorld": {
            "operationId": "get_world",
            "description": "The world after the reset: no objects.",
        },
    },
}


def operation_id(route: APIRoute) -> str:
    """A route's operationId: its function's name (``get_world``), unique in the app."""
    return route.name


def add_links(schema: dict[str, Any], links: dict[tuple[str, str], dict[str, Any]] = LINKS) -> None:
    """Put ``links`` under their source responses of the generated ``schema``.

    Raises ``ValueError`` for a link whose source operation, status or target
    operation the document does not have (a renamed route function, a removed status).
    """
    operations = {
        op["operationId"]: op
        for path in schema.get("paths", {}).values()
        for op in path.values()
        if isinstance(op, dict) and "operationId" in op
    }
    for (source, status), named in links.items():
        if source not in operations:
            raise ValueError(f"OpenAPI link source {source!r} is not an operationId")
        responses = operations[source].get("responses", {})
        if status not in responses:
            raise ValueError(f"OpenAPI links of {source!r}: no {status} response")
        for name, link in named.items():
            target = link["operationId"]
            if target not in operations:
                raise ValueError(f"OpenAPI link {source}.{name}: no operation {target!r}")
        responses[status].setdefault("links", {}).update(named)
