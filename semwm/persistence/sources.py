"""Where records come from: a data directory, a JSON Lines export, an MCAP recording,
or a simulated scenario (its detections as one batch per scan)."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

from semwm.persistence.journal import DATABASE, Journal
from semwm.persistence.records import (
    ReadReport,
    Record,
    batch_record,
    config_record,
    knowledge_record,
    read_jsonl,
)


def scenario_records(name: str, seed: int = 0, duration: float | None = None) -> Iterator[Record]:
    """A scenario's run as records: its knowledge, then one batch per scan."""
    from semwm.knowledge.loader import load_knowledge
    from semwm.knowledge.shipped import shipped_knowledge_path
    from semwm.sim.runner import scans
    from semwm.sim.scenarios import make_scenario

    sizes = {"duration": duration} if duration is not None and name != "sim2" else {}
    scenario = make_scenario(name, seed, **sizes)
    knowledge = load_knowledge(shipped_knowledge_path(scenario.knowledge_file))
    yield config_record(0.0)
    yield knowledge_record(knowledge)
    for scan in scans(scenario.detections):
        yield batch_record([d.to_dict() for d in scan])


def open_records(source: str, report: ReadReport) -> Iterator[Record]:
    """The records of ``source``: a data directory, ``.jsonl``, ``.mcap`` or a scenario
    name (``sim1``, ``sim2``, ``robocup``...). A damaged end is reported in ``report``."""
    path = Path(source)
    if path.is_dir():
        if not (path / DATABASE).is_file():
            raise FileNotFoundError(f"{path}: not a data directory (no {DATABASE})")
        yield from _journal_records(path, report)
    elif path.suffix == ".mcap":
        from semwm.persistence.mcap_io import read_recording

        yield from read_recording(path, report)
    elif path.suffix in (".jsonl", ".ndjson") or path.is_file():
        yield from read_jsonl(path, report)
    else:
        from semwm.sim.scenarios import SCENARIOS

        if source not in SCENARIOS:
            raise FileNotFoundError(
                f"{source}: no such file or directory, and not a scenario "
                f"({', '.join(sorted(SCENARIOS))})"
            )
        yield from scenario_records(source)


def _journal_records(path: Path, report: ReadReport) -> Iterator[Record]:
    from semwm.persistence.records import RecordError

    journal = Journal(path, "batch")
    try:
        yield from journal.archived_records()
        yield from journal.records(after=int(journal.meta("archived_through") or 0))
    except RecordError as error:
        report.problem = f"{error}; read up to there"
    finally:
        journal.close()
