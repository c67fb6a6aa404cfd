"""Cost of the integrity check a reader of a SQLite catalogue makes at open (prints figures).

    python bench/catalogue_check.py [--sessions 1000 10000 100000]

Each catalogue holds ``--sessions`` sessions with one analysis each, rows of the size a monitor writes (a ~400-byte
options_json, tags, reasons); the table gives the file's size and the median wall time (5 runs) of
``PRAGMA quick_check`` (pages and records, no index against its table) and ``PRAGMA integrity_check(1)`` (what
:func:`acq.monitoring.catalogue_damage.integrity_error` runs: every index against its table too) on a warm page cache.
A monitor files a window every few minutes: 100 000 sessions are a year of one joint at one window per 5 min.
"""

from __future__ import annotations

import argparse
import json
import sqlite3
import statistics
import tempfile
import time
from pathlib import Path

from acq.monitoring.catalogue import Catalogue


def build(path: Path, n: int) -> None:
    """A catalogue of ``n`` sessions of joint1 with one analysis each."""
    Catalogue(path).close()
    options = json.dumps({f"option_{i}": f"value {i}" for i in range(20)})
    db = sqlite3.connect(path)
    with db:
        db.executemany("INSERT INTO sessions (session_key, session_id, path, joint, created_utc, status, tags_json, "
                       "monitor_id) VALUES (?, ?, ?, 'joint1', ?, 'complete', '{\"monitor\": \"m\"}', 'm')",
                       ((f"{i:032x}", f"{i:032x}", f"/data/mon/2026-12-01T05-12-{i:08d}_joint1.h5",
                         f"2026-12-01T05:12:{i:08d}Z") for i in range(n)))
        db.executemany("INSERT INTO analyses (session_key, sha256, request_key, options_json, analyzed_utc, verdict, "
                       "reasons_json, K_Nm_per_rad, K_lo, K_hi) VALUES (?, ?, 'r', ?, ?, 'ok', '[]', 890.5, 880, 900)",
                       ((f"{i:032x}", f"{i:064x}", options, f"2026-12-01T05:12:{i:08d}Z") for i in range(n)))
    db.close()  # checkpoints the WAL into the file: its size is the catalogue's


def median_s(path: Path, pragma: str) -> float:
    """Median wall time of ``pragma`` on a read-only connection, s."""
    times = []
    for _ in range(5):
        db = sqlite3.connect(f"file:{path}?mode=ro", uri=True)
        start = time.perf_counter()
        assert db.execute(pragma).fetchone()[0] == "ok"
        times.append(time.perf_counter() - start)
        db.close()
    return statistics.median(times)


def main() -> None:
    """Build each catalogue and print its figures."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sessions", type=int, nargs="+", default=[1000, 10000, 100000])
    args = parser.parse_args()
    print(f"{'sessions':>9} {'MB':>7} {'quick_check s':>14} {'integrity_check s':>18}")
    with tempfile.TemporaryDirectory() as tmp:
        for n in args.sessions:
            path = Path(tmp) / f"c{n}.sqlite"
            build(path, n)
            quick, full = median_s(path, "PRAGMA quick_check"), median_s(path, "PRAGMA integrity_check(1)")
            print(f"{n:>9} {path.stat().st_size / 1e6:>7.1f} {quick:>14.3f} {full:>18.3f}")


if __name__ == "__main__":
    main()
