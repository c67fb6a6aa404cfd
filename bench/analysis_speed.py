"""CPU, wall time and peak memory of acq's analysis next to the floor of the same work (prints figures; not a test).

    python bench/analysis_speed.py [--sizes 10,60,600] [--repeat 3] [--threads 1,default] [--sessions DIR] [--profile]

For each size a session is recorded by the simulated bench (``acq record --fast --no-analyze``: 25.6 kS/s current
on one phase, 1 kHz encoder, the 0.2 s triangle all along). Then, for each BLAS thread setting, fresh Python
processes measure:

* acq: reading the session (:func:`acq.recording.reader.load`) and :func:`analysis.pipeline.analyze` with the options
  ``acq analyze`` uses (clock alignment, encoder torque, FRF, fit, verdict — no PNG): CPU and wall time of the
  analysis (best of ``--repeat``), and the process's peak RSS (``ru_maxrss``: interpreter, libraries, the loaded
  session and the analysis);
* the floor: what any identifier of the same session has to do at least — read both streams with plain h5py,
  ``scipy.signal.resample_poly`` of the current to the encoder rate, one ``scipy.signal.csd`` at the current's
  rate with the same 0.5 s segments, and a 5-parameter Levenberg–Marquardt fit (``scipy.optimize.least_squares``)
  of the two-mass amplitude on 200 lines — its CPU time, and acq's CPU over it.

Thread settings: ``1`` sets ``OPENBLAS_NUM_THREADS``/``OMP_NUM_THREADS``/``MKL_NUM_THREADS`` to 1 in the child (what
the ``acq`` command and the batch/monitor workers do, ``acq/entry.py``); ``default`` removes them (OpenBLAS then
starts one thread per core). Either way the child sets glibc's allocator as the ``acq analyze`` process does
(``acq.entry.keep_freed_memory``: freed memory kept for the next arrays instead of page-faulted back in; without it a
60 s session's analysis spent ~0.05 s of its CPU in page faults), unless ``--default-allocator``. Targets (issue 17): 60 s ≤ 0.4 s CPU; 10 min ≤ 4 s
CPU and ≤ 600 MB peak RSS; cost linear in duration (the CPU per minute of session is printed). ``--profile`` adds a
cProfile of the first size.

Measured (one BLAS thread, 2 cores shared with other work; CPU is less sensitive to load than wall time, not immune):
main at 1ef86d5 60 s 0.47 s and 10 min 4.10 s CPU at load ≈ 1 (0.48 s and 4.27 s at load ≈ 8); with the sine/cosine
table (analysis/trig.py), the BLAS decimating FIR (analysis/resample.fir_decimate), the diagnosis only for a
poor/failed verdict and the allocator setting 0.36 s and 3.57 s at load ≈ 8 (without the allocator setting 60 s
0.40 s against 0.37–0.38 s, the same load; again at load 4: 0.39–0.40 s with --default-allocator, 0.36–0.37 s without).
Session 15 (main at d9a91e0 against the triangular solves on a unit-diagonal factor, the quantisation-lock sums from 6
FFTs instead of 12, the Hann window and the FIR filters designed once per length, the delete-a-move jackknife in one
stacked solve; each child alternately, the same session files): 60 s 0.455, 0.456, 0.464, 0.465 s against 0.415,
0.422, 0.424, 0.438 s at load 14–19 and 0.477, 0.484, 0.477 s against 0.446, 0.443, 0.436 s at load 10 (``--child``
best of 5); 10 min 4.20, 4.05 s against 3.83, 3.71 s at load 19 (one run each), peak RSS 513–515 MB both.
Session 16 (main at 7ed0994 against: the spline fit's triangular solves in place in its projections' array — no
12 MB Z zeroed, gathered and scattered back per 20 s chunk —, the slow offset's values written beside the extra
columns instead of joined by a copy, fir_decimate reading the record without a padded copy, the model's speed in
estimator_check by scipy.fft, whose plan of the 59 909 = 139·431-sample length serves the inverse too; every change
bit-identical: ``acq analyze --json`` of a 10 s and a 60 s session equal but for analysis_fingerprint). Two long-lived
processes, main's tree and this one, alternating one analysis of the same 60 s session at a time, 40 each, one BLAS
thread: 60 s 0.599 against 0.576 s CPU (medians; paired difference 22.5 ms, range 4.5…36.9 ms) at load 0.6–1.2,
0.588 against 0.566 s (24 ms, 6…36 ms) at load 2, 0.648 against 0.623 s (28 ms, −13…65 ms) at load 7–12; 10 s 0.175
against 0.172 s (30 each, load 1–2). This script, main and this tree alternately, 3 each: 60 s 0.60, 0.60, 0.60 against
0.58, 0.58, 0.57 s at load 0.4–0.6; 10 min (one run each, 2 each) 5.69, 5.81 against 5.46, 5.32 s at load 2–4, peak
RSS 516 MB against 511–516 MB. This machine reads main's 60 s at 0.60 s at load 0.5 (0.41 s in the notes above):
compare trees interleaved, not against those figures. Of the 0.57 s, the spline fit is ~0.12 s (its BLAS
products and LAPACK's sequential banded solves), the rest of the encoder torque ~0.11 s, the clock stages ~0.12 s,
the anti-alias resampling with the alias terms ~0.08 s, FRF, fit and verdict ~0.1 s; what is left above the floor is
arithmetic whose order fixes the results' bits (a different block size, summation order or FFT length changes the
last digits of K).
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
if str(ROOT) not in sys.path:  # this checkout's acq and analysis, also in the children
    sys.path.insert(0, str(ROOT))
TARGET_CPU_60S = 0.4
TARGET_CPU_600S = 4.0
TARGET_RSS_600S_MB = 600.0
_BLAS_VARS = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")


def record(seconds: float, out: Path) -> Path:
    """Record a simulated session of ``seconds`` into ``out`` (reused if one of that length is there)."""
    folder = out / f"{seconds:g}s"
    found = sorted(folder.glob("*.h5"))
    if found:
        return found[-1]
    folder.mkdir(parents=True, exist_ok=True)
    proc = subprocess.run([sys.executable, "-m", "acq", "record", "--profile", "triangle_0.2s", "--duration",
                           f"{seconds:g}", "--fast", "--no-analyze", "--out", str(folder)], cwd=ROOT,
                          capture_output=True, text=True)
    if proc.returncode != 0:
        raise SystemExit(f"acq record failed ({proc.returncode}): {proc.stderr.strip()}")
    return sorted(folder.glob("*.h5"))[-1]


def _peak_rss_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def child_acq(path: str, repeat: int, profile: bool) -> dict:
    """In a fresh process: load and analyse ``path`` as ``acq analyze`` does; figures as a dict."""
    from acq.offline.analyze import request_for, recording_from_session
    from acq.recording.reader import load
    from analysis.pipeline import analyze

    rss_start = _peak_rss_mb()
    w0, c0 = time.perf_counter(), time.process_time()
    session = load(path)
    rec = recording_from_session(session)
    options = request_for(session)
    out: dict = {"load_wall_s": time.perf_counter() - w0, "load_cpu_s": time.process_time() - c0,
                 "rss_start_mb": rss_start}
    if profile:
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
        return {"profile": buf.getvalue()}
    walls, cpus = [], []
    for _ in range(repeat):
        w0, c0 = time.perf_counter(), time.process_time()
        res = analyze(rec, options)
        walls.append(time.perf_counter() - w0)
        cpus.append(time.process_time() - c0)
    v = res.fit.values
    out.update(wall_s=min(walls), cpu_s=min(cpus), first_cpu_s=cpus[0], verdict=res.quality.verdict,
               peak_rss_mb=_peak_rss_mb(),
               values=[v.K_Nm_per_rad, v.Jm_kgm2, v.Jl_kgm2, v.C_Nms_per_rad])
    return out


def child_floor(path: str, repeat: int) -> dict:
    """In a fresh process: the floor of the same session's identification; CPU and wall time per step."""
    import h5py
    import numpy as np
    from scipy.optimize import least_squares
    from scipy.signal import csd, resample_poly

    def two_mass_db(p: np.ndarray, w: np.ndarray) -> np.ndarray:
        k, jm, jl, c, b = np.exp(p)
        s = 1j * w
        h = (jl * s**2 + c * s + k) / (s * (jm * jl * s**2 + (jm + jl) * c * s + (jm + jl) * k) + b)
        return np.log(np.abs(h))

    steps: dict[str, list[tuple[float, float]]] = {"read": [], "resample": [], "csd": [], "fit": []}

    def timed(name: str, f, *a, **kw):  # type: ignore[no-untyped-def]
        w0, c0 = time.perf_counter(), time.process_time()
        r = f(*a, **kw)
        steps[name].append((time.process_time() - c0, time.perf_counter() - w0))
        return r

    def read() -> tuple[np.ndarray, np.ndarray, float, float]:
        with h5py.File(path, "r") as f:
            return (f["current/i_a_A"][()], f["encoder/position_counts"][()], float(f["current"].attrs["rate_hz"]),
                    float(f["encoder"].attrs["period_s"]))

    w = 2 * np.pi * np.linspace(10.0, 400.0, 200)
    truth = np.log([891.0, 0.003027, 0.00748, 0.1, 1e-3])
    target = two_mass_db(truth, w)
    for _ in range(repeat):
        current, _counts, rate_hz, period_s = timed("read", read)
        timed("resample", resample_poly, current, 1, int(round(rate_hz * period_s)))
        timed("csd", csd, current, current, fs=rate_hz, nperseg=int(0.5 * rate_hz))
        timed("fit", least_squares, lambda p: two_mass_db(p, w) - target, truth + 0.2, method="lm")
        del current
    best = {name: min(v) for name, v in steps.items()}
    return {"steps_cpu_s": {k: v[0] for k, v in best.items()}, "cpu_s": sum(v[0] for v in best.values()),
            "wall_s": sum(v[1] for v in best.values())}


