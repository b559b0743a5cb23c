"""HTTP vs in-process, side by side: what the service adds to each detection.

Run: ``python benchmarks/bench_http.py [--quick] [--repeats 3] [--update-results]``

The server is ``semwm serve`` in its own process (client and server do not share
an interpreter lock) on a free loopback port, with the time guards opened (the
scenarios' times start at 0). The client is :class:`semwm.client.Client`: one
keep-alive connection, one request at a time. Each case runs the same scans
in-process (a fresh :class:`semwm.WorldModel`, ``ingest`` of the scenario's
:class:`~semwm.detection.Detection` values, as ``run_scenario`` does) and over HTTP
(``POST /reset``, then one ``POST /detections`` per scan or batch), back to back,
``--repeats`` times; the table gives the medians.

* Scans: a static grid of k = 1, 3, 10 objects, each 10 Hz frame one scan of k
  detections; the room (``sim2``: one person walking, clutter; scans of 1-2) and
  RoboCup (``robocup``, 2 s: 5 observers at 30 Hz; scans of 1-7).
* Batches: a static grid of 100 objects, 10 frames (1,000 detections) per request.
* Queries: ``GET /world`` of a static grid of 20 and 1,000 objects beside the model's
  ``world()`` in process.

Split of the HTTP time, from the service's Prometheus metrics
(``semwm_ingest_apply_seconds``: the world model's part under the lock;
``semwm_ingest_latency_seconds``: the whole request inside the server):
``apply`` (the MHF), ``server`` (the rest of the request in the server: parsing,
validation, routing, middlewares, the response), ``client`` (everything else: the
client's encoding and decoding, the loopback round trip, the HTTP parsing of uvicorn
outside the app). ``overhead`` = HTTP time - apply: what the HTTP path adds, whatever
the MHF costs; ``det/s without MHF`` = 1 / overhead per detection.

Writes ``http.json`` and ``http.md`` (with the machine and sizes) to
``benchmarks/out/`` (``benchmarks/results/`` with ``--update-results``).
"""

from __future__ import annotations

import argparse
import os
import re
import socket
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))

from baselines import RESULTS, add_output_arguments, fmt, machine_info, write_results
from tqdm import tqdm

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


@dataclass(frozen=True)
class Case:
    """One workload: requests (each a list of detections) for one knowledge file."""

    name: str
    kind: str  # "scans" or "batches"
    knowledge: Path
    requests: list[list[Detection]]

    @property
    def detections(self) -> int:
        return sum(len(r) for r in self.requests)


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
    n_batches = 8 if quick else 20
    path, _ = _grid_knowledge(GRID_BATCH_OBJECTS, directory)
    frames_per_batch = BATCH // GRID_BATCH_OBJECTS
    scenario = make_scenario(
        "grid", 0, n_objects=GRID_BATCH_OBJECTS,
        duration=(n_batches * frames_per_batch - 1) / 10.0,
    )  # fmt: skip
    dets = list(scenario.detections)
    batches = [dets[i : i + BATCH] for i in range(0, len(dets), BATCH)]
    cases.append(Case(f"grid {GRID_BATCH_OBJECTS}, batches of {BATCH}", "batches", path, batches))
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


# -- the server ---------------------------------------------------------------------------------


