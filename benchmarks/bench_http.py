"""HTTP vs in-process, both engines side by side, and a request's cost by stage (issue 29).

Run: ``python benchmarks/bench_http.py [--quick] [--repeats 3] [--only NAME]
[--compare-with REV] [--update-results]``

Once the core takes microseconds, the service is the bill: this benchmark says what
the service adds to each detection, with the Python engine and with the Rust engine
(``semwm serve --engine``), and where a request's time goes.

The servers are ``semwm serve`` in their own processes (client and server do not
share an interpreter lock), one per engine, on free loopback ports, with the time
guards opened (the scenarios' times start at 0); each is started through this file
(``--serve``), which times the world model's parts in it (:func:`model_timers`) and
then runs ``semwm serve``. The client is :class:`semwm.client.Client`: one keep-alive
connection, one request at a time (the team case: one per robot). Each case runs
the same requests in process (a fresh :class:`semwm.WorldModel` of each engine,
``ingest`` of the scenario's :class:`~semwm.detection.Detection` values, as
``run_scenario`` does) and over HTTP (``POST /reset``, then one ``POST /detections``
per scan or batch), back to back, engine after engine, ``--repeats`` times; the tables
give the medians.

* Scans: a static grid of k = 1, 3, 10 objects, each 10 Hz frame one scan of k
  detections; the room (``sim2``: one person walking, clutter; scans of 1-2) and
  RoboCup (``robocup``, 2 s: 5 observers at 30 Hz; scans of 1-7).
* Batches: a static grid of 100 objects, 10 frames (1,000 detections) per request
  (issue 29's targets: >= 500,000 det/s in process, >= 200,000 det/s over HTTP).
* A team: 5 robots x 10 detections x 30 Hz on 20 shared objects (``sim1.yaml``,
  ``bench_speed.team_batches``, as ``bench_teamload``): over HTTP each robot posts from
  its own thread and connection, the five of each 1/30 s tick at once (a barrier per
  tick), so their requests wait for each other at the world's lock; in process the
  same batches one after the other. 150 batches of warm-up first, not timed.
* Queries: ``GET /world`` of a static grid of 20 and 1,000 objects beside the
  model's ``world()`` in process.

A request's cost by stage: the servers time every accepted request (``stage_timing``
on: :mod:`api.stages`, ``semwm_ingest_stage_seconds`` in ``/metrics``): read (the body
off the socket), parse (JSON and the wire schema, one pydantic-core call), the hand-
over to an ingest thread, lock (waiting for the world), sources, save, model
(``WorldModel.ingest``), notify, service, respond (the answer's JSON and send), gc (the
garbage collector, wherever it ran). In the
servers this benchmark starts, ``WorldModel.ingest`` is split further
(:func:`model_timers`): validate (``_read``: the detections parsed and checked
against the knowledge, each one's range and region checked; with the Rust engine a
plain batch in one pass of the core's reader, ``_read_plain``), core
(``_process_scans``, or ``_ingest_scan`` for a batch of one scan: the MHF scan, the
confidences, the reorder log), publish (``_publish``: ids and the published world),
and what is left of ``ingest`` (grouping into scans, the time bounds), counted with
validate. Outside the app: the client's time minus
``semwm_ingest_latency_seconds`` (the client's JSON, the loopback, uvicorn's HTTP
parsing); middlewares: that latency minus the stages (the guards, request ids, the
metrics middleware). In process the same timers split ``ingest`` on the same requests
(a separate pass: the in-process times are measured without them).

Writes ``http.json`` and ``http.md`` (with the machine and sizes) to
``benchmarks/out/`` (``benchmarks/results/`` with ``--update-results``).
"""

from __future__ import annotations

import argparse
import functools
import os
import socket
import statistics
import subprocess
import sys
import tempfile
import threading
import time
import timeit
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))

from baselines import RESULTS, add_output_arguments, fmt, machine_info, write_results
from prometheus_client.parser import text_string_to_metric_families
from tqdm import tqdm

from api import stages as timing
from semwm.client import Client
from semwm.detection import Detection
from semwm.knowledge.loader import dump_document, load_knowledge
from semwm.knowledge.shipped import shipped_knowledge_path
from semwm.sim.runner import scans
from semwm.sim.scenarios import make_scenario
from semwm.world import WorldModel

ROOT = Path(__file__).resolve().parents[1]
REORDER_WINDOW = 0.5
BATCH = 1000
GRID_BATCH_OBJECTS = 100
ENGINES = ("python", "rust")
TEAM_ROBOTS = 5
TEAM_WARMUP = 150
TARGETS = {"batch_in_process_det_per_s": 500_000, "batch_http_det_per_s": 200_000}
"""Issue 29's targets for batches of 1,000."""
MODEL_STAGES = ("validate", "core", "publish")
"""The parts of ``WorldModel.ingest`` :func:`model_timers` times (``model``: the rest)."""
GROUPS: tuple[tuple[str, tuple[str, ...]], ...] = (
    ("read", ("read",)),
    ("parse + schema", ("parse",)),
    ("lock", ("lock",)),
    ("validate", ("validate", "model")),
    ("core", ("core",)),
    ("publish", ("publish",)),
    ("service", ("handoff", "sources", "save", "notify", "service", "other", "middlewares")),
    ("respond", ("respond",)),
    ("gc", ("gc",)),
    ("outside the app", ("outside",)),
)
"""The stage table's columns: issue 29's stages, from the timed stages they add up."""
SERVICE_DETAIL = ("handoff", "sources", "save", "notify", "service", "other", "middlewares")


