"""What the report PNG costs the caller of `acq analyze --json`, and what the picture itself costs (prints figures).

    python bench/report_speed.py [--runs 7] [--session S.h5]

Each run starts ``python -m acq analyze S --json …`` as a script would (``subprocess.run`` reading stdout and stderr
to their end) and times it from start to exit (wall, and the CPU of that process), for ``--no-report`` (no picture), the default (the picture drawn by a
background process after the JSON is printed) and ``--wait-report`` (drawn before exit, what the default did
before). For the default it also times until the PNG is on disk, and waits for it before the next run (so the runs
do not overlap). The three kinds run interleaved, so a change of the machine's load hits each alike; medians.
Target (issue 17, item 3): the default's wall time equals ``--no-report``'s (the result does not wait for the
picture), or the picture costs ≤ 0.2 s.

The picture's own cost is measured in one process: CPU of importing the plotting stack (pyqtgraph, Qt) and of
drawing the report of S (first and second drawing), best of ``--runs``/2 processes. Without ``--session`` a 10 s
``--fast`` session of the simulated bench is recorded into a temp folder.
"""

from __future__ import annotations

import argparse
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

KINDS = {"--no-report": ["--no-report"], "default (background picture)": [], "--wait-report": ["--wait-report"]}
PNG_TIMEOUT_S = 120.0

PICTURE_COST = """
import sys, time
from acq.offline.analyze import analyze_session
from acq.ui.report_png import _title
done = analyze_session(sys.argv[1], write=False)
t0 = time.process_time()
from acq.ui.report_view import render_report_png
t1 = time.process_time()
render_report_png(done.result.figures, sys.argv[2], values=done.json_dict, title=_title(done))
t2 = time.process_time()
render_report_png(done.result.figures, sys.argv[2], values=done.json_dict, title=_title(done))
t3 = time.process_time()
print(t1 - t0, t2 - t1, t3 - t2)
"""


def record_session(folder: Path) -> Path:
    subprocess.run([sys.executable, "-m", "acq", "record", "--profile", "triangle_0.2s", "--duration", "10", "--fast",
                    "--no-analyze", "--out", str(folder)], check=True, capture_output=True)
    (path,) = folder.glob("*.h5")
    return path


def _children_cpu_s() -> float:
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def analyze_wall_s(session: Path, options: list[str], png: Path) -> tuple[float, float, float | None]:
    """Wall time of one ``acq analyze --json`` as its caller sees it and the CPU of that process (not of a
    background drawer it leaves), s; and, when it leaves the picture to a background process, the time from start
    until the PNG is on disk, s."""
    png.unlink(missing_ok=True)
    cpu0, t0 = _children_cpu_s(), time.perf_counter()
    subprocess.run([sys.executable, "-m", "acq", "analyze", str(session), "--json", *options], capture_output=True,
                   check=True)
    wall, cpu = time.perf_counter() - t0, _children_cpu_s() - cpu0
    if options:
        return wall, cpu, None
    while not png.exists():
        if time.perf_counter() - t0 > PNG_TIMEOUT_S:
            raise SystemExit(f"{png}: not drawn within {PNG_TIMEOUT_S:g} s (see {png.with_suffix('.log')})")
        time.sleep(0.005)
    return wall, cpu, time.perf_counter() - t0


def picture_cost_s(session: Path, png: Path, runs: int) -> tuple[float, float, float]:
    """CPU of importing the plotting stack, of the first and of a second drawing, s (best of ``runs`` processes)."""
    costs = [tuple(float(v) for v in subprocess.run([sys.executable, "-c", PICTURE_COST, str(session), str(png)],
                                                    capture_output=True, check=True, text=True).stdout.split())
             for _ in range(runs)]
    return min(c[0] for c in costs), min(c[1] for c in costs), min(c[2] for c in costs)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=7)
    parser.add_argument("--session", type=Path, default=None, help="a session file (default: record a 10 s one)")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        session = args.session or record_session(Path(tmp))
        png = session.with_name(session.stem + ".report.png")
        walls: dict[str, list[float]] = {name: [] for name in KINDS}
        cpus: dict[str, list[float]] = {name: [] for name in KINDS}
        until_png: list[float] = []
        for _ in range(args.runs):
            for name, options in KINDS.items():
                wall, cpu, png_s = analyze_wall_s(session, options, png)
                walls[name].append(wall)
                cpus[name].append(cpu)
                if png_s is not None:
                    until_png.append(png_s)
        import_s, first_s, second_s = picture_cost_s(session, Path(tmp) / "cost.png", max(1, args.runs // 2))
    floor, cpu_floor = statistics.median(walls["--no-report"]), statistics.median(cpus["--no-report"])
    print(f"acq analyze {session.name} --json: the caller's process, median of {args.runs} runs, "
          f"load average {os.getloadavg()[0]:.2f}")
    print(f"{'options':32s} {'wall [s]':>9s} {'excess':>7s} {'CPU [s]':>9s} {'excess':>7s}")
    for name in KINDS:
        wall, cpu = statistics.median(walls[name]), statistics.median(cpus[name])
        print(f"{name:32s} {wall:9.3f} {wall - floor:+7.3f} {cpu:9.3f} {cpu - cpu_floor:+7.3f}")
    print(f"{'default: PNG on disk after':32s} {statistics.median(until_png):10.3f}")
    print(f"the picture's own CPU (best of {max(1, args.runs // 2)}): import pyqtgraph + Qt {import_s:.3f} s, "
          f"first drawing {first_s:.3f} s, a second drawing {second_s:.3f} s")


if __name__ == "__main__":
    main()