class Server:
    """``semwm serve`` in a child process, on a free port; from ``source`` (a checkout of
    another commit) instead of this tree when given."""

    def __init__(self, knowledge: Path, source: Path | None = None) -> None:
        env = {
            **os.environ,
            **({"PYTHONPATH": str(source)} if source is not None else {}),
            "SEMWM_MAX_JUMP": "1e9",
            "SEMWM_MAX_AHEAD": "1e9",
            "SEMWM_TIMEOUT_KEEP_ALIVE": "60",
        }
        with socket.socket() as sock:
            sock.bind(("127.0.0.1", 0))
            port = sock.getsockname()[1]
        command = [
            sys.executable, "-m", "semwm.cli", "serve", "--knowledge", str(knowledge),
            "--port", str(port), "--log-level", "warning",
            "--reorder-window", str(REORDER_WINDOW), "--max-batch", str(BATCH),
        ]  # fmt: skip
        self.process = subprocess.Popen(command, cwd=source or ROOT, env=env)
        self.url = f"http://127.0.0.1:{port}"
        deadline = time.monotonic() + 60
        while True:
            try:
                with Client(self.url, timeout=1) as client:
                    client.get("/health")
                return
            except OSError:
                if self.process.poll() is not None or time.monotonic() > deadline:
                    self.process.kill()
                    raise RuntimeError("semwm serve did not start") from None
                time.sleep(0.1)

    def cpu_seconds(self) -> float:
        """CPU time (user + system, every thread) the server process has used (s)."""
        fields = Path(f"/proc/{self.process.pid}/stat").read_text().rsplit(")", 1)[1].split()
        return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")

    def stop(self) -> None:
        self.process.terminate()
        self.process.wait(10)


def _metric_sums(text: str) -> dict[str, float]:
    sums = {}
    for name in ("semwm_ingest_apply_seconds", "semwm_ingest_latency_seconds"):
        for suffix in ("_sum", "_count"):
            found = re.search(rf"^{name}{suffix} (\S+)$", text, re.MULTILINE)
            sums[name + suffix] = float(found.group(1)) if found else 0.0
    return sums


def _metrics(client: Client) -> dict[str, float]:
    return _metric_sums(client.get_text("/metrics"))


# -- one run of a case --------------------------------------------------------------------------


def in_process(case: Case) -> dict[str, float]:
    """Seconds (wall and CPU) the world model's ``ingest`` took for every request of ``case``."""
    model = WorldModel(load_knowledge(case.knowledge), reorder_window=REORDER_WINDOW)
    total = cpu = 0.0
    for request in case.requests:
        started, cpu_started = time.perf_counter(), time.process_time()
        model.ingest(request)
        total += time.perf_counter() - started
        cpu += time.process_time() - cpu_started
    return {"in_process": total, "in_process_cpu": cpu}


def over_http(case: Case, server: Server, client: Client) -> dict[str, float]:
    """Seconds over HTTP for every request of ``case``, the server's split and the CPU
    time of both processes."""
    bodies = [[d.to_dict() for d in request] for request in case.requests]
    client.request("POST", "/reset")
    before = _metrics(client)
    total = client_cpu = 0.0
    server_cpu = server.cpu_seconds()
    for body in bodies:
        started, cpu_started = time.perf_counter(), time.process_time()
        client.post_detections(body)
        total += time.perf_counter() - started
        client_cpu += time.process_time() - cpu_started
    server_cpu = server.cpu_seconds() - server_cpu
    after = _metrics(client)
    apply = after["semwm_ingest_apply_seconds_sum"] - before["semwm_ingest_apply_seconds_sum"]
    inside = after["semwm_ingest_latency_seconds_sum"] - before["semwm_ingest_latency_seconds_sum"]
    return {
        "http": total,
        "apply": apply,
        "server": inside - apply,
        "client": total - inside,
        "http_cpu": server_cpu + client_cpu,
    }


def run_case(case: Case, repeats: int, servers: dict[str, Path | None]) -> list[dict[str, Any]]:
    """``case`` in-process and over HTTP to each server (label -> source tree), side by side."""
    running = {label: Server(case.knowledge, source) for label, source in servers.items()}
    runs: dict[str, list[dict[str, float]]] = {label: [] for label in servers}
    try:
        clients = {label: Client(s.url, timeout=120) for label, s in running.items()}
        for label, client in clients.items():
            over_http(case, running[label], client)  # warm-up: imports, first allocations
        for _ in range(repeats):
            local = in_process(case)
            for label, client in clients.items():
                runs[label].append({**local, **over_http(case, running[label], client)})
        for client in clients.values():
            client.close()
    finally:
        for server in running.values():
            server.stop()
    return [_row(case, label, label_runs) for label, label_runs in runs.items()]