# -- the world model's parts, timed -------------------------------------------------------------


def _timed(function: Callable[..., Any], name: str) -> Callable[..., Any]:
    @functools.wraps(function)
    def timed(*args: Any, **kwargs: Any) -> Any:
        with timing.stage(name):
            return function(*args, **kwargs)

    return timed


@contextmanager
def model_timers() -> Iterator[None]:
    """Within: ``WorldModel.ingest``'s parts are stages of the request being timed
    (:mod:`api.stages`): ``validate`` (``WorldModel._read``: the batch parsed, checked
    against the knowledge and each detection's range and region checked, or
    ``WorldModel._read_plain``: the Rust engine's reader doing all that in one pass),
    ``core`` (``WorldModel._process_scans``, or ``WorldModel._ingest_scan`` for a batch of
    one scan read by the reader) and ``publish`` (``WorldModel._publish``, within either).
    A few stages of a microsecond or less per ``ingest`` (hold 0); outside a timed
    request they cost a no-op each."""
    import semwm.world as world

    patched: list[tuple[Any, str, Any]] = [
        (world.WorldModel, "_read_plain", "validate"),
        (world.WorldModel, "_read", "validate"),
        (world.WorldModel, "_ingest_scan", "core"),
        (world.WorldModel, "_process_scans", "core"),
        (world.WorldModel, "_publish", "publish"),
    ]
    originals = [(owner, attribute, getattr(owner, attribute)) for owner, attribute, _ in patched]
    for owner, attribute, name in patched:
        setattr(owner, attribute, _timed(getattr(owner, attribute), name))
    try:
        yield
    finally:
        for owner, attribute, original in originals:
            setattr(owner, attribute, original)


def serve(argv: Sequence[str]) -> int:
    """``semwm serve ARGV`` in this process, with :func:`model_timers` (a server of
    this benchmark: ``bench_http.py --serve ARGV``)."""
    from semwm.cli import main as semwm_main

    with model_timers():
        return semwm_main(["serve", *argv])


def timers_cost(loops: int = 2000, rounds: int = 5) -> dict[str, Any]:
    """What the stage timers cost a request (CPU µs, the best of ``rounds``): a timed
    request's stages as the service (13) and :func:`model_timers` (3) time a one-scan
    batch, their sums added, and the same stages outside a timed request."""
    names = (
        "read", "parse", "service", "sources", "lock", "sources", "save", "sources",
        "model", "validate", "core", "publish", "notify", "sources", "notify",
        "respond",
    )  # fmt: skip
    totals = timing.StageTotals()

    def timed() -> None:
        stages, token = timing.start()
        for name in names:
            with timing.stage(name):
                pass
        timing.stop(token)
        totals.add(stages.finish())

    def untimed() -> None:
        for name in names:
            with timing.stage(name):
                pass

    def cpu_us(function: Callable[[], None]) -> float:
        timer = timeit.Timer(function, timer=time.process_time)
        return min(timer.repeat(number=loops, repeat=rounds)) / loops * 1e6

    return {
        "stages": len(names),
        "service_stages": len(names) - 3,
        "timed_us_per_request": cpu_us(timed),
        "untimed_us_per_request": cpu_us(untimed),
    }


# -- the cases ----------------------------------------------------------------------------------


@dataclass(frozen=True)
class Case:
    """One workload: requests (each a list of detections) for one knowledge file; the
    first ``warmup`` are sent before the timing starts; ``clients`` > 1: that many
    robots post at once, request ``i`` from robot ``i % clients``."""

    name: str
    kind: str  # "scans", "batches", "team" or "query"
    knowledge: Path
    requests: list[list[Detection]]
    warmup: int = 0
    clients: int = 1

    @property
    def timed(self) -> list[list[Detection]]:
        return self.requests[self.warmup :]

    @property
    def detections(self) -> int:
        return sum(len(r) for r in self.timed)


def _grid_knowledge(n: int, directory: Path) -> tuple[Path, Any]:
    """The grid scenario's knowledge with its region covering ``n`` objects (a file)."""
    scenario = make_scenario("grid", 0, n_objects=n, duration=0.1)
    knowledge = load_knowledge(shipped_knowledge_path(scenario.knowledge_file))
    world = knowledge.document.world.model_copy(
        update={"region": tuple(tuple(r) for r in scenario.region)}
    )
    document = knowledge.document.model_copy(update={"world": world})
    path = directory / f"grid{n}.yaml"
    dump_document(document, path)
    return path, scenario


def batch_case(directory: Path, n_batches: int) -> Case:
    """A static grid of :data:`GRID_BATCH_OBJECTS` objects, 10 frames (1,000 detections)
    per request, ``n_batches`` requests."""
    path, _ = _grid_knowledge(GRID_BATCH_OBJECTS, directory)
    frames_per_batch = BATCH // GRID_BATCH_OBJECTS
    scenario = make_scenario(
        "grid", 0, n_objects=GRID_BATCH_OBJECTS,
        duration=(n_batches * frames_per_batch - 1) / 10.0,
    )  # fmt: skip
    dets = list(scenario.detections)
    batches = [dets[i : i + BATCH] for i in range(0, len(dets), BATCH)]
    return Case(f"grid {GRID_BATCH_OBJECTS}, batches of {BATCH}", "batches", path, batches)


