"""``semwm replay``, ``semwm record`` and ``semwm journal``: recordings and journals.

* ``semwm replay SOURCE [--knowledge K] [--speed X] [--out DIR]`` feeds the changes
  of a data directory, a JSON Lines export, an MCAP recording or a scenario back
  through a world model and writes ``world.jsonl`` (the world published after
  each batch) and ``metrics.json``.
* ``semwm record SOURCE OUT.mcap`` runs the same and records it as MCAP
  (``pip install "semwm[mcap]"``); with ``--out DIR`` it also writes
  ``world.jsonl`` and ``metrics.json`` there.
* ``semwm journal export DATA_DIR [OUT.jsonl]``, ``semwm journal compact DATA_DIR``
  (with the server stopped).
"""

from __future__ import annotations

import argparse
import contextlib
import itertools
import json
import sys
import time as clock
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TextIO

import numpy as np
from tqdm import tqdm

from semwm.cli.common import CommandError, positive_float, require
from semwm.knowledge import Knowledge, KnowledgeError, load_knowledge
from semwm.persistence.records import ReadReport, Record, RecordError, batch_parts
from semwm.persistence.replay import Replayer, model_digest
from semwm.ros2.classmap import ClassMapError
from semwm.ros2.read import BagError, ros2_topics


def _paced(records: Iterator[Record], speed: float | None) -> Iterator[Record]:
    """Records at ``speed`` times real time (by their batches' detection times)."""
    if not speed:
        yield from records
        return
    start_wall: float | None = None
    start_time = 0.0
    for record in records:
        detections = batch_parts(record.payload)[0] if record.kind == "batch" else []
        if detections:
            t = max(float(d["time"]) for d in detections)
            if start_wall is None:
                start_wall, start_time = clock.monotonic(), t
            wait = (t - start_time) / speed - (clock.monotonic() - start_wall)
            if wait > 0:
                clock.sleep(wait)
        yield record


def run_replay(
    source: str,
    out: Path | None,
    knowledge_path: Path | None = None,
    speed: float | None = None,
    progress: bool = True,
    recorder_path: Path | None = None,
    ros2: Ros2Input | None = None,
    ros2_out: Path | None = None,
) -> dict[str, Any]:
    """Replay ``source`` into ``out`` (world.jsonl, metrics.json; ``None``: neither, as
    ``semwm record`` without ``--out``); returns the metrics.

    ``ros2``: ``source`` is a ROS 2 bag read as it says (needs ``knowledge_path``);
    ``ros2_out``: also write each published world to this ROS 2 bag.
    """
    from semwm.persistence.sources import open_records

    knowledge = load_knowledge(knowledge_path) if knowledge_path else None
    replayer = Replayer(knowledge, strict=False)
    report = ReadReport()
    bag_report = None
    if ros2 is None:
        records = _primed(open_records(source, report))
    else:
        if knowledge is None:
            raise CommandError("a ROS 2 bag carries no knowledge: pass --knowledge FILE")
        records, bag_report = _bag_records(source, ros2, knowledge)
    world_bag = None
    if ros2_out is not None:
        from semwm.ros2.write import Ros2WorldWriter

        world_bag = Ros2WorldWriter(ros2_out)
    if out is not None:
        out.mkdir(parents=True, exist_ok=True)
    seconds: list[float] = []
    sizes: list[int] = []
    recorder = None
    try:
        with (
            (
                (out / "world.jsonl").open("w", encoding="utf-8")
                if out is not None
                else contextlib.nullcontext(None)
            ) as worlds,
            tqdm(disable=not progress, desc=f"replay {source}", unit="rec", leave=False) as bar,
        ):
            for record in _paced(records, speed):
                start = clock.perf_counter()
                result = replayer.apply(record)
                elapsed = clock.perf_counter() - start
                bar.update(1)
                if recorder is None and recorder_path is not None and replayer.model is not None:
                    recorder = _start_recorder(recorder_path, replayer)  # writes config, knowledge
                elif recorder is not None and (record.kind != "knowledge" or knowledge is None):
                    recorder.write_change(record)
                if record.kind != "batch" or result is None:
                    continue
                seconds.append(elapsed)
                sizes.append(len(batch_parts(record.payload)[0]))
                assert replayer.model is not None
                state = replayer.model.world()
                if worlds is not None:
                    _write_world(worlds, state.to_dict())
                if recorder is not None:
                    recorder.write_world(state)
                if world_bag is not None:
                    world_bag.write(state)
    finally:  # a recording cut short (Ctrl-C) is still a readable file
        if recorder is not None:
            recorder.close()
        if world_bag is not None:
            world_bag.close()
    counts = replayer.counts
    per = np.asarray(seconds) / np.maximum(np.asarray(sizes), 1) if seconds else np.zeros(1)
    metrics: dict[str, Any] = {
        "source": source,
        "knowledge": str(knowledge_path) if knowledge_path else "as recorded",
        "records": report.records if report.records else None,
        "batches": counts.batches,
        "n_detections": counts.detections,
        "refused_batches": counts.refused_batches,
        "resets": counts.resets,
        "actions": counts.actions,
        "refused_actions": counts.refused_actions,
        "skipped_knowledge_changes": counts.skipped_knowledge,
        "tail_problem": report.problem,
        "first_refusal": counts.first_refusal,
        "objects_at_end": len(replayer.model.world().objects) if replayer.model else 0,
        "digest": model_digest(replayer.model) if replayer.model else None,
        "time_per_detection": {
            "mean_s": float(sum(seconds) / max(sum(sizes), 1)),
            "median_s": float(np.median(per)),
            "p99_s": float(np.percentile(per, 99)),
            "total_ingest_s": float(sum(seconds)),
        },
    }
    if bag_report is not None:
        metrics["ros2"] = {"report": bag_report.lines(), **bag_report.to_dict()}
    if ros2_out is not None:
        metrics["ros2_out"] = str(ros2_out)
    if out is not None:
        (out / "metrics.json").write_text(json.dumps(metrics, indent=2) + "\n", encoding="utf-8")
    return metrics


