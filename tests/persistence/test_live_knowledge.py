"""Issue 30 case 3: a class added live survives a restart, with its objects.

``PUT /knowledge/classes/Mug``, Mug detections (200), a restart with the same
arguments: the file's knowledge replaced the journal's, Mug was gone (404), its
object too, and a new Mug detection was 422, with one WARNING line. Now the
journal's knowledge is the one in force: a restart whose file differs refuses to
start, naming the classes and the ways out.
"""

from __future__ import annotations

import shutil
from pathlib import Path
from typing import Any

import pytest
from fastapi.testclient import TestClient

from api.app import create_app
from api.settings import Settings
from semwm.knowledge.loader import load_document
from semwm.knowledge.shipped import shipped_knowledge_path
from semwm.persistence import KnowledgeConflict

MUG = {"name": "Mug", "is_a": ["Cup"]}


def mug(t: float) -> dict[str, Any]:
    return {"time": t, "class": "Mug", "position": [1.0, 1.0], "source": "r1"}


def _settings(tmp_path: Path, **options: Any) -> Settings:
    return Settings(
        knowledge=tmp_path / "sim1.yaml",
        data_dir=tmp_path / "data",
        allowed_hosts=("testserver",),
        **options,
    )


@pytest.fixture
def edited(tmp_path: Path) -> Path:
    """A data directory whose journal added Mug live, with a Mug object; the file
    does not know Mug."""
    shutil.copyfile(shipped_knowledge_path("sim1.yaml"), tmp_path / "sim1.yaml")
    with TestClient(create_app(_settings(tmp_path))) as client:
        assert client.put("/knowledge/classes/Mug", json=MUG).status_code == 200
        for step in range(3):
            assert client.post("/detections", json=mug(0.5 * step)).status_code == 200
        assert [o["class"] for o in client.get("/world").json()["objects"]] == ["Mug"]
    return tmp_path


def _mug_served(client: TestClient) -> None:
    assert client.get("/knowledge/classes/Mug").status_code == 200
    assert [o["class"] for o in client.get("/world").json()["objects"]] == ["Mug"]
    assert client.post("/detections", json=mug(2.0)).status_code == 200


def test_a_restart_with_the_stale_file_refuses_naming_the_class_and_the_ways_out(
    edited: Path,
) -> None:
    app = create_app(_settings(edited))
    with pytest.raises(KnowledgeConflict) as refused, TestClient(app):
        pass
    message = str(refused.value)
    assert "Mug" in message and "--write-back" in message and "--knowledge-from file" in message


def test_applying_the_file_is_refused_while_objects_hold_the_class(edited: Path) -> None:
    app = create_app(_settings(edited, knowledge_from="file"))
    with pytest.raises(KnowledgeConflict, match="Mug"), TestClient(app):
        pass
    # nothing changed: the journal's knowledge still serves the Mug
    with TestClient(create_app(_settings(edited, knowledge_from="journal"))) as client:
        _mug_served(client)


def test_write_back_keeps_the_journals_knowledge_and_writes_it_to_the_file(
    edited: Path,
) -> None:
    with TestClient(create_app(_settings(edited, write_back=True))) as client:
        _mug_served(client)
    assert "Mug" in [c.name for c in load_document(edited / "sim1.yaml").classes]
    # the file now agrees with the journal: the same arguments as before start
    with TestClient(create_app(_settings(edited))) as client:
        _mug_served(client)


def test_an_edited_file_applies_with_knowledge_from_file(tmp_path: Path) -> None:
    shutil.copyfile(shipped_knowledge_path("sim1.yaml"), tmp_path / "sim1.yaml")
    with TestClient(create_app(_settings(tmp_path))) as client:
        assert client.post("/detections", json={**mug(0.0), "class": "Cup"}).status_code == 200
    path = tmp_path / "sim1.yaml"
    path.write_text(path.read_text() + "\n# an operator's edit\n")  # same document: starts
    with TestClient(create_app(_settings(tmp_path))) as client:
        assert client.put("/knowledge/classes/Mug", json=MUG).status_code == 200
    with TestClient(create_app(_settings(tmp_path, knowledge_from="file"))) as client:
        assert client.get("/knowledge/classes/Mug").status_code == 404  # no Mug object held
        assert client.get("/persistence").json()["journal"]["recovery"]["knowledge_changed"]
