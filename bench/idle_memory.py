"""Resident memory of a process idle after analyses, with acq analyze's allocator setting and without (prints
figures; not a test).

    python bench/idle_memory.py [--sizes 60,600] [--analyses 3] [--sessions DIR]

For each size a session is recorded by the simulated bench (as bench/analysis_speed.py does), then fresh Python
processes load it and analyse it ``--analyses`` times as ``acq analyze`` does, and print their resident set (VmRSS)
afterwards, idle, and their peak (VmHWM), for three allocators:

* ``acq``: :func:`acq.entry.keep_freed_memory` (what a one-shot ``acq analyze``/``acq record`` process sets);
* ``default``: glibc's malloc defaults (what ``acq monitor`` and every worker and child process run with);
* ``default+trim``: the defaults and ``malloc_trim(0)`` after the analyses.

What stays resident while idle is what a long-running process (``acq monitor``: hours) holds between windows.
"""

from __future__ import annotations

import argparse
import ctypes
import json
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))
from bench.analysis_speed import record  # noqa: E402 — after the path: this checkout's acq

ALLOCATORS = ("acq", "default", "default+trim")


def _status_mb(field: str) -> float:
    """A ``/proc/self/status`` field (VmRSS, VmHWM), MB."""
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith(field + ":"):
            return int(line.split()[1]) / 1024
    raise KeyError(field)


def child(path: str, analyses: int, allocator: str) -> dict:
    """In a fresh process: the allocator, then ``analyses`` analyses of ``path``; resident memory afterwards."""
    if allocator == "acq":
        from acq.entry import keep_freed_memory

        keep_freed_memory()
    from acq.offline.analyze import recording_from_session, request_for
    from acq.recording.reader import load
    from analysis.pipeline import analyze

    session = load(path)
    rec, options = recording_from_session(session), request_for(session)
    for _ in range(analyses):
        analyze(rec, options)
    if allocator == "default+trim":
        ctypes.CDLL(None).malloc_trim(0)
    return {"idle_rss_mb": _status_mb("VmRSS"), "peak_rss_mb": _status_mb("VmHWM")}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", default="60,600", help="session lengths, s (default 60,600)")
    parser.add_argument("--analyses", type=int, default=3, help="analyses per process (default 3)")
    parser.add_argument("--sessions", type=Path, default=Path(tempfile.gettempdir()) / "acq_bench_sessions",
                        help="folder to keep (and reuse) the recorded sessions (default: acq_bench_sessions in the "
                             "temp folder)")
    parser.add_argument("--child", help=argparse.SUPPRESS)
    parser.add_argument("--allocator", choices=ALLOCATORS, default="acq", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        print(json.dumps(child(args.child, args.analyses, args.allocator)))
        return 0
    print(f"{'session':>8} {'allocator':>13} {'idle RSS, MB':>13} {'peak RSS, MB':>13}   ({args.analyses} analyses)")
    for seconds in (float(s) for s in args.sizes.split(",")):
        path = record(seconds, args.sessions)
        for allocator in ALLOCATORS:
            proc = subprocess.run([sys.executable, __file__, "--child", str(path), "--analyses", str(args.analyses),
                                   "--allocator", allocator], check=True, capture_output=True, text=True)
            out = json.loads(proc.stdout.strip().splitlines()[-1])
            print(f"{seconds:>7g}s {allocator:>13} {out['idle_rss_mb']:>13.0f} {out['peak_rss_mb']:>13.0f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
