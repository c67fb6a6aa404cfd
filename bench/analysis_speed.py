"""Time and peak memory of `acq analyze` on long simulated sessions (prints figures; not a test).

    python bench/analysis_speed.py [--sizes 60,600] [--repeat 3] [--sessions DIR] [--profile]

For each size a session is recorded by the simulated bench (``acq record --fast --no-analyze``:
25.6 kS/s current on one phase, 1 kHz encoder, the 0.2 s triangle all along), then a fresh Python
process per size loads it and runs the default analysis (``acq.analyze``: clock alignment, encoder
torque, FRF, fit, verdict — no PNG) and reports:

* load: reading the HDF5 session into arrays, s (wall);
* analyse: :func:`analysis.pipeline.analyze`, s — wall (best of ``--repeat``) and CPU;
* peak RSS: the child's ``ru_maxrss`` (whole process: interpreter, libraries, session, analysis), MB;
* analysis peak: ``tracemalloc`` peak of the analysis alone (NumPy reports its buffers), MB, run
  in a separate child because tracing slows it down.

Targets (design §9): ≤ 3 s for 60 s on 2 cores, ≤ 1 GB for 10 min. ``--profile`` adds the top
functions (cProfile, cumulative and own time) of analysing the first size.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from rich.console import Console
from rich.progress import Progress, SpinnerColumn, TextColumn, TimeElapsedColumn
from rich.table import Table

ROOT = Path(__file__).resolve().parent.parent
TARGET_TIME_60S = 3.0
TARGET_MEMORY_MB = 1024.0


def record(seconds: float, out: Path) -> Path:
    """Record a simulated session of ``seconds`` into ``out`` (reused if one of that length is there)."""
    folder = out / f"{seconds:g}s"
    found = sorted(folder.glob("*.h5"))
    if found:
        return found[-1]
    folder.mkdir(parents=True, exist_ok=True)
    acq = Path(sys.executable).with_name("acq")
    cmd = [str(acq)] if acq.exists() else [sys.executable, "-m", "acq"]
    proc = subprocess.run([*cmd, "record", "--profile", "triangle_0.2s", "--duration", f"{seconds:g}", "--fast",
                           "--no-analyze", "--out", str(folder)], cwd=ROOT, capture_output=True, text=True)
    if proc.returncode != 0:
        raise SystemExit(f"acq record failed ({proc.returncode}): {proc.stderr.strip()}")
    return sorted(folder.glob("*.h5"))[-1]


def child(path: str, repeat: int, trace: bool, profile: bool) -> None:
    """Run in a fresh process: load and analyse ``path``; print one JSON line of figures."""
    import tracemalloc

    from acq.analyze import request_for, recording_from_session
    from acq.session import load
    from analysis.pipeline import analyze

    rss_start = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    t0 = time.perf_counter()
    session = load(path)
    rec = recording_from_session(session)
    options = request_for(session)
    load_s = time.perf_counter() - t0
    samples = sum(a.size for a in rec.current_a.values()) + rec.position_counts.size
    out: dict = {"load_s": load_s, "samples": samples, "rss_after_load_mb": resource.getrusage(
        resource.RUSAGE_SELF).ru_maxrss / 1024, "rss_start_mb": rss_start}
    if trace:
        tracemalloc.start()
        analyze(rec, options)
        out["trace_peak_mb"] = tracemalloc.get_traced_memory()[1] / 2**20
        tracemalloc.stop()
    elif profile:
        import cProfile
        import io
        import pstats

        prof = cProfile.Profile()
        prof.enable()
        analyze(rec, options)
        prof.disable()
        buf = io.StringIO()
        stats = pstats.Stats(prof, stream=buf)
        stats.sort_stats("cumulative").print_stats(r"analysis/", 25)
        stats.sort_stats("tottime").print_stats(15)
        out["profile"] = buf.getvalue()
    else:
        walls, cpus = [], []
        for _ in range(repeat):
            w0, c0 = time.perf_counter(), time.process_time()
            res = analyze(rec, options)
            walls.append(time.perf_counter() - w0)
            cpus.append(time.process_time() - c0)
        out.update(analyze_wall_s=min(walls), analyze_walls_s=walls, analyze_cpu_s=min(cpus),
                   verdict=res.quality.verdict, K=res.fit.values.K_Nm_per_rad,
                   peak_rss_mb=resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024)
    print(json.dumps(out))


def run_child(path: Path, *flags: str) -> dict:
    proc = subprocess.run([sys.executable, __file__, "--child", str(path), *flags], check=True, cwd=ROOT,
                          capture_output=True, text=True)
    return json.loads(proc.stdout.strip().splitlines()[-1])


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", default="60,600", help="session lengths, s (default 60,600)")
    parser.add_argument("--repeat", type=int, default=3, help="analyses per size; the best wall time is shown")
    parser.add_argument("--sessions", type=Path, default=None,
                        help="folder to keep (and reuse) the recorded sessions (default: a temporary one)")
    parser.add_argument("--profile", action="store_true", help="print a cProfile of the first size")
    parser.add_argument("--child", help=argparse.SUPPRESS)
    parser.add_argument("--trace", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        child(args.child, args.repeat, args.trace, args.profile)
        return 0

    sizes = [float(s) for s in args.sizes.split(",")]
    console = Console() if sys.stdout.isatty() else Console(width=160)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        where = args.sessions or Path(tmp)
        with Progress(SpinnerColumn(), TextColumn("{task.description}"), TimeElapsedColumn(),
                      console=console) as progress:
            for seconds in sizes:
                task = progress.add_task(f"{seconds:g} s: recording with the simulated bench (--fast)")
                t0 = time.perf_counter()
                path = record(seconds, where)
                rec_s = time.perf_counter() - t0
                progress.update(task, description=f"{seconds:g} s: analysing ({args.repeat}×, fresh process)")
                timing = run_child(path, "--repeat", str(args.repeat if seconds <= 120 else 1))
                progress.update(task, description=f"{seconds:g} s: tracemalloc peak of the analysis")
                traced = run_child(path, "--trace")
                progress.update(task, description=f"{seconds:g} s: done", completed=1, total=1)
                rows.append((seconds, path, rec_s, timing, traced))
            if args.profile:
                progress.add_task(f"profiling {sizes[0]:g} s")
                prof = run_child(rows[0][1], "--profile")["profile"]

    table = Table(title=f"analysis speed and memory — simulated sessions, 25.6 kS/s current + 1 kHz encoder "
                        f"({os.cpu_count()} cores)")
    for col in ("session", "samples", "load, s", "analyse wall, s", "analyse CPU, s", "peak RSS, MB",
                "analysis peak\n(tracemalloc), MB", "verdict", "target"):
        table.add_column(col, justify="left" if col in ("session", "verdict", "target") else "right")
    ok = True
    for seconds, _, _, t, tr in rows:
        target = ""
        if seconds == 60:
            met = t["analyze_wall_s"] <= TARGET_TIME_60S
            ok &= met
            target = f"≤ {TARGET_TIME_60S:g} s: " + ("[green]met[/green]" if met else "[red]MISSED[/red]")
        if seconds == 600:
            met = t["peak_rss_mb"] <= TARGET_MEMORY_MB
            ok &= met
            target = f"≤ 1 GB: " + ("[green]met[/green]" if met else "[red]MISSED[/red]")
        table.add_row(f"{seconds:g} s", f"{t['samples']:,}", f"{t['load_s']:.2f}",
                      f"{t['analyze_wall_s']:.2f}" + (f" (of {len(t['analyze_walls_s'])})"
                                                      if len(t["analyze_walls_s"]) > 1 else ""),
                      f"{t['analyze_cpu_s']:.2f}", f"{t['peak_rss_mb']:.0f}", f"{tr['trace_peak_mb']:.0f}",
                      t["verdict"], target)
    console.print(table)
    load1 = os.getloadavg()[0]
    console.print(f"load average during the run: {load1:.1f} on {os.cpu_count()} cores "
                  f"(wall times grow when other work shares the machine; CPU time does not)")
    console.print("peak RSS includes the interpreter and libraries "
                  f"(≈ {rows[0][3]['rss_start_mb']:.0f} MB after imports) and the loaded session")
    if args.profile:
        console.print(prof, markup=False, highlight=False)
    return 0 if ok else 1


if __name__ == "__main__":
    raise SystemExit(main())