def team_case(seconds: float) -> Case:
    """The team's stream (``bench_speed.team_batches``) after :data:`TEAM_WARMUP` batches."""
    from bench_speed import team_batches

    batches = [
        [Detection.model_validate(d) for d in batch]
        for batch in team_batches(seconds + TEAM_WARMUP / (TEAM_ROBOTS * 30.0))
    ]
    return Case(
        f"team, {TEAM_ROBOTS} robots at once",
        "team",
        shipped_knowledge_path("sim1.yaml"),
        batches,
        warmup=TEAM_WARMUP,
        clients=TEAM_ROBOTS,
    )


def make_cases(directory: Path, quick: bool) -> list[Case]:
    cases = []
    frames = 60 if quick else 150
    for k in (1, 3, 10):
        path, _ = _grid_knowledge(k, directory)
        scenario = make_scenario("grid", 0, n_objects=k, duration=(frames - 1) / 10.0)
        cases.append(Case(f"grid k={k}", "scans", path, list(scans(scenario.detections))))
    room = make_scenario("sim2", 0)
    cases.append(
        Case("room (sim2)", "scans", shipped_knowledge_path(room.knowledge_file),
             list(scans(room.detections)))
    )  # fmt: skip
    robocup = make_scenario("robocup", 0, duration=1.0 if quick else 2.0)
    cases.append(
        Case("robocup", "scans", shipped_knowledge_path(robocup.knowledge_file),
             list(scans(robocup.detections)))
    )  # fmt: skip
    cases.append(batch_case(directory, 8 if quick else 20))
    cases.append(team_case(2.0 if quick else 5.0))
    return cases


QUERY_OBJECTS = (20, 1000)
QUERIES = 30


def make_query_cases(directory: Path) -> list[Case]:
    """Worlds to query: a static grid of N objects after 5 frames (one scan each)."""
    cases = []
    for n in QUERY_OBJECTS:
        path, _ = _grid_knowledge(n, directory)
        scenario = make_scenario("grid", 0, n_objects=n, duration=0.4)
        requests = list(scans(scenario.detections))
        cases.append(Case(f"GET /world, {n} objects", "query", path, requests))
    return cases


# -- the servers --------------------------------------------------------------------------------


@dataclass(frozen=True)
class ServerSpec:
    """A server to run: its label, engine, and the source tree (``None``: this one)."""

    label: str
    engine: str
    source: Path | None = None


class Server:
    """``semwm serve`` in a child process, on a free port: through :func:`serve` (the
    world model's parts timed) from this tree, or plainly from ``spec.source``."""

    def __init__(self, knowledge: Path, spec: ServerSpec) -> None:
        source = spec.source
        env = {
            **os.environ,
            **({"PYTHONPATH": str(source)} if source is not None else {}),
            "SEMWM_MAX_JUMP": "1e9",
            "SEMWM_MAX_AHEAD": "1e9",
            "SEMWM_TIMEOUT_KEEP_ALIVE": "60",
            "SEMWM_STAGE_TIMING": "1",  # api.stages (a revision without it ignores it)
        }
        with socket.socket() as sock:
            sock.bind(("127.0.0.1", 0))
            port = sock.getsockname()[1]
        options = [
            "--knowledge", str(knowledge), "--port", str(port), "--log-level", "warning",
            "--reorder-window", str(REORDER_WINDOW), "--max-batch", str(BATCH),
            "--engine", spec.engine,
        ]  # fmt: skip
        if source is None:
            command = [sys.executable, str(Path(__file__).resolve()), "--serve", *options]
        else:
            command = [sys.executable, "-m", "semwm.cli", "serve", *options]
        self.process = subprocess.Popen(command, cwd=source or ROOT, env=env)
        self.url = f"http://127.0.0.1:{port}"
        deadline = time.monotonic() + 60
        while True:
            try:
                with Client(self.url, timeout=1) as client:
                    self.health = client.get("/health")
                return
            except OSError:
                if self.process.poll() is not None or time.monotonic() > deadline:
                    self.process.kill()
                    raise RuntimeError("semwm serve did not start") from None
                time.sleep(0.1)

    def cpu_seconds(self) -> float:
        """CPU time the server process's threads have run (s): the sum of their
        ``/proc/PID/task/TID/schedstat`` (nanoseconds; a thread that ended in between is
        missed), else user + system of ``/proc/PID/stat`` (in clock ticks, 10 ms)."""
        total = 0
        try:
            for task in Path(f"/proc/{self.process.pid}/task").iterdir():
                total += int((task / "schedstat").read_text().split()[0])
        except (OSError, ValueError, IndexError):
            fields = Path(f"/proc/{self.process.pid}/stat").read_text().rsplit(")", 1)[1].split()
            return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")
        return total / 1e9

    def stop(self) -> None:
        self.process.terminate()
        self.process.wait(10)


