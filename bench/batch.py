"""Batch re-analysis throughput: sessions per minute, process pool of 1 and 2 jobs, and a Dask LocalCluster.

    python bench/batch.py [--sessions 20] [--seconds 10] [--workers 2] [--report]

Records ``--sessions`` simulated sessions of ``--seconds`` each (the default bench, ``--fast``),
then analyses the whole folder into a fresh catalogue per run, the way ``acq analyze FOLDER`` does
(no report PNGs unless ``--report``). The figure includes the parent's hashing and catalogue writes
and the pool's or cluster's start-up; the cluster runs ``--workers`` single-threaded worker
processes on this machine.
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from pathlib import Path

from rich.console import Console
from rich.table import Table

from acq.batch import DEFAULT_REQUEST, find_sessions, run_batch
from acq.catalogue import Catalogue
from acq.config import load_bench, load_profile
from acq.recorder import Recorder
from drivers.registry import open_bench

REQUEST = DEFAULT_REQUEST


def record_sessions(out: Path, n: int, seconds: float) -> list[Path]:
    """``n`` sessions of the default simulated bench in ``out``."""
    bench, profile = load_bench(), load_profile("triangle_0.2s")
    for _ in range(n):
        current, drive = open_bench(bench, fast=True)
        result = Recorder(bench, profile, current, drive, out, seconds).run()
        assert result.status == "complete", result.stop_reason
    return find_sessions(out)[0]


def timed(paths: list[Path], catalogue: Path, report: bool, **how: object) -> tuple[float, int]:
    """Analyse ``paths`` into a fresh catalogue; return (wall s, failures)."""
    t0 = time.perf_counter()
    with Catalogue(catalogue) as c:
        done = run_batch(paths, c, REQUEST, report=report, **how)  # type: ignore[arg-type]
    assert not done.skipped
    return time.perf_counter() - t0, len(done.failed)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sessions", type=int, default=20)
    parser.add_argument("--seconds", type=float, default=10.0)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--report", action="store_true", help="also draw each session's report PNG")
    args = parser.parse_args()
    console = Console()
    with tempfile.TemporaryDirectory() as tmp:
        with console.status(f"recording {args.sessions} sessions of {args.seconds:g} s …"):
            paths = record_sessions(Path(tmp) / "sessions", args.sessions, args.seconds)
        table = Table(title=f"batch analysis of {len(paths)} simulated {args.seconds:g} s sessions "
                            f"({os.cpu_count()} CPUs)")
        for column in ("runner", "wall s", "sessions/min", "failed"):
            table.add_column(column, justify="left" if column == "runner" else "right")
        runs: list[tuple[str, dict[str, object]]] = [("process pool, 1 job", {"jobs": 1}),
                                                     ("process pool, 2 jobs", {"jobs": 2})]
        from distributed import LocalCluster

        with LocalCluster(n_workers=args.workers, threads_per_worker=1, processes=True,
                          dashboard_address=None) as cluster:
            runs.append((f"Dask LocalCluster, {args.workers} workers × 1 thread",
                         {"scheduler": cluster.scheduler_address}))
            for i, (name, how) in enumerate(runs):
                wall, failed = timed(paths, Path(tmp) / f"catalogue{i}.sqlite", args.report, **how)
                table.add_row(name, f"{wall:.1f}", f"{60.0 * len(paths) / wall:.1f}", str(failed))
    table.caption = "load average (1, 5, 15 min) at the end: " + ", ".join(f"{x:.1f}" for x in os.getloadavg())
    console.print(table)


if __name__ == "__main__":
    main()
