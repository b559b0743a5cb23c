"""The fault-injection run of issue 30, as one table: what was tried, what was lost.

Each row is one kind of fault, injected into a real ``semwm serve`` (a subprocess)
or a :class:`~semwm.persistence.DurableWorld`, with a client that records what was
acknowledged (200) and what was refused (a 4xx/5xx answer: nothing may be kept).
After the fault the journal is read offline and compared with the client's record.

1. ``kill -9``: N kills at random moments of a server taking batches, each followed
   by a restart on the same data directory.
2. Full disk: the data directory on a 2 MiB tmpfs (as root, where ``mount`` works),
   else SQLite's "database or disk is full" raised by the journal's fault hook (the
   table says which); then the space comes back.
3. Damage: the write-ahead log cut by 100 bytes, cut in half, filled with garbage,
   deleted, and the database emptied, after a kill; each start must name the loss.
4. Connection flood: one client holds 300 connections; probes of ``/health`` and
   ``/ready`` (and a read of another client) must be answered.
5. Overload: 12 writers at once against ``--max-waiting 4``: answers 200, 503 with
   ``Retry-After`` (nothing applied), and what the journal kept. Then the team's
   load (5 robots x 10 det x 30 Hz) with one core taken by another process, robots
   that queue late frames and robots that drop them (``bench_teamload.overload_run``,
   in memory): it must not storm (the robots end within 1 s of their schedule, and
   the service replays fewer scans than it acknowledges).

    python benchmarks/bench_faults.py [--kills 5] [--seed 0] [--team-seconds 20]

Must read: nothing acknowledged lost, nothing refused kept, every damage reported.
Writes benchmarks/out/faults.{json,md}.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import random
import re
import shutil
import socket
import sqlite3
import subprocess
import sys
import tempfile
import threading
import time
import uuid
from collections.abc import Iterator
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import httpx

from semwm.knowledge.loader import load_knowledge
from semwm.knowledge.shipped import shipped_knowledge_path
from semwm.persistence import DurableWorld, StoreError
from semwm.persistence.journal import DATABASE, HEAD, Journal
from semwm.persistence.records import batch_parts

HERE = Path(__file__).parent
SIM1 = shipped_knowledge_path("sim1.yaml")
LISTENING = re.compile(r"Uvicorn running on (http://127\.0\.0\.1:\d+)")


@dataclass
class Row:
    """One fault: what was tried and what came of it."""

    fault: str
    tried: str
    acknowledged: int
    refused: int
    lost: int  # acknowledged, not in the journal
    refused_kept: int  # refused, in the journal
    detected: str
    notes: str = ""

    @property
    def ok(self) -> bool:
        return self.lost == 0 and self.refused_kept == 0 and not self.detected.startswith("NO")


# -- helpers ------------------------------------------------------------------------------------


class Server:
    """``semwm serve --port 0`` in a subprocess (so it can be SIGKILLed)."""

    def __init__(self, data_dir: Path, log: Path, *options: str) -> None:
        command = [
            sys.executable, "-m", "semwm.cli", "serve", "--knowledge", str(SIM1), "--port", "0",
            "--data-dir", str(data_dir), "--snapshot-every", "20", "--log-level", "info",
            *options,
        ]  # fmt: skip
        self.log = log
        with log.open("w") as out:
            self.process = subprocess.Popen(command, stdout=out, stderr=subprocess.STDOUT)
        deadline = time.monotonic() + 30
        while True:
            found = LISTENING.search(log.read_text())
            if found:
                self.url = found.group(1)
                return
            if self.process.poll() is not None or time.monotonic() > deadline:
                self.process.kill()
                raise RuntimeError(f"the server did not start:\n{log.read_text()}")
            time.sleep(0.05)

    def kill(self) -> None:
        self.process.kill()
        self.process.wait(10)


def journal_times(data_dir: Path) -> set[float]:
    """The time of every batch's first detection in the journal (each batch unique)."""
    return {t for _, t in journal_keys(data_dir)}


def journal_keys(data_dir: Path) -> set[tuple[str, float]]:
    """``(source, time)`` of every batch's first detection in the journal."""
    journal = Journal(data_dir, "batch")
    try:
        archived = int(journal.meta("archived_through") or 0)
        records = [*journal.archived_records(), *journal.records(after=archived)]
    finally:
        journal.close()
    keys = set()
    for record in records:
        if record.kind == "batch":
            detections, _ = batch_parts(record.payload)
            if detections:
                first = detections[0]
                keys.add((str(first.get("source")), round(float(first["time"]), 6)))
    return keys


