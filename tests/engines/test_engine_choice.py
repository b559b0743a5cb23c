"""Choosing the engine: the argument, $SEMWM_ENGINE, the errors, and the Python engine
where the extension is not built (simulated in a subprocess that cannot import it)."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap

import pytest

from semwm.filters.engine import EngineUnavailable, resolve_engine, rust_core
from semwm.knowledge.loader import load_knowledge
from semwm.knowledge.shipped import shipped_knowledge_path
from semwm.world import WorldModel

from . import needs_rust


def test_rust_is_the_default_where_built_and_the_environment_chooses(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.delenv("SEMWM_ENGINE", raising=False)
    assert resolve_engine() == ("rust" if rust_core() is not None else "python")
    monkeypatch.setenv("SEMWM_ENGINE", "Python ")
    assert resolve_engine() == "python"
    monkeypatch.setenv("SEMWM_ENGINE", "numba")
    with pytest.raises(
        ValueError, match=r"SEMWM_ENGINE: expected one of python, rust; got 'numba'"
    ):
        resolve_engine()
    with pytest.raises(ValueError, match=r"engine: expected one of python, rust; got 'c'"):
        resolve_engine("c")


@needs_rust
def test_the_world_runs_the_engine_asked_for(monkeypatch: pytest.MonkeyPatch) -> None:
    knowledge = load_knowledge(shipped_knowledge_path("sim1.yaml"))
    monkeypatch.setenv("SEMWM_ENGINE", "rust")
    world = WorldModel(knowledge)
    assert world.engine == "rust"
    assert WorldModel(knowledge, engine="python").engine == "python"  # the argument wins
    world.ingest([{"time": 0.0, "class": "Cup", "position": [1.0, 2.0], "source": "r"}])
    assert len(world.world(min_existence=0.01).objects) == 1


def test_without_the_extension_python_runs_and_rust_says_why() -> None:
    script = textwrap.dedent(
        """
        import sys
        sys.modules["semwm._core"] = None  # as if it was not built: import fails
        from semwm.filters.engine import EngineUnavailable, rust_core
        from semwm.knowledge.loader import load_knowledge
        from semwm.knowledge.shipped import shipped_knowledge_path
        from semwm.world import WorldModel
        assert rust_core() is None
        knowledge = load_knowledge(shipped_knowledge_path("sim1.yaml"))
        world = WorldModel(knowledge)
        world.ingest([{"time": 0.0, "class": "Cup", "position": [1.0, 2.0], "source": "r"}])
        assert world.engine == "python" and len(world.world(min_existence=0.01).objects) == 1
        try:
            WorldModel(knowledge, engine="rust")
        except EngineUnavailable as error:
            print(error)
        """
    )
    # without SEMWM_ENGINE (a second pass of the suite sets it to rust)
    env = {k: v for k, v in os.environ.items() if k != "SEMWM_ENGINE"}
    done = subprocess.run(
        [sys.executable, "-c", script],
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
        env=env,
    )
    assert done.returncode == 0, done.stderr
    assert "engine='rust' needs the Rust core semwm._core" in done.stdout
    assert "pip install ." in done.stdout


def test_unavailable_is_a_runtime_error() -> None:
    assert issubclass(EngineUnavailable, RuntimeError)
    if rust_core() is not None:
        assert resolve_engine("rust") == "rust"