def query_in_process(case: Case) -> float:
    """Seconds per ``WorldModel.world()`` of ``case``'s world (mean of :data:`QUERIES`)."""
    model = WorldModel(load_knowledge(case.knowledge), reorder_window=REORDER_WINDOW)
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


def run_query_case(
    case: Case, repeats: int, servers: dict[str, Path | None]
) -> list[dict[str, Any]]:
    """``GET /world`` on ``case``'s world over HTTP to each server, beside the model's
    ``world()`` in process (medians of ``repeats``)."""
    running = {label: Server(case.knowledge, source) for label, source in servers.items()}
    rows = []
    try:
        local = [query_in_process(case) for _ in range(repeats)]
        for label, server in running.items():
            with Client(server.url, timeout=120) as client:
                query_over_http(case, client)  # warm-up
                measured = [query_over_http(case, client) for _ in range(repeats)]
            http = statistics.median(m[0] for m in measured)
            inside = statistics.median(local)
            rows.append(
                {
                    "case": case.name,
                    "server": label,
                    "objects": measured[-1][1],
                    "queries": QUERIES,
                    "in_process_ms": round(inside * 1e3, 3),
                    "http_ms": round(http * 1e3, 3),
                    "ratio": round(http / inside, 3),
                }
            )
    finally:
        for server in running.values():
            server.stop()
    return rows


def _row(case: Case, server: str, runs: list[dict[str, float]]) -> dict[str, Any]:
    n = case.detections
    med = {key: statistics.median(r[key] for r in runs) for key in runs[0]}
    ratio = statistics.median(r["http"] / r["in_process"] for r in runs)
    cpu_ratio = statistics.median(r["http_cpu"] / r["in_process_cpu"] for r in runs)
    us = {key: 1e6 * value / n for key, value in med.items()}
    overhead = us["http"] - us["apply"]
    return {
        "case": case.name,
        "server": server,
        "kind": case.kind,
        "requests": len(case.requests),
        "detections": n,
        "detections_per_request": round(n / len(case.requests), 2),
        "repeats": len(runs),
        "in_process_us_per_det": round(us["in_process"], 2),
        "http_us_per_det": round(us["http"], 2),
        "ratio": round(ratio, 3),
        "in_process_cpu_us_per_det": round(us["in_process_cpu"], 2),
        "http_cpu_us_per_det": round(us["http_cpu"], 2),
        "cpu_ratio": round(cpu_ratio, 3),
        "apply_us_per_det": round(us["apply"], 2),
        "server_us_per_det": round(us["server"], 2),
        "client_us_per_det": round(us["client"], 2),
        "overhead_us_per_det": round(overhead, 2),
        "overhead_us_per_request": round(overhead * n / len(case.requests), 1),
        "in_process_det_per_s": round(1e6 / us["in_process"]),
        "http_det_per_s": round(1e6 / us["http"]),
        "det_per_s_without_mhf": round(1e6 / overhead) if overhead > 0 else None,
        "runs": [{k: round(v, 6) for k, v in r.items()} for r in runs],
    }