def matched(posted: set[tuple[str, float]], kept: set[tuple[str, float]]) -> set[tuple[str, float]]:
    """The posted batches found in the journal. A scan within ``--order-tolerance``
    (5 ms) of the newest processed one is journaled at the time it was moved to, just
    after it: a posted time matches a journaled one of its source within 6 ms."""
    by_source: dict[str, list[float]] = {}
    for source, t in kept:
        by_source.setdefault(source, []).append(t)
    return {
        (source, t)
        for source, t in posted
        if any(abs(t - u) < 0.006 for u in by_source.get(source, ()))
    }


def batch(t: float, source: str = "bench") -> dict[str, Any]:
    return {"detections": [{"time": t, "class": "Cup", "position": [1.0, 1.0], "source": source}]}


class Poster:
    """Posts one batch per call with a unique time; records the outcome of each."""

    def __init__(self) -> None:
        self.t = 0.0
        self.acked: set[float] = set()
        self.refused: set[float] = set()
        self.statuses: dict[int, int] = {}

    def post(self, http: httpx.Client) -> int | None:
        self.t = round(self.t + 0.01, 6)
        try:
            status = http.post("/detections", json=batch(self.t)).status_code
        except httpx.HTTPError:
            return None  # no answer: the outcome is unknown, neither promised
        self.statuses[status] = self.statuses.get(status, 0) + 1
        (self.acked if status == 200 else self.refused).add(self.t)
        return status


# -- 1. kill -9 ----------------------------------------------------------------------------------


def kills(work: Path, count: int, rng: random.Random) -> Row:
    data_dir = work / "kill"
    poster = Poster()
    for cycle in range(count):
        server = Server(data_dir, work / f"kill-{cycle}.log")
        stop = threading.Event()

        def run(url: str = server.url, stop: threading.Event = stop) -> None:
            with httpx.Client(base_url=url, timeout=5) as http:
                while not stop.is_set() and poster.post(http) is not None:
                    pass

        writer = threading.Thread(target=run)
        writer.start()
        time.sleep(rng.uniform(0.2, 1.2))
        server.kill()
        stop.set()
        writer.join(10)
    last = Server(data_dir, work / "kill-last.log")  # must start: no damage after kills
    recovery = httpx.get(f"{last.url}/persistence", timeout=10).json()["journal"]["recovery"]
    last.kill()
    kept = journal_times(data_dir)
    return Row(
        "kill -9",
        f"{count} kills at random moments, restart after each",
        len(poster.acked),
        len(poster.refused),
        len(poster.acked - kept),
        len(poster.refused & kept),
        "no damage (none expected)" if not recovery["damage"] else f"NO: {recovery['damage']}",
    )


# -- 2. full disk ---------------------------------------------------------------------------------


@contextlib.contextmanager
def tmpfs(size: str) -> Iterator[Path | None]:
    where = Path(tempfile.gettempdir()) / f"semwm-bench-tmpfs-{uuid.uuid4().hex[:8]}"
    where.mkdir()
    mounted = False
    with contextlib.suppress(OSError, subprocess.SubprocessError):
        mounted = (
            os.geteuid() == 0
            and subprocess.run(
                ["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", str(where)],
                capture_output=True,
                timeout=10,
            ).returncode
            == 0
        )
    try:
        yield where if mounted else None
    finally:
        if mounted:
            subprocess.run(["umount", "-l", str(where)], capture_output=True, timeout=10)
        with contextlib.suppress(OSError):
            where.rmdir()


def full_disk(work: Path) -> Row:
    with tmpfs("2m") as disk:
        if disk is None:
            return full_disk_hook(work)
        data_dir, filler = disk / "data", disk / "filler"
        poster = Poster()
        server = Server(data_dir, work / "full.log", "--snapshot-every", "10")
        ready_when_full = None
        try:
            with httpx.Client(base_url=server.url, timeout=10) as http:
                poster.post(http)
                stat = os.statvfs(disk)
                filler.write_bytes(b"\0" * max(0, stat.f_bavail * stat.f_frsize - 96 * 1024))
                while len(poster.refused) < 20 and len(poster.acked) < 5000:
                    poster.post(http)
                ready_when_full = http.get("/ready").status_code
                reads = http.get("/world").status_code
                filler.unlink()
                ready_after = http.get("/ready").status_code
                for _ in range(30):
                    poster.post(http)
        finally:
            server.kill()
        kept = journal_times(data_dir)
    return Row(
        "full disk (2 MiB tmpfs)",
        "fill the disk, post until 20 refusals, free the space, post 30 more",
        len(poster.acked),
        len(poster.refused),
        len(poster.acked - kept),
        len(poster.refused & kept),
        f"answers {poster.statuses}; /ready {ready_when_full} full, {ready_after} after",
        f"reads while full: {reads}",
    )