@dataclass(frozen=True)
class Ros2Input:
    """How to read a ROS 2 bag: its detection topic, sensor pose topic, class map."""

    detections: str
    pose: str | None = None
    class_map: Path | None = None


def _bag_records(
    source: str, ros2: Ros2Input, knowledge: Knowledge
) -> tuple[Iterator[Record], Any]:
    """The bag's records and the report they fill; the bag and its topics are
    checked here (the first record read), before anything is written."""
    from semwm.ros2.classmap import load_class_map
    from semwm.ros2.convert import BagReport
    from semwm.ros2.read import bag_records

    class_map = load_class_map(ros2.class_map, set(knowledge.classes)) if ros2.class_map else None
    bag_report = BagReport()
    records = bag_records(
        Path(source), ros2.detections, knowledge, bag_report, class_map, ros2.pose
    )
    return _primed(records), bag_report


def _primed(records: Iterator[Record]) -> Iterator[Record]:
    """``records`` with the first one read now: a source that cannot be read fails
    here, before anything is written (no empty output folder left behind)."""
    first = next(records, None)
    return records if first is None else itertools.chain([first], records)


def _write_world(handle: TextIO, world: dict[str, Any]) -> None:
    handle.write(json.dumps(world) + "\n")


def _start_recorder(path: Path, replayer: Replayer) -> Any:
    from semwm.persistence.mcap_io import McapRecorder

    assert replayer.model is not None
    model = replayer.model
    last = [0.0]

    def scenario_clock() -> float:  # log time = the detections' time
        if replayer.model is not None and replayer.model.latest_time is not None:
            last[0] = max(last[0], replayer.model.latest_time)
        return last[0]

    recorder = McapRecorder.create(path, lambda: replayer.model or model, scenario_clock)
    recorder.start(model.knowledge, replayer.reorder_window, replayer.hold)
    return recorder


ROS2_ERRORS = (BagError, ClassMapError)
"""A bag or class map that cannot be used as asked: one line, like a missing file."""


