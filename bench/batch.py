"""Batch re-analysis throughput: sessions per minute into a SQLite or a PostgreSQL catalogue, on a process
pool or a Dask LocalCluster of 1 and 2 workers; and concurrent catalogue writes.

    nice -n 10 python bench/batch.py [--sessions 6] [--seconds 4] [--report] [--postgres URL]
                                     [--writers 4] [--writes 50]

Records ``--sessions`` simulated sessions of ``--seconds`` each (the default bench, ``--fast``),
then analyses the whole folder into a fresh catalogue per run, the way ``acq analyze FOLDER`` does
(no report PNGs unless ``--report``). The figure includes the parent's hashing and catalogue writes
and the pool's or cluster's start-up; the cluster runs single-threaded worker processes on this
machine. Then ``--writers`` processes record ``--writes`` synthetic sessions each into one fresh
catalogue at once (opening and migrating it together). PostgreSQL is the server at ``--postgres``
(a URL without database: a fresh database per run is created there) or, by default, a throw-away
server started with Debian's ``postgresql`` package (fsync on, as a real one).
"""

from __future__ import annotations

import argparse
import multiprocessing
import os
import tempfile
import time
from collections.abc import Iterator
from contextlib import ExitStack, contextmanager
from pathlib import Path
from typing import Any

from rich.console import Console
from rich.table import Table

from acq.monitoring.batch import run_batch
from analysis import AnalysisRequest
from acq.config import load_bench, load_profile
from acq.monitoring.catalogue import Catalogue, Outcome
from acq.monitoring.session_search import find_sessions
from acq.recording.recorder import Recorder
from acq.ui.batch_cli import batch_progress
from acq.ui.report_png import draw_report
from drivers.registry import open_bench
from tests.pg_server import new_database, server_binaries, throwaway_server

REQUEST = AnalysisRequest()


def record_sessions(out: Path, n: int, seconds: float) -> list[Path]:
    """``n`` sessions of the default simulated bench in ``out``."""
    bench, profile = load_bench(), load_profile("triangle_0.2s")
    for _ in range(n):
        current, drive = open_bench(bench, fast=True)
        result = Recorder(bench, profile, current, drive, out, seconds).run()
        assert result.status == "complete", result.stop_reason
    return find_sessions(out)[0]


def timed(paths: list[Path], catalogue: Path | str, report: bool, **how: object) -> tuple[float, int]:
    """Analyse ``paths`` into a fresh catalogue; return (wall s, failures)."""
    t0 = time.perf_counter()
    with Catalogue(catalogue) as c, batch_progress() as on_progress:
        done = run_batch(paths, c, REQUEST, draw_report=draw_report if report else None, on_progress=on_progress,
                         **how)  # type: ignore[arg-type]
    assert not done.skipped
    return time.perf_counter() - t0, len(done.failed)


def write_sessions(location: Path | str, writer: str, n: int, start: Any) -> None:
    """Once all writers have imported acq (``start``, a barrier), open the catalogue and record ``n`` synthetic
    (failed) analyses, one transaction each."""
    start.wait()
    with Catalogue(location) as c:
        for i in range(n):
            meta = {"session_id": f"{writer}-{i}", "joint": "j"}
            c.record(Outcome(f"/x/{writer}-{i}.h5", f"h-{writer}-{i}", "r", meta, None, "synthetic", 0.0))


def concurrent_writes(location: Path | str, writers: int, writes: int) -> tuple[float, int]:
    """``writers`` processes × ``writes`` sessions into a fresh catalogue at once; (wall s, sessions found)."""
    context = multiprocessing.get_context("spawn")
    start = context.Barrier(writers + 1)
    procs = [context.Process(target=write_sessions, args=(location, f"w{n}", writes, start)) for n in range(writers)]
    for p in procs:
        p.start()
    start.wait()  # the clock starts when every writer has imported acq
    t0 = time.perf_counter()
    for p in procs:
        p.join()
    wall = time.perf_counter() - t0
    assert all(p.exitcode == 0 for p in procs)
    with Catalogue(location) as c:
        return wall, len({e.session_key for e in c.entries()})


@contextmanager
def postgres(url: str | None) -> Iterator[str]:
    """The server URL to make databases on: ``url``, or a throw-away server for the run."""
    if url is not None:
        yield url
        return
    binaries = server_binaries()
    if binaries is None:
        raise SystemExit("no PostgreSQL server binaries (apt-get install postgresql), or give --postgres URL")
    with throwaway_server(binaries, durable=True) as server:
        yield server


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sessions", type=int, default=6)
    parser.add_argument("--seconds", type=float, default=4.0)
    parser.add_argument("--report", action="store_true", help="also draw each session's report PNG")
    parser.add_argument("--postgres", default=None, metavar="URL", help="PostgreSQL server (default: a throw-away one)")
    parser.add_argument("--writers", type=int, default=4)
    parser.add_argument("--writes", type=int, default=50)
    args = parser.parse_args()
    console = Console(width=100)
    from distributed import LocalCluster

    with tempfile.TemporaryDirectory() as tmp, ExitStack() as stack:
        server = stack.enter_context(postgres(args.postgres))
        with console.status(f"recording {args.sessions} sessions of {args.seconds:g} s …"):
            paths = record_sessions(Path(tmp) / "sessions", args.sessions, args.seconds)
        table = Table(title=f"batch analysis of {len(paths)} simulated {args.seconds:g} s sessions "
                            f"({os.cpu_count()} CPUs)")
        for column in ("catalogue", "runner", "wall s", "sessions/min", "failed"):
            table.add_column(column, justify="left" if column in ("catalogue", "runner") else "right")
        runs: list[tuple[str, dict[str, object]]] = [("process pool, 1 job", {"jobs": 1}),
                                                     ("process pool, 2 jobs", {"jobs": 2})]
        for workers in (1, 2):
            cluster = stack.enter_context(LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                                                       dashboard_address=None))
            runs.append((f"Dask LocalCluster, {workers} × 1 thread",
                         {"scheduler": cluster.scheduler_address}))
        for backend in ("SQLite", "PostgreSQL"):
            for i, (name, how) in enumerate(runs):
                location = Path(tmp) / f"catalogue{i}.sqlite" if backend == "SQLite" else new_database(server)
                wall, failed = timed(paths, location, args.report, **how)
                table.add_row(backend, name, f"{wall:.1f}", f"{60.0 * len(paths) / wall:.1f}", str(failed))
        table.caption = "load average (1, 5, 15 min) at the end: " + ", ".join(f"{x:.1f}" for x in os.getloadavg())
        console.print(table)
        writes = Table(title=f"{args.writers} processes × {args.writes} sessions written at once into a fresh "
                             "catalogue (one transaction each)")
        for column in ("catalogue", "wall s", "sessions/s", "rows", "expected"):
            writes.add_column(column, justify="left" if column == "catalogue" else "right")
        for backend, location in (("SQLite (WAL)", Path(tmp) / "writes.sqlite"), ("PostgreSQL", new_database(server))):
            wall, rows = concurrent_writes(location, args.writers, args.writes)
            writes.add_row(backend, f"{wall:.2f}", f"{args.writers * args.writes / wall:.0f}", str(rows),
                           str(args.writers * args.writes))
        console.print(writes)


if __name__ == "__main__":
    main()