def full_disk_hook(work: Path) -> Row:
    """The same cycle in process, the disk's refusal raised by the journal's fault hook."""
    world = DurableWorld.open(work / "hook", load_knowledge(SIM1), snapshot_every=5)
    acked, refused = set(), set()
    full = False

    def fault(step: str) -> None:
        if full and step in ("append", "snapshot", "commit"):
            raise sqlite3.OperationalError("database or disk is full")

    world.journal.fault = fault
    t = 0.0
    for i in range(60):
        full = 20 <= i < 40
        t = round(t + 0.01, 6)
        try:
            world.ingest(batch(t)["detections"])
            acked.add(t)
        except Exception:
            refused.add(t)
    world.close()
    kept = journal_times(work / "hook")
    return Row(
        "full disk (fault hook)",
        "60 batches, the store full for batches 20-39 (no tmpfs could be mounted)",
        len(acked),
        len(refused),
        len(acked - kept),
        len(refused & kept),
        "every refusal a WriteFailed (full)",
    )


# -- 3. damage ----------------------------------------------------------------------------------


def damaged(work: Path) -> list[Row]:
    def cut(by: int) -> Any:
        def damage(path: Path) -> None:
            wal = path / (DATABASE + "-wal")
            size = wal.stat().st_size
            os.truncate(wal, size - by if by else size // 2)

        return damage

    def garbage(path: Path) -> None:
        wal = path / (DATABASE + "-wal")
        wal.write_bytes(random.Random(7).randbytes(wal.stat().st_size))

    def delete(path: Path) -> None:
        (path / (DATABASE + "-wal")).unlink()

    def empty(path: Path) -> None:
        os.truncate(path / DATABASE, 0)
        (path / (DATABASE + "-wal")).unlink()

    cases = {
        "WAL cut by 100 bytes": cut(100),
        "WAL cut in half": cut(0),
        "WAL filled with garbage": garbage,
        "WAL deleted": delete,
        "database emptied": empty,
    }
    knowledge = load_knowledge(SIM1)
    rows: list[Row] = []
    for name, damage in cases.items():
        live, left = work / f"live-{len(rows)}", work / f"left-{len(rows)}"
        world = DurableWorld.open(live, knowledge, snapshot_every=10_000)
        for step in range(100):
            world.ingest(batch(0.01 * (step + 1))["detections"])
        last = world.journal.last_seq()
        left.mkdir()
        for part in (DATABASE, DATABASE + "-wal", HEAD):
            shutil.copyfile(live / part, left / part)  # as kill -9 leaves them
        world.close()
        damage(left)
        try:
            DurableWorld.open(left, knowledge, on_damage="refuse").close()
            refusal = "NO: it started"
        except StoreError as error:
            refusal = "refused" if "are lost" in str(error) else f"NO: {error}"
        reopened = DurableWorld.open(left, knowledge, on_damage="truncate")
        recovery = reopened.recovery
        lost = last - recovery.replayed
        reported = recovery.lost[1] - recovery.lost[0] + 1 if recovery.lost else 0
        reopened.close()
        detected = (
            f"{refusal}; truncate reports {reported} lost, new={recovery.new}"
            if reported == lost and not recovery.new
            else f"NO: reported {reported} of {lost} lost, new={recovery.new}"
        )
        tried = "100 batches, kill -9, damage, start"
        note = f"{lost} records lost to the damage, all named"
        rows.append(Row(f"damage: {name}", tried, 100, 0, 0, 0, detected, note))
    return rows


# -- 4. connection flood ---------------------------------------------------------------------------


def flood(work: Path) -> Row:
    server = Server(work / "flood", work / "flood.log")
    port = int(server.url.rsplit(":", 1)[1])
    held = []
    try:
        for _ in range(300):
            held.append(socket.create_connection(("127.0.0.1", port)))
        answered = total = 0
        started = time.monotonic()
        while time.monotonic() - started < 5.0:
            for path in ("/health", "/ready"):
                total += 1
                with contextlib.suppress(httpx.HTTPError):
                    answered += httpx.get(f"{server.url}{path}", timeout=2).status_code == 200
            time.sleep(0.1)
        transport = httpx.HTTPTransport(local_address="127.0.0.2")
        with httpx.Client(transport=transport, timeout=5) as other:
            other_status = other.get(f"{server.url}/world").status_code
    finally:
        for sock in held:
            sock.close()
        server.kill()
    return Row(
        "connection flood",
        "one client holds 300 idle connections; probes for 5 s",
        0,
        0,
        0,
        0,
        f"probes answered {answered}/{total}" if answered == total else f"NO: {answered}/{total}",
        f"another client's GET /world: {other_status}",
    )


# -- 5. overload ------------------------------------------------------------------------------


def overload(work: Path) -> Row:
    data_dir = work / "overload"
    server = Server(data_dir, work / "overload.log", "--max-waiting", "4")
    acked: set[tuple[str, float]] = set()
    refused: set[tuple[str, float]] = set()
    statuses: dict[int, int] = {}
    lock = threading.Lock()

    def writer(index: int) -> None:
        with httpx.Client(base_url=server.url, timeout=10) as http:
            for step in range(60):
                t = round(1.0 + step * 0.05 + index * 0.001, 6)
                body = {"detections": [
                    {"time": t, "class": "Cup", "position": [1.0 + 0.01 * j, 1.0 + index],
                     "source": f"w{index}"} for j in range(10)
                ]}  # fmt: skip
                with contextlib.suppress(httpx.HTTPError):
                    status = http.post("/detections", json=body).status_code
                    with lock:
                        statuses[status] = statuses.get(status, 0) + 1
                        (acked if status == 200 else refused).add((f"w{index}", t))

    threads = [threading.Thread(target=writer, args=(i,)) for i in range(12)]
    started = time.monotonic()
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join(120)
    seconds = time.monotonic() - started
    stats = httpx.get(f"{server.url}/metrics", timeout=10).text
    replayed = re.search(r"^semwm_replayed_scans (\S+)", stats, re.MULTILINE)
    server.kill()
    kept = journal_keys(data_dir)
    return Row(
        "overload",
        "12 writers x 60 batches of 10 at once, --max-waiting 4",
        len(acked),
        len(refused),
        len(acked - matched(acked, kept)),
        len(matched(refused, kept)),
        f"answers {dict(sorted(statuses.items()))}",
        f"{len(acked) * 10 / seconds:.0f} det/s acknowledged; scans replayed "
        f"{replayed.group(1) if replayed else '?'}",
    )


def team_overload(seconds: float) -> list[Row]:
    """The team's load with one core taken (:func:`bench_teamload.overload_run`)."""
    from bench_teamload import LATE_MODES, overload_run

    rows = []
    for late in LATE_MODES:
        r = overload_run(seconds, late)
        answers = r["answers"]
        refused = sum(n for status, n in answers.items() if status not in ("200", "dropped"))
        share = ", ".join(f"{s} {100 * v:.1f} %" for s, v in r["share"].items())
        verdict = "NO: it storms" if r["storms"] else "sheds, no storm"
        rows.append(
            Row(
                f"overload: team load, one core taken, robots {late} late frames",
                f"5 robots x 10 det x 30 Hz for {seconds:g} s, a busy loop on one core",
                answers.get("200", 0),
                refused,
                0,
                0,
                f"{verdict}: {r['replayed_scans']:.0f} scans replayed, behind "
                f"{r['behind_schedule_s']} s at the end",
                f"{r['acknowledged_det_per_s']:.0f} det/s acknowledged of 1,500; {share}; "
                f"late dropped {r['dropped_by_service']} / skipped {r['skipped_by_clients']}; "
                f"POST p99 {r['post_ms']['p99']} ms; in memory (no journal compared)",
            )
        )
    return rows


# -- the run --------------------------------------------------------------------------------------


def table(rows: list[Row]) -> str:
    lines = [
        "| fault | tried | acknowledged | refused | lost | refused kept | detected / answers | "
        "notes |",
        "|---|---|---:|---:|---:|---:|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r.fault} | {r.tried} | {r.acknowledged} | {r.refused} | {r.lost} | "
            f"{r.refused_kept} | {r.detected} | {r.notes} |"
        )
    verdict = "PASS" if all(r.ok for r in rows) else "FAIL"
    lines.append("")
    lines.append(f"{verdict}: nothing acknowledged lost, nothing refused kept, damage reported")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--kills", type=int, default=5)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument(
        "--team-seconds",
        type=float,
        default=20.0,
        help="length of each team overload run with one core taken (0: skip them)",
    )
    args = parser.parse_args(argv)
    rng = random.Random(args.seed)
    with tempfile.TemporaryDirectory(prefix="semwm-faults-") as tmp:
        work = Path(tmp)
        rows = [kills(work, args.kills, rng), full_disk(work), *damaged(work), flood(work),
                overload(work)]  # fmt: skip
    if args.team_seconds > 0:
        rows += team_overload(args.team_seconds)
    text = table(rows)
    print(text)
    out = HERE / "out"
    out.mkdir(exist_ok=True)
    (out / "faults.md").write_text(text + "\n", encoding="utf-8")
    (out / "faults.json").write_text(
        json.dumps([asdict(r) for r in rows], indent=2) + "\n", encoding="utf-8"
    )
    return 0 if all(r.ok for r in rows) else 1


if __name__ == "__main__":
    raise SystemExit(main())