def metric_values(text: str) -> dict[str, float]:
    """The samples of ``/metrics`` this benchmark reads: ``NAME`` or ``NAME:STAGE``."""
    wanted = {
        "semwm_ingest_apply_seconds_sum", "semwm_ingest_latency_seconds_sum",
        "semwm_ingest_latency_seconds_count", "semwm_ingest_stage_seconds_sum",
        "semwm_ingest_stage_seconds_count", "semwm_replayed_scans", "semwm_arrival_order_scans",
    }  # fmt: skip
    values = {}
    for family in text_string_to_metric_families(text):
        for sample in family.samples:
            if sample.name not in wanted:
                continue
            stage = sample.labels.get("stage")
            values[sample.name + (f":{stage}" if stage else "")] = sample.value
    return values


def _metrics(client: Client) -> dict[str, float]:
    return metric_values(client.get_text("/metrics"))


# -- one run of a case --------------------------------------------------------------------------


def _model(case: Case, engine: str, reorder_window: float = REORDER_WINDOW) -> WorldModel:
    """A fresh world model of ``case`` after its warm-up requests."""
    model = WorldModel(load_knowledge(case.knowledge), reorder_window=reorder_window, engine=engine)
    for request in case.requests[: case.warmup]:
        model.ingest(request)
    return model


def in_process(case: Case, engine: str) -> dict[str, float]:
    """Seconds (wall and CPU) the world model's ``ingest`` took for every timed request."""
    model = _model(case, engine)
    total = cpu = 0.0
    for request in case.timed:
        started, cpu_started = time.perf_counter(), time.process_time()
        model.ingest(request)
        total += time.perf_counter() - started
        cpu += time.process_time() - cpu_started
    return {"in_process": total, "in_process_cpu": cpu}


def in_process_stages(
    case: Case, engine: str, reorder_window: float = REORDER_WINDOW
) -> dict[str, float]:
    """Seconds by stage of ``ingest`` for every timed request (:func:`model_timers`):
    ``validate``, ``core``, ``publish`` and ``model`` (the rest)."""
    model = _model(case, engine, reorder_window)
    totals = timing.StageTotals()
    with model_timers():
        for request in case.timed:
            stages, token = timing.start()
            try:
                with timing.stage("model"):
                    model.ingest(request)
            finally:
                timing.stop(token)
            totals.add(stages.finish())
    _, seconds = totals.totals()
    return {name: seconds.get(name, 0.0) for name in (*MODEL_STAGES, "model")}


def _post_all(client: Client, bodies: Sequence[list[dict[str, Any]]]) -> float:
    """Post ``bodies`` one after the other; the client's seconds."""
    total = 0.0
    for body in bodies:
        started = time.perf_counter()
        client.post_detections(body)
        total += time.perf_counter() - started
    return total


