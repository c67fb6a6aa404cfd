"""Reading one monitor's windows from a catalogue many monitors share: by the monitor_id column's index, against
reading every window of the joint's name and keeping the monitor's in Python (what acq did before schema 6, and what
``acq trend`` / ``acq fleet --tag monitor_id=…`` did until the last closing note).

    nice -n 10 python bench/monitor_scope.py [--monitors 100] [--windows 200] [--repeat 20] [--catalogue URL]

The catalogue (a fresh SQLite file in a temporary folder, or an empty PostgreSQL database given by ``--catalogue``)
is filled through :meth:`Catalogue.record`, as a monitor files its windows: ``--monitors`` monitors, each of a robot
whose joint is named ``joint1`` (the shipped robot benches all name it so), ``--windows`` windows each, with the tags a
monitor files. Printed, each the median of ``--repeat`` reads after one unmeasured read:

* **index** — ``Catalogue.entries("joint1", monitor=ID)``: a monitor reading back its own windows;
* **Python filter** — ``Catalogue.entries("joint1")`` and the monitor's kept in Python;
* **acq trend --tag monitor_id=ID** — :func:`acq.monitoring.trend_catalogue.load_trend`, the reading and the trend judged;
* **acq fleet --tag monitor_id=ID** — :func:`acq.monitoring.fleet.load_fleet`, the same for the fleet's row;

and, for SQLite, the query plan of the index read (the index named there is the proof it is used).
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from collections.abc import Callable
from datetime import UTC, datetime, timedelta
from pathlib import Path
from typing import Any

from acq.monitoring.catalogue import MONITOR_TAG, Catalogue, Outcome
from acq.monitoring.catalogue_backends import is_url
from acq.monitoring.fleet import load_fleet
from acq.monitoring.trend_catalogue import load_trend

JOINT = "joint1"
START = datetime(2026, 1, 1, tzinfo=UTC)


def monitor_id(m: int) -> str:
    """The identity of monitor ``m``, as acq makes one (``<host>:<folder>:<8 hex digits>``)."""
    return f"station{m:03d}:/srv/acq/monitor:{m:08x}"


def window(m: int, n: int) -> Outcome:
    """Window ``n`` of monitor ``m``, one minute apart, with the tags and result fields a monitor files."""
    k = 891.0 * (1 + 0.002 * ((n * 7 + m) % 5 - 2))
    start = START + timedelta(minutes=n, seconds=m / 1000)
    doc = {"options": {"select_segments": True}, "analyzed_utc": (start + timedelta(seconds=20)).isoformat(),
           "acq_version": "bench", "K_Nm_per_rad": k, "ci95": {"K_Nm_per_rad": [k - 6.0, k + 6.0]},
           "quality": {"verdict": "ok", "reasons": []}, "antiresonance_hz": 55.0, "resonance_hz": 102.0,
           "excitation": {"excited_fraction": 0.75, "segments_used": 30, "segments_averaged": 30}}
    tags: dict[str, Any] = {"robot": f"r{m}", MONITOR_TAG: monitor_id(m), "monitor_window": n,
                            "monitor_elapsed_s": 60.0 * n, "monitor_every_s": 60.0, "monitor_baseline_windows": 5,
                            "monitor_threshold_pct": 10.0, "monitor_ewma_lambda": 0.2}
    meta = {"session_id": f"m{m:03d}w{n:04d}", "joint": JOINT, "created_utc": start.isoformat(),
            "start_monotonic_ns": n * 60_000_000_000, "status": "complete", "tags": tags}
    return Outcome(f"/srv/acq/monitor/m{m:03d}w{n:04d}.h5", f"sha-{m}-{n}", "{}", meta, doc, None, 1.0)


def fill(location: Path | str, monitors: int, windows: int) -> float:
    """File every monitor's windows, interleaved in time as monitors running together file them; seconds taken."""
    t0 = time.perf_counter()
    with Catalogue(location) as catalogue:
        if not is_url(location):  # one fsync per window is the monitors' cost, not the read's: left out here
            catalogue._db.execute("PRAGMA synchronous = OFF")  # noqa: SLF001 - a bench's shortcut
        for n in range(windows):
            for m in range(monitors):
                catalogue.record(window(m, n))
    return time.perf_counter() - t0


def median_ms(read: Callable[[], object], repeat: int) -> float:
    """Median wall time of ``read`` over ``repeat`` calls after one unmeasured call, ms."""
    read()
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        read()
        times.append(time.perf_counter() - t0)
    return 1000 * statistics.median(times)


def query_plan(catalogue: Catalogue, read: Callable[[], object]) -> list[str]:
    """SQLite's plan of the statement ``read`` runs (as run: with its values bound), one line per step."""
    statements: list[str] = []
    catalogue._db.set_trace_callback(statements.append)  # noqa: SLF001 - a bench looks inside
    read()
    catalogue._db.set_trace_callback(None)  # noqa: SLF001
    return [str(r[3]) for r in catalogue._db.execute(f"EXPLAIN QUERY PLAN {statements[-1]}")]  # noqa: SLF001


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--monitors", type=int, default=100)
    parser.add_argument("--windows", type=int, default=200, help="windows per monitor")
    parser.add_argument("--repeat", type=int, default=20)
    parser.add_argument("--catalogue", default=None, help="an empty PostgreSQL database's URL (default: SQLite)")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        location: Path | str = args.catalogue or Path(tmp) / "catalogue.sqlite"
        filled_s = fill(location, args.monitors, args.windows)
        mine = monitor_id(args.monitors // 2)
        tag = f"{MONITOR_TAG}={mine}"
        now = START + timedelta(minutes=args.windows)
        with Catalogue(location) as catalogue:
            own = catalogue.entries(JOINT, monitor=mine)
            kept = [e for e in catalogue.entries(JOINT) if e.tags.get(MONITOR_TAG) == mine]
            if [e.session_key for e in own] != [e.session_key for e in kept] or len(own) != args.windows:
                print(f"the two reads disagree: {len(own)} and {len(kept)} windows", file=sys.stderr)
                return 1
            figures = {
                "index: entries(joint, monitor=ID)": median_ms(lambda: catalogue.entries(JOINT, monitor=mine),
                                                              args.repeat),
                "Python filter: entries(joint), then the monitor's": median_ms(
                    lambda: [e for e in catalogue.entries(JOINT) if e.tags.get(MONITOR_TAG) == mine], args.repeat),
            }
            plan = [] if is_url(location) else query_plan(catalogue, lambda: catalogue.entries(JOINT, monitor=mine))
        catalogue_arg = [] if is_url(location) else [location]
        figures["acq trend --tag monitor_id=ID (read and judged)"] = median_ms(
            lambda: load_trend(None, location, JOINT, [tag]), args.repeat)
        figures["acq fleet --tag monitor_id=ID (read and judged)"] = median_ms(
            lambda: load_fleet([], [location] if is_url(location) else catalogue_arg, [tag], now=now), args.repeat)
    backend = "PostgreSQL" if is_url(location) else "SQLite"
    print(f"{backend} catalogue of {args.monitors} monitors × {args.windows} windows of joint {JOINT} "
          f"({args.monitors * args.windows} windows, filed in {filled_s:.1f} s); one monitor's {len(own)} windows, "
          f"median of {args.repeat} reads:")
    for what, ms in figures.items():
        print(f"  {what:<52} {ms:8.1f} ms")
    for line in plan:
        print(f"  plan: {line}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