def _message(error: Exception) -> str:
    """An error as one line: ``FILE: no such file`` rather than ``[Errno 2] ...``."""
    if isinstance(error, OSError) and error.filename is not None:
        return f"{error.filename}: {error.strerror or error}"
    return str(error)


def _require_mcap(source: str, what: str) -> None:
    if Path(source).suffix == ".mcap":
        require("mcap", what)


def _ros2_options(args: argparse.Namespace) -> tuple[Ros2Input | None, Path | None]:
    """``--ros2-detections``, ``--ros2-pose``, ``--class-map``, ``--ros2-out``, checked."""
    ros2 = None
    if args.ros2_detections is not None:
        require("ros2", "reading a ROS 2 bag")
        ros2 = Ros2Input(args.ros2_detections, args.ros2_pose, args.class_map)
    elif args.ros2_pose is not None or args.class_map is not None:
        raise CommandError("--ros2-pose and --class-map go with --ros2-detections TOPIC")
    else:
        _require_mcap(args.source, "replaying an MCAP file")
        topics = ros2_topics(Path(args.source))
        if topics is not None:
            raise CommandError(
                f"{args.source} is a ROS 2 bag ({', '.join(topics)}): pass --ros2-detections "
                "TOPIC and --knowledge FILE (docs/ros2.md)"
            )
    ros2_out = Path(args.ros2_out) if args.ros2_out else None
    if ros2_out is not None:
        require("ros2", "--ros2-out")
        if ros2_out.exists():
            raise CommandError(f"--ros2-out {ros2_out}: exists already; not overwriting it")
        if not ros2_out.parent.is_dir():
            raise CommandError(f"--ros2-out {ros2_out}: no such folder {ros2_out.parent}/")
    return ros2, ros2_out


def replay_command(args: argparse.Namespace) -> int:
    ros2, ros2_out = _ros2_options(args)
    out = Path(args.out) if args.out else Path("runs") / f"replay-{Path(args.source).stem}"
    try:
        metrics = run_replay(
            args.source,
            out,
            args.knowledge,
            args.speed,
            not args.no_progress,
            ros2=ros2,
            ros2_out=ros2_out,
        )
    except (FileNotFoundError, KnowledgeError, RecordError, ImportError, *ROS2_ERRORS) as error:
        print(f"semwm replay: {_message(error)}", file=sys.stderr)
        return 2
    _summary("replay", out, metrics)
    return 0


def record_command(args: argparse.Namespace) -> int:
    require("mcap", "recording")
    ros2, ros2_out = _ros2_options(args)
    target = Path(args.output)
    out = None if args.out is None else Path(args.out)
    try:
        metrics = run_replay(
            args.source,
            out,
            args.knowledge,
            None,
            not args.no_progress,
            recorder_path=target,
            ros2=ros2,
            ros2_out=ros2_out,
        )
    except (FileNotFoundError, KnowledgeError, RecordError, ImportError, *ROS2_ERRORS) as error:
        print(f"semwm record: {_message(error)}", file=sys.stderr)
        return 2
    _summary("record", out, metrics)
    print(f"recorded {target}")
    return 0


def _summary(what: str, out: Path | None, metrics: dict[str, Any]) -> None:
    wrote = f"; wrote {out}/world.jsonl, metrics.json" if out is not None else ""
    print(
        f"{what} {metrics['source']}: {metrics['batches']} batches, "
        f"{metrics['n_detections']} detections, {metrics['refused_batches']} refused, "
        f"{metrics['objects_at_end']} objects at the end{wrote}"
    )
    if metrics["tail_problem"]:
        print(f"warning: {metrics['tail_problem']}")
    if metrics["first_refusal"]:
        print(f"warning: the first refused batch: {metrics['first_refusal']}")
    if "ros2" in metrics:
        ros2 = metrics["ros2"]
        print(
            f"ROS 2 bag: {ros2['messages']} messages, {ros2['detections']} detections, "
            f"{ros2['used']} used"
        )
        for line in ros2["report"]:
            print(f"  {line}")
    if "ros2_out" in metrics:
        print(f"wrote the world as ROS 2 vision_msgs/msg/Detection3DArray to {metrics['ros2_out']}")