def run_child(path: Path, threads: str, *flags: str) -> dict:
    env = dict(os.environ)
    for var in _BLAS_VARS:
        env.pop(var, None)
        if threads != "default":
            env[var] = threads
    proc = subprocess.run([sys.executable, __file__, "--child", str(path), *flags], check=True, cwd=ROOT, env=env,
                          capture_output=True, text=True)
    return json.loads(proc.stdout.strip().splitlines()[-1])


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", default="10,60,600", help="session lengths, s (default 10,60,600)")
    parser.add_argument("--repeat", type=int, default=3,
                        help="analyses per size up to 2 min (best shown); longer sessions once")
    parser.add_argument("--threads", default="1,default",
                        help="BLAS thread settings to measure: a count or 'default' (default 1,default)")
    parser.add_argument("--sessions", type=Path, default=None,
                        help="folder to keep (and reuse) the recorded sessions (default: a temporary one)")
    parser.add_argument("--profile", action="store_true", help="print a cProfile of the first size (1 thread)")
    parser.add_argument("--default-allocator", action="store_true",
                        help="glibc's malloc defaults in the children, not acq analyze's (acq.entry.keep_freed_memory)")
    parser.add_argument("--child", help=argparse.SUPPRESS)
    parser.add_argument("--floor", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        if not args.default_allocator:
            from acq.entry import keep_freed_memory

            keep_freed_memory()  # as the acq analyze process does
        out = child_floor(args.child, args.repeat) if args.floor else child_acq(args.child, args.repeat, args.profile)
        print(json.dumps(out))
        return 0

    sizes = [float(s) for s in args.sizes.split(",")]
    settings = args.threads.split(",")
    console = Console() if sys.stdout.isatty() else Console(width=170)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        where = args.sessions or Path(tmp)
        with Progress(SpinnerColumn(), TextColumn("{task.description}"), TimeElapsedColumn(),
                      console=console) as progress:
            for seconds in sizes:
                task = progress.add_task(f"{seconds:g} s: recording with the simulated bench (--fast)")
                path = record(seconds, where)
                repeat = str(args.repeat if seconds <= 120 else 1)
                for threads in settings:
                    progress.update(task, description=f"{seconds:g} s, BLAS threads {threads}: acq, then the floor")
                    allocator = ("--default-allocator",) if args.default_allocator else ()
                    acq = run_child(path, threads, "--repeat", repeat, *allocator)
                    floor = run_child(path, threads, "--repeat", repeat, "--floor", *allocator)
                    rows.append((seconds, threads, acq, floor))
                progress.update(task, description=f"{seconds:g} s: done", completed=1, total=1)
            if args.profile:
                progress.add_task(f"profiling {sizes[0]:g} s")
                prof = run_child(record(sizes[0], where), "1", "--profile")["profile"]

    table = Table(title="acq analyze vs the floor — simulated sessions, 25.6 kS/s current + 1 kHz encoder, "
                        f"{os.cpu_count()} cores")
    for col in ("session", "BLAS\nthreads", "acq CPU, s", "first\nrun CPU, s", "acq wall, s", "CPU per\nmin, s",
                "floor CPU, s",
                "acq / floor\n(CPU)", "floor: read · resample\n· CSD · fit, s", "load, s", "peak RSS, MB",
                "K, N·m/rad", "verdict", "target"):
        table.add_column(col, justify="left" if col in ("session", "verdict", "target") else "right")
    ok = True
    for seconds, threads, a, f in rows:
        checks = []
        if seconds == 60:
            checks.append((a["cpu_s"] <= TARGET_CPU_60S, f"CPU ≤ {TARGET_CPU_60S:g} s"))
        if seconds == 600:
            checks += [(a["cpu_s"] <= TARGET_CPU_600S, f"CPU ≤ {TARGET_CPU_600S:g} s"),
                       (a["peak_rss_mb"] <= TARGET_RSS_600S_MB, f"RSS ≤ {TARGET_RSS_600S_MB:g} MB")]
        ok &= all(met for met, _ in checks)
        target = "; ".join(f"{what}: " + ("[green]met[/green]" if met else "[red]MISSED[/red]") for met, what in checks)
        st = f["steps_cpu_s"]
        table.add_row(f"{seconds:g} s", threads, f"{a['cpu_s']:.2f}", f"{a['first_cpu_s']:.2f}", f"{a['wall_s']:.2f}",
                      f"{60.0 * a['cpu_s'] / seconds:.2f}", f"{f['cpu_s']:.3f}", f"{a['cpu_s'] / f['cpu_s']:.1f}×",
                      " · ".join(f"{st[k]:.3f}" for k in ("read", "resample", "csd", "fit")),
                      f"{a['load_wall_s']:.2f}", f"{a['peak_rss_mb']:.0f}", f"{a['values'][0]:.2f}", a["verdict"],
                      target)
    console.print(table)
    console.print(f"load average after the run: {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores (wall times grow "
                  "when other work shares the machine; CPU time much less). Times: best of "
                  f"{args.repeat} up to 2 min, else one run; first run: the process's first analysis, what one "
                  "`acq analyze` pays (first calls, caches, fresh memory). Peak RSS: the whole process (≈ "
                  f"{rows[0][2]['rss_start_mb']:.0f} MB after imports) with the session loaded.")
    if args.profile:
        console.print(prof, markup=False, highlight=False)
    return 0 if ok else 1


if __name__ == "__main__":
    raise SystemExit(main())