def markdown(doc: dict[str, Any]) -> str:
    """The results as markdown tables (``http.md``, benchmarks/README.md)."""
    m = doc["machine"]
    servers = ", ".join(f"`{label}`" for label in doc["servers"])
    lines = [
        "# HTTP vs in-process",
        "",
        f"`semwm serve` in its own process on loopback ({doc['server']}), one keep-alive "
        f"client (`semwm.client.Client`), one request at a time; in-process: "
        f"`WorldModel.ingest` of the same scenario `Detection` values. Servers: {servers}. "
        f"Medians of {doc['repeats']} runs, each in-process then over HTTP to each server, "
        f"back to back. Machine: {m['platform']}, {m['cpu_count']} CPUs "
        f"({m.get('processor') or '?'}), Python {m['python']}, {m['date']}, "
        f"commit {m.get('commit')}.",
        "",
        "## One scan per request (target: HTTP / in-process <= 1.5)",
        "",
        "| case | server | requests | det/request | in-process µs/det | HTTP µs/det | "
        "HTTP / in-process | CPU: HTTP / in-process | apply (MHF) µs/det | server µs/det | "
        "client+wire µs/det | overhead µs/request |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in doc["results"]:
        if r["kind"] != "scans":
            continue
        lines.append(
            f"| {r['case']} | {r['server']} | {r['requests']} | "
            f"{r['detections_per_request']:g} | {fmt(r['in_process_us_per_det'])} | "
            f"{fmt(r['http_us_per_det'])} | {r['ratio']:.2f} | {r['cpu_ratio']:.2f} | "
            f"{fmt(r['apply_us_per_det'])} | {fmt(r['server_us_per_det'])} | "
            f"{fmt(r['client_us_per_det'])} | {fmt(r['overhead_us_per_request'])} |"
        )
    lines += [
        "",
        "## Batches (target: >= 50,000 det/s; the MHF's share depends on the core)",
        "",
        "| case | server | requests | in-process det/s | HTTP det/s | HTTP / in-process | "
        "CPU: HTTP / in-process | apply (MHF) µs/det | server µs/det | client+wire µs/det | "
        "overhead µs/det | det/s without MHF |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in doc["results"]:
        if r["kind"] != "batches":
            continue
        lines.append(
            f"| {r['case']} | {r['server']} | {r['requests']} | {r['in_process_det_per_s']} | "
            f"{r['http_det_per_s']} | {r['ratio']:.2f} | {r['cpu_ratio']:.2f} | "
            f"{fmt(r['apply_us_per_det'])} | {fmt(r['server_us_per_det'])} | "
            f"{fmt(r['client_us_per_det'])} | {fmt(r['overhead_us_per_det'])} | "
            f"{fmt(r['det_per_s_without_mhf'])} |"
        )
    if doc.get("queries"):
        lines += [
            "",
            "## Queries: `GET /world` beside the model's `world()`",
            "",
            "A static grid after 5 frames; each figure the mean of "
            f"{doc['queries'][0]['queries']} queries, the median of the runs. HTTP counts the "
            "query, its JSON and the round trip.",
            "",
            "| case | server | objects | in-process ms | HTTP ms | HTTP / in-process |",
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
        "threads. apply: `semwm_ingest_apply_seconds` (the world model under the service's "
        "lock); server: the rest of the request inside the app "
        "(`semwm_ingest_latency_seconds` - apply); client+wire: the client's time minus the "
        "app's (JSON encoding, loopback, uvicorn's HTTP parsing). overhead = HTTP - apply; "
        "det/s without MHF = 1 / overhead.",
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


def main(argv: Sequence[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true", help="fewer frames and batches")
    parser.add_argument("--repeats", type=int, default=3, help="runs of each case (median)")
    parser.add_argument("--only", help="run only the cases whose name contains this")
    parser.add_argument(
        "--compare-with",
        metavar="REV",
        help="also serve the api/ and semwm/ of git revision REV (same packages), side by side",
    )
    add_output_arguments(parser)
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory() as directory:
        servers: dict[str, Path | None] = {"this tree": None}
        if args.compare_with:
            source = source_tree(args.compare_with, Path(directory))
            servers[source.name.removeprefix("src-")] = source
        cases = make_cases(Path(directory), args.quick)
        if args.only:
            cases = [c for c in cases if args.only in c.name]
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
        "servers": list(servers),
        "sizes": {
            "grid_scan_frames": 60 if args.quick else 150,
            "robocup_duration_s": 1.0 if args.quick else 2.0,
            "batch": BATCH,
            "batch_grid_objects": GRID_BATCH_OBJECTS,
        },
        "machine": machine_info(),
        "results": rows,
        "queries": queries,
    }
    write_results(
        RESULTS, "http", report, markdown(report), args.quick, update_results=args.update_results
    )


if __name__ == "__main__":
    main()