def journal_command(args: argparse.Namespace) -> int:
    from semwm.persistence.durable import DurableWorld
    from semwm.persistence.journal import DATABASE, StoreError

    data_dir = Path(args.data_dir)
    if not (data_dir / DATABASE).is_file():
        print(f"semwm journal: {data_dir}: not a data directory (no {DATABASE})", file=sys.stderr)
        return 2
    try:
        world = DurableWorld.open(data_dir, on_damage="refuse")  # a look changes nothing
    except StoreError as error:
        print(f"semwm journal: {error}", file=sys.stderr)
        return 2
    try:
        if args.action == "export":
            if args.output in (None, "-"):
                count = world.export_jsonl(sys.stdout)
            else:
                with Path(args.output).open("w", encoding="utf-8") as handle:
                    count = world.export_jsonl(handle)
                print(f"exported {count} records to {args.output}")
        elif args.action == "compact":
            path = world.compact()
            print(f"compacted into {path}" if path else "nothing to compact")
        else:
            print(json.dumps(world.status(), indent=2))
    finally:
        world.close()
    return 0


def _common(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "source",
        help="data directory, FILE.jsonl, FILE.mcap, a scenario name (sim1, ...), or a ROS 2 "
        "bag (folder, .mcap, .db3) with --ros2-detections",
    )
    parser.add_argument("--knowledge", type=Path, help="replay into this knowledge file instead")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    group = parser.add_argument_group('ROS 2 bags (pip install "semwm[ros2]"; docs/ros2.md)')
    group.add_argument(
        "--ros2-detections",
        metavar="TOPIC",
        help="SOURCE is a ROS 2 bag: build the world from this topic of "
        "vision_msgs/msg/Detection3DArray or Detection2DArray (needs --knowledge)",
    )
    group.add_argument(
        "--ros2-pose",
        metavar="TOPIC",
        help="the sensor's pose in the world (PoseStamped, PoseWithCovarianceStamped or "
        "Odometry): detections are in the sensor's frame",
    )
    group.add_argument(
        "--class-map",
        type=Path,
        metavar="FILE",
        help="YAML mapping of the detector's class ids to knowledge classes",
    )
    group.add_argument(
        "--ros2-out",
        metavar="BAG",
        help="also write each published world to this new ROS 2 bag (folder) as "
        "vision_msgs/msg/Detection3DArray on /semwm/world",
    )


def add_replay_command(subparsers: Any) -> argparse.ArgumentParser:
    """Add ``replay`` to the ``semwm`` command's sub-commands."""
    parser: argparse.ArgumentParser = subparsers.add_parser(
        "replay", help="feed a journal or recording back through a world model"
    )
    _common(parser)
    parser.add_argument(
        "--speed", type=positive_float, help="times real time (default: as fast as possible)"
    )
    parser.add_argument("--out", help="output directory (default runs/replay-NAME)")
    parser.set_defaults(func=replay_command)
    return parser


def add_record_command(subparsers: Any) -> argparse.ArgumentParser:
    """Add ``record`` to the ``semwm`` command's sub-commands."""
    parser: argparse.ArgumentParser = subparsers.add_parser(
        "record", help="run a journal, export or scenario and record it as MCAP"
    )
    _common(parser)
    parser.add_argument("output", help="the MCAP file to write")
    parser.add_argument(
        "--out", help="also write world.jsonl and metrics.json into this folder (default: not)"
    )
    parser.set_defaults(func=record_command)
    return parser


def add_journal_command(subparsers: Any) -> argparse.ArgumentParser:
    """Add ``journal`` (export, compact, status) to the ``semwm`` command's sub-commands."""
    parser: argparse.ArgumentParser = subparsers.add_parser(
        "journal", help="export, compact or inspect a data directory (server stopped)"
    )
    parser.add_argument("action", choices=["export", "compact", "status"])
    parser.add_argument("data_dir", help="the --data-dir of semwm serve")
    parser.add_argument("output", nargs="?", help="export: FILE.jsonl (default stdout)")
    parser.set_defaults(func=journal_command)
    return parser