def _post_as_team(url: str, bodies: list[list[dict[str, Any]]], robots: int) -> float:
    """Post ``bodies`` from ``robots`` threads, body ``i`` from robot ``i % robots``, each
    tick's ``robots`` bodies at once (a barrier); the sum of the requests' seconds."""
    barrier = threading.Barrier(robots)
    seconds = [0.0] * robots
    errors: list[BaseException] = []

    def robot(r: int) -> None:
        try:
            with Client(url, timeout=120) as client:
                for body in bodies[r::robots]:
                    barrier.wait()
                    started = time.perf_counter()
                    client.post_detections(body)
                    seconds[r] += time.perf_counter() - started
        except BaseException as error:  # reported below, after the others stop
            errors.append(error)
            barrier.abort()

    threads = [threading.Thread(target=robot, args=(r,)) for r in range(robots)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    if errors:
        raise errors[0]
    return sum(seconds)


def over_http(case: Case, server: Server, client: Client) -> dict[str, float]:
    """Seconds over HTTP for every timed request of ``case``, the server's split and the
    CPU time of both processes."""
    bodies = [[d.to_dict() for d in request] for request in case.requests]
    client.request("POST", "/reset")
    _post_all(client, bodies[: case.warmup])
    before = _metrics(client)
    server_cpu = server.cpu_seconds()
    started, cpu_started = time.perf_counter(), time.process_time()
    if case.clients > 1:
        requests_s = _post_as_team(server.url, bodies[case.warmup :], case.clients)
    else:
        requests_s = _post_all(client, bodies[case.warmup :])
    total = time.perf_counter() - started
    client_cpu = time.process_time() - cpu_started
    server_cpu = server.cpu_seconds() - server_cpu
    after = _metrics(client)
    delta = {key: after.get(key, 0.0) - before.get(key, 0.0) for key in after}
    latency = delta["semwm_ingest_latency_seconds_sum"]
    run = {
        "http": total,
        "requests_s": requests_s,
        "http_cpu": server_cpu + client_cpu,
        "server_cpu": server_cpu,
        "apply": delta["semwm_ingest_apply_seconds_sum"],
        "latency": latency,
        "timed_requests": delta.get("semwm_ingest_stage_seconds_count:read", 0.0),
        "replayed_scans": delta.get("semwm_replayed_scans", 0.0),
        "arrival_order_scans": delta.get("semwm_arrival_order_scans", 0.0),
    }
    stage_sum = 0.0
    for key, value in delta.items():
        if key.startswith("semwm_ingest_stage_seconds_sum:"):
            run[f"stage:{key.split(':', 1)[1]}"] = value
            stage_sum += value
    if stage_sum:
        run["stage:middlewares"] = latency - stage_sum
    run["stage:outside"] = requests_s - latency
    return run


def run_case(case: Case, repeats: int, servers: list[ServerSpec]) -> list[dict[str, Any]]:
    """``case`` in process and over HTTP to each server, side by side, ``repeats`` times."""
    running = {spec.label: Server(case.knowledge, spec) for spec in servers}
    runs: dict[str, list[dict[str, float]]] = {spec.label: [] for spec in servers}
    try:
        clients = {label: Client(s.url, timeout=120) for label, s in running.items()}
        for spec in servers:  # warm-up: imports, first allocations
            in_process(case, spec.engine)
            over_http(case, running[spec.label], clients[spec.label])
        for _ in tqdm(range(repeats), desc=case.name, unit="run", leave=False):
            for spec in servers:
                local = in_process(case, spec.engine)
                split = {
                    f"in_process:{k}": v for k, v in in_process_stages(case, spec.engine).items()
                }
                http = over_http(case, running[spec.label], clients[spec.label])
                runs[spec.label].append({**local, **split, **http})
        for client in clients.values():
            client.close()
    finally:
        for server in running.values():
            server.stop()
    return [_row(case, spec, runs[spec.label]) for spec in servers]


def query_in_process(case: Case, engine: str) -> float:
    """Seconds per ``WorldModel.world()`` of ``case``'s world (mean of :data:`QUERIES`)."""
    model = WorldModel(load_knowledge(case.knowledge), reorder_window=REORDER_WINDOW, engine=engine)
    for request in case.requests:
        model.ingest(request)
    started = time.perf_counter()
    for _ in range(QUERIES):
        model.world()
    return (time.perf_counter() - started) / QUERIES


def query_over_http(case: Case, client: Client) -> tuple[float, int]:
    """Seconds per ``GET /world`` of ``case``'s world, and the objects answered."""
    client.request("POST", "/reset")
    for request in case.requests:
        client.post_detections([d.to_dict() for d in request])
    objects = len(client.get("/world")["objects"])
    started = time.perf_counter()
    for _ in range(QUERIES):
        client.get("/world")
    return (time.perf_counter() - started) / QUERIES, objects


def run_query_case(case: Case, repeats: int, servers: list[ServerSpec]) -> list[dict[str, Any]]:
    """``GET /world`` on ``case``'s world over HTTP to each server, beside the model's
    ``world()`` in process with the same engine (medians of ``repeats``)."""
    rows = []
    for spec in servers:
        server = Server(case.knowledge, spec)
        try:
            with Client(server.url, timeout=120) as client:
                query_over_http(case, client)  # warm-up
                measured = []
                local = []
                for _ in range(repeats):
                    local.append(query_in_process(case, spec.engine))
                    measured.append(query_over_http(case, client))
        finally:
            server.stop()
        http = statistics.median(m[0] for m in measured)
        inside = statistics.median(local)
        rows.append(
            {
                "case": case.name,
                "server": spec.label,
                "engine": spec.engine,
                "objects": measured[-1][1],
                "queries": QUERIES,
                "in_process_ms": round(inside * 1e3, 3),
                "http_ms": round(http * 1e3, 3),
                "ratio": round(http / inside, 3),
            }
        )
    return rows


def _row(case: Case, spec: ServerSpec, runs: list[dict[str, float]]) -> dict[str, Any]:
    n = case.detections
    requests = len(case.timed)
    keys = sorted({key for r in runs for key in r})
    med = {key: statistics.median(r.get(key, 0.0) for r in runs) for key in keys}
    us = {key: 1e6 * value / n for key, value in med.items()}
    per_request = {key: 1e6 * value / requests for key, value in med.items()}
    stages = {
        k.split(":", 1)[1]: round(v, 2) for k, v in per_request.items() if k.startswith("stage:")
    }
    local = {
        k.split(":", 1)[1]: round(v, 2)
        for k, v in per_request.items()
        if k.startswith("in_process:")
    }
    model_keys = [f"stage:{name}" for name in (*MODEL_STAGES, "model")]
    model_us = sum(us.get(key, 0.0) for key in model_keys) if "stage:model" in us else us["apply"]
    http_us = us["http"]
    overhead = http_us - model_us
    return {
        "case": case.name,
        "server": spec.label,
        "engine": spec.engine,
        "kind": case.kind,
        "requests": requests,
        "clients": case.clients,
        "detections": n,
        "detections_per_request": round(n / requests, 2),
        "repeats": len(runs),
        "in_process_us_per_det": round(us["in_process"], 2),
        "http_us_per_det": round(http_us, 2),
        "ratio": round(statistics.median(r["http"] / r["in_process"] for r in runs), 3),
        "in_process_cpu_us_per_det": round(us["in_process_cpu"], 2),
        "http_cpu_us_per_det": round(us["http_cpu"], 2),
        "cpu_ratio": round(statistics.median(r["http_cpu"] / r["in_process_cpu"] for r in runs), 3),
        "model_us_per_det": round(model_us, 2),
        "service_us_per_det": round(us["latency"] - model_us, 2),
        "client_us_per_det": round(us["requests_s"] - us["latency"], 2),
        "request_latency_us": round(per_request["requests_s"], 1),
        "server_cpu_us_per_request": round(per_request["server_cpu"], 1),
        "server_latency_us_per_request": round(per_request["latency"], 1),
        "overhead_us_per_det": round(overhead, 2),
        "overhead_us_per_request": round(overhead * n / requests, 1),
        "in_process_det_per_s": round(1e6 / us["in_process"]),
        "in_process_cpu_det_per_s": round(1e6 / us["in_process_cpu"]),
        "http_det_per_s": round(1e6 / http_us),
        "det_per_s_without_mhf": round(1e6 / overhead) if overhead > 0 else None,
        "timed_requests": med.get("timed_requests"),
        "replayed_scans": med.get("replayed_scans"),
        "arrival_order_scans": med.get("arrival_order_scans"),
        "stages_us_per_request": stages,
        "in_process_stages_us_per_request": local,
        "runs": [{k: round(v, 6) for k, v in r.items()} for r in runs],
    }


# -- the report ---------------------------------------------------------------------------------


def _group(stages: dict[str, float], names: tuple[str, ...]) -> float | None:
    found = [stages[name] for name in names if name in stages]
    return sum(found) if found else None


def _met(value: float | None, target: float) -> str:
    return "—" if value is None else ("met" if value >= target else "not met")


def _load(m: dict[str, Any]) -> str:
    load = m.get("load_average")
    return "not recorded" if load is None else f"{load[0]:g}"


def markdown(doc: dict[str, Any]) -> str:
    """The results as markdown tables (``http.md``, benchmarks/README.md)."""
    m = doc["machine"]
    servers = ", ".join(f"`{label}`" for label in doc["servers"])
    results = doc["results"]
    lines = [
        "# HTTP vs in-process, both engines, and a request's cost by stage",
        "",
        f"`semwm serve --engine E` in its own process on loopback ({doc['server']}), one "
        f"keep-alive client (`semwm.client.Client`), one request at a time (the team: one "
        f"client per robot, the robots of a tick at once); in process: `WorldModel.ingest` of "
        f"the same `Detection` values with the same engine. Servers: {servers}. Medians of "
        f"{doc['repeats']} runs, each in process then over HTTP, engine after engine, back to "
        f"back. Machine: {m['platform']}, {m['cpu_count']} CPUs ({m.get('processor') or '?'}), "
        f"1-minute load average {_load(m)} at the end, Python {m['python']}, {m['date']}, "
        f"commit {m.get('commit')}; "
        "sizes: " + ", ".join(f"{k} {v}" for k, v in doc["sizes"].items()) + ".",
        "",
        "## One scan per request",
        "",
        "| case | engine | requests | det/request | in-process µs/det | HTTP µs/det | "
        "HTTP / in-process | CPU: HTTP / in-process | model µs/det | service µs/det | "
        "client+wire µs/det | overhead µs/request |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in results:
        if r["kind"] != "scans":
            continue
        lines.append(
            f"| {r['case']} | {r['server']} | {r['requests']} | "
            f"{r['detections_per_request']:g} | {fmt(r['in_process_us_per_det'])} | "
            f"{fmt(r['http_us_per_det'])} | {r['ratio']:.2f} | {r['cpu_ratio']:.2f} | "
            f"{fmt(r['model_us_per_det'])} | {fmt(r['service_us_per_det'])} | "
            f"{fmt(r['client_us_per_det'])} | {fmt(r['overhead_us_per_request'])} |"
        )
    lines += [
        "",
        "## Batches of 1,000 (targets: >= 500,000 det/s in process, >= 200,000 det/s over HTTP)",
        "",
        "| case | engine | requests | in-process det/s | in process: target | HTTP det/s | "
        "HTTP: target | HTTP / in-process | CPU: HTTP / in-process | model µs/det | "
        "service µs/det | client+wire µs/det | overhead µs/det | det/s without the model | "
        "server CPU µs/det |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in results:
        if r["kind"] != "batches":
            continue
        lines.append(
            f"| {r['case']} | {r['server']} | {r['requests']} | {r['in_process_det_per_s']} | "
            f"{_met(r['in_process_det_per_s'], TARGETS['batch_in_process_det_per_s'])} | "
            f"{r['http_det_per_s']} | "
            f"{_met(r['http_det_per_s'], TARGETS['batch_http_det_per_s'])} | "
            f"{r['ratio']:.2f} | {r['cpu_ratio']:.2f} | {fmt(r['model_us_per_det'])} | "
            f"{fmt(r['service_us_per_det'])} | {fmt(r['client_us_per_det'])} | "
            f"{fmt(r['overhead_us_per_det'])} | {fmt(r['det_per_s_without_mhf'])} | "
            f"{fmt(r['server_cpu_us_per_request'] / r['detections_per_request'])} |"
        )
    team = [r for r in results if r["kind"] == "team"]
    if team:
        lines += [
            "",
            "## A team at once (5 robots x 10 detections x 30 Hz, `sim1.yaml`)",
            "",
            "Each robot posts from its own connection; the five requests of a 1/30 s tick are "
            "sent at once. A batch this small is applied on the event loop when the world is "
            "free (`api/ingest_fast.py`, `INLINE_BODY`), so the others wait for the loop "
            "before the app reads them (counted outside the app in the stage table), not at "
            "the world's lock. det/s: detections over the run's wall time (the robots post as "
            "fast as the service answers, not at 30 Hz); latency: a request's mean time at "
            "its client.",
            "",
            "| case | engine | requests | in-process det/s | HTTP det/s | request latency µs | "
            "lock wait µs/request | model µs/request | scans replayed | in arrival order |",
            "|---|---|---|---|---|---|---|---|---|---|",
        ]
        for r in team:
            stages = r["stages_us_per_request"]
            model = _group(stages, (*MODEL_STAGES, "model"))
            lines.append(
                f"| {r['case']} | {r['server']} | {r['requests']} | {r['in_process_det_per_s']} "
                f"| {r['http_det_per_s']} | {fmt(r['request_latency_us'])} | "
                f"{fmt(stages.get('lock'))} | {fmt(model)} | {fmt(r['replayed_scans'])} | "
                f"{fmt(r['arrival_order_scans'])} |"
            )
    lines += [
        "",
        "## A request's cost by stage (µs per request)",
        "",
        "Timed in the server (`semwm_ingest_stage_seconds`, `api/stages.py`; the world "
        "model's parts by this benchmark's timers in its servers). read: the body off the "
        "socket; parse + schema: JSON and the wire schema (one pydantic-core call); lock: "
        "waiting for the world; validate: the detections against the knowledge "
        "(`WorldModel._read`: `parse`, `check`, each detection's range and region check; "
        "with the Rust engine a plain batch in one pass of the core's reader); core: the MHF scan "
        "(with the confidences and the reorder log); publish: ids and the published world; "
        "service: the rest of the service (sources, the save that undoes a failed change, "
        "listeners, the hand-over to a thread, middlewares; detail below); respond: the "
        "answer's JSON and send; gc: the garbage collector, wherever it ran in the request; "
        "outside the app: the client's JSON, the loopback, uvicorn's HTTP parsing. Each a "
        "median over the runs; a run's stages add up to its HTTP time per request (the last "
        "column but two: for the team, a request's mean latency at its client). In the "
        "server: `semwm_ingest_latency_seconds` per request, the stages from read to gc and "
        "the middlewares; server CPU: the CPU time of the server's threads per request "
        "(`/proc/PID/task/*/schedstat`): where it is well below the time in the server, "
        "the server waited for a CPU (the machine is shared) or, for the team, for the "
        "world's lock.",
        "",
        "| case | engine | " + " | ".join(name for name, _ in GROUPS) + " | HTTP µs/request | "
        "in the server | server CPU |",
        "|---|---|" + "---|" * (len(GROUPS) + 3),
    ]
    for r in results:
        stages = r["stages_us_per_request"]
        if not stages:
            continue
        cells = [fmt(_group(stages, names)) for _, names in GROUPS]
        lines.append(
            f"| {r['case']} | {r['server']} | " + " | ".join(cells) + f" | "
            f"{fmt(r['request_latency_us'])} | {fmt(r['server_latency_us_per_request'])} | "
            f"{fmt(r['server_cpu_us_per_request'])} |"
        )
    lines += [
        "",
        "### The service's part in detail (µs per request)",
        "",
        "handoff: to an ingest thread and back (bodies over 4 KiB); sources: placing the "
        "batch on the sources' clocks and in time order, the late-scan policies, the bound "
        "on sources; save: the copy of the model's tables that undoes a failed change; "
        "notify: the listeners (metrics, live feed) and `/health`'s summary; service: the "
        "rest (overload check, hooks, warnings, idempotency); other: the rest of the fast "
        "path; middlewares: the guards, request ids and the metrics middleware "
        "(`semwm_ingest_latency_seconds` minus the stages).",
        "",
        "| case | engine | " + " | ".join(SERVICE_DETAIL) + " |",
        "|---|---|" + "---|" * len(SERVICE_DETAIL),
    ]
    for r in results:
        stages = r["stages_us_per_request"]
        if not stages:
            continue
        lines.append(
            f"| {r['case']} | {r['server']} | "
            + " | ".join(fmt(stages.get(name)) for name in SERVICE_DETAIL)
            + " |"
        )
    lines += [
        "",
        "### In process: `WorldModel.ingest` by stage (µs per request)",
        "",
        "The same requests, the same timers, in this process (a pass of its own).",
        "",
        "| case | engine | validate | core | publish | in-process µs/request |",
        "|---|---|---|---|---|---|",
    ]
    for r in results:
        local = r["in_process_stages_us_per_request"]
        if not local:
            continue
        lines.append(
            f"| {r['case']} | {r['server']} | {fmt(_group(local, ('validate', 'model')))} | "
            f"{fmt(local.get('core'))} | {fmt(local.get('publish'))} | "
            f"{fmt(r['in_process_us_per_det'] * r['detections_per_request'])} |"
        )
    cost = doc.get("timers_cost")
    if cost:
        lines += [
            "",
            f"The timers themselves (CPU, measured in this run, best of 5 x 2,000): "
            f"{cost['stages']} stages of a request ({cost['service_stages']} the service's, "
            f"{cost['stages'] - cost['service_stages']} this benchmark's in its servers) cost "
            f"{fmt(cost['timed_us_per_request'])} µs "
            f"when the request is timed (`stage_timing` on), "
            f"{fmt(cost['untimed_us_per_request'])} µs when not (the default).",
        ]
    if doc.get("queries"):
        lines += [
            "",
            "## Queries: `GET /world` beside the model's `world()`",
            "",
            "A static grid after 5 frames; each figure the mean of "
            f"{doc['queries'][0]['queries']} queries, the median of the runs. HTTP counts the "
            "query, its JSON and the round trip.",
            "",
            "| case | engine | objects | in-process ms | HTTP ms | HTTP / in-process |",
            "|---|---|---|---|---|---|",
        ]
        for q in doc["queries"]:
            lines.append(
                f"| {q['case']} | {q['server']} | {q['objects']} | {fmt(q['in_process_ms'])} | "
                f"{fmt(q['http_ms'])} | {q['ratio']:.2f} |"
            )
    lines += [
        "",
        "HTTP / in-process: wall time. CPU: the CPU time of the server process (every "
        "thread) and the client over the in-process CPU time; on a shared machine the wall "
        "ratio also counts waiting for a CPU at each hand-over between processes and "
        "threads. model: `WorldModel.ingest` in the server (validate + core + publish); "
        "service: the rest of the request in the server (`semwm_ingest_latency_seconds` - "
        "model); client+wire: the client's time minus the server's (JSON, loopback, "
        "uvicorn's HTTP parsing). overhead = HTTP - model: what the HTTP path adds whatever "
        "the world model costs; det/s without the model = 1 / overhead.",
        "",
    ]
    return "\n".join(lines)


def server_description() -> str:
    import uvicorn

    loops = []
    for module in ("httptools", "uvloop", "orjson"):
        try:
            __import__(module)
            loops.append(module)
        except ImportError:
            pass
    return f"uvicorn {uvicorn.__version__}" + (f" with {', '.join(loops)}" if loops else "")


def source_tree(revision: str, directory: Path) -> Path:
    """The files of ``revision`` (``git archive``) in ``directory``."""
    commit = subprocess.run(
        ["git", "rev-parse", "--short", revision], cwd=ROOT, check=True,
        capture_output=True, text=True,
    ).stdout.strip()  # fmt: skip
    target = directory / f"src-{commit}"
    target.mkdir()
    archive = subprocess.run(
        ["git", "archive", commit], cwd=ROOT, check=True, capture_output=True
    ).stdout
    subprocess.run(["tar", "-x", "-C", str(target)], input=archive, check=True)
    return target


def main(argv: Sequence[str] | None = None) -> int:
    arguments = list(sys.argv[1:] if argv is None else argv)
    if arguments[:1] == ["--serve"]:  # a server of this benchmark (Server)
        return serve(arguments[1:])
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true", help="fewer frames and batches")
    parser.add_argument("--repeats", type=int, default=3, help="runs of each case (median)")
    parser.add_argument("--only", help="run only the cases whose name contains this")
    parser.add_argument(
        "--engines", nargs="+", default=list(ENGINES), choices=ENGINES, help="engines to serve"
    )
    parser.add_argument(
        "--compare-with",
        metavar="REV",
        help="also serve the api/ and semwm/ of git revision REV with the Python engine (its "
        "Rust core would need a build of its own), side by side; not stage-timed",
    )
    add_output_arguments(parser)
    args = parser.parse_args(arguments)
    with tempfile.TemporaryDirectory() as directory:
        servers = [ServerSpec(engine, engine) for engine in args.engines]
        if args.compare_with:
            source = source_tree(args.compare_with, Path(directory))
            label = f"{source.name.removeprefix('src-')} (python)"
            servers.append(ServerSpec(label, "python", source))
        cases = make_cases(Path(directory), args.quick)
        if args.only:
            cases = [c for c in cases if args.only in c.name]
        cost = timers_cost()
        rows = [
            row
            for case in tqdm(cases, desc="http", unit="case")
            for row in run_case(case, args.repeats, servers)
        ]
        query_cases = [
            c for c in make_query_cases(Path(directory)) if not args.only or args.only in c.name
        ]
        queries = [
            row
            for case in tqdm(query_cases, desc="queries", unit="case")
            for row in run_query_case(case, args.repeats, servers)
        ]
    report = {
        "benchmark": "http",
        "quick": args.quick,
        "repeats": args.repeats,
        "reorder_window": REORDER_WINDOW,
        "server": server_description(),
        "servers": [spec.label for spec in servers],
        "engines": {spec.label: spec.engine for spec in servers},
        "sizes": {
            "grid_scan_frames": 60 if args.quick else 150,
            "robocup_duration_s": 1.0 if args.quick else 2.0,
            "batch": BATCH,
            "batch_grid_objects": GRID_BATCH_OBJECTS,
            "batches": 8 if args.quick else 20,
            "team_seconds": 2.0 if args.quick else 5.0,
            "team_warmup_batches": TEAM_WARMUP,
        },
        "targets": TARGETS,
        "machine": machine_info(),
        "timers_cost": cost,
        "results": rows,
        "queries": queries,
    }
    write_results(
        RESULTS, "http", report, markdown(report), args.quick, update_results=args.update_results
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
