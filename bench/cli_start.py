"""Start-up of the command line: `acq --help` and an error path against a bare `python -c pass` (prints figures).

    python bench/cli_start.py [--runs 7]

Each command runs in a fresh process (``python -m acq``, what the ``acq`` script runs), ``--runs`` times in turn;
the table gives the median wall time of each and its excess over ``python -c pass`` (the interpreter's own
start-up, the floor). Target (issue 17): excess ≤ 0.3 s. The error path is ``acq analyze missing.h5`` (exit 2,
one line). On a shared machine the medians move with its load: the excess is the figure to compare.
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import time

TARGET_EXCESS_S = 0.3
COMMANDS = {
    "python -c pass": [sys.executable, "-c", "pass"],
    "acq --help": [sys.executable, "-m", "acq", "--help"],
    "acq analyze missing.h5": [sys.executable, "-m", "acq", "analyze", "missing.h5"],
    "acq analyze --help": [sys.executable, "-m", "acq", "analyze", "--help"],
}


def wall_s(cmd: list[str]) -> float:
    """Wall time of one run of ``cmd``, s."""
    t0 = time.perf_counter()
    subprocess.run(cmd, capture_output=True, check=False)
    return time.perf_counter() - t0


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=7)
    args = parser.parse_args()
    times: dict[str, list[float]] = {name: [] for name in COMMANDS}
    for _ in range(args.runs):  # interleaved, so a change of the machine's load hits every command alike
        for name, cmd in COMMANDS.items():
            times[name].append(wall_s(cmd))
    floor = statistics.median(times["python -c pass"])
    print(f"median of {args.runs} runs, load average {os.getloadavg()[0]:.2f}")
    print(f"{'command':28s} {'median [s]':>10s} {'excess [s]':>10s}  target excess <= {TARGET_EXCESS_S} s")
    for name, values in times.items():
        median = statistics.median(values)
        print(f"{name:28s} {median:10.3f} {median - floor:10.3f}")


if __name__ == "__main__":
    main()
