"""Condition monitoring over simulated shifts: flat memory, bounded disk, alarms on wear and only on wear.

    nice -n 10 python bench/monitor.py [--hours 4] [--every 900] [--seeds 0,1,2] [--decay 3] [--decay-hours 6]
                                       [--wear-every 600] [--png trend.png] [--budget-mb 12] [--no-wear] [--no-kill]

All runs use ``configs/benches/sim_robot.toml`` in ``--fast`` (machine time simulated), 10 s windows,
a baseline of 5 good windows, the default alarm rules (−10 % threshold, EWMA λ = 0.2 at 3σ), ``--keep 3``:

* **constant K** — one monitor of ``--hours`` per seed: windows, excited windows, the share of the program's time
  that excites the joint (segment selection, mean over the windows), alarms (any alarm is a
  false alarm), K scatter against the truth, the RSS of the monitor (and with its workers) after the first
  simulated hour and at the end, and the disk used;
* **wear** — K falls ``--decay`` % of its new value per simulated hour over ``--decay-hours``: the window
  at which the true K first lies 10 % below the true baseline, and the first alarming window (either
  rule, and the threshold rule alone), in windows after that crossing (negative: before it);
* **disk budget** — 1 simulated hour under ``--budget-mb`` with ``--keep 10`` (the budget binds): the folder's
  peak size, sampled every 20 ms from another thread, and the windows not captured;
* **kill -9** — ``acq monitor`` in a subprocess is killed with SIGKILL after a few windows and restarted
  in the same folder: the catalogue rows and the baseline before and after, the windows marked
  interrupted.
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import sqlite3
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

import psutil
from rich.console import Console
from rich.table import Table

from acq.config import load_bench
from acq.monitoring.catalogue import Catalogue
from acq.monitoring.monitor import WINDOW_TAG, Monitor, MonitorSettings, MonitorStatus
from acq.monitoring.retention import folder_bytes
from acq.monitoring.trend import ELAPSED_TAG, Trend, TrendPoint, compute_trend
from acq.ui.trend_plot import render_trend_png
from acq.recording.reader import load
from acq.ui.values import format_value

ROBOT = Path(__file__).resolve().parents[1] / "configs" / "benches" / "sim_robot.toml"
WINDOW_S, BASELINE, KEEP = 10.0, 5, 3


def rss_mb() -> tuple[float, float]:
    """Resident memory of this process, and of it with its children (the analysis workers), MB."""
    me = psutil.Process()
    total = 0
    for p in me.children(recursive=True):
        try:
            total += p.memory_info().rss
        except psutil.Error:
            pass
    mine = me.memory_info().rss
    return mine / 1e6, (mine + total) / 1e6


def trend_of(folder: Path) -> Trend:
    with Catalogue(folder / "catalogue.sqlite") as cat:
        entries = [e for e in cat.entries("joint1") if WINDOW_TAG in e.tags]
    return compute_trend("joint1", entries, baseline_sessions=BASELINE)


def run_monitor(folder: Path, hours: float, every_s: float, **sim: float) -> tuple[dict[str, Any], MonitorStatus]:
    """One in-process --fast monitor; RSS after the first simulated hour and at the end."""
    bench = load_bench(ROBOT)
    bench = bench.model_copy(update={"sim": bench.sim.model_copy(update=sim)})
    rss: dict[str, Any] = {}
    seen = [-1]

    def watch(st: MonitorStatus) -> None:  # sampled as each window is catalogued (the workers idle then)
        if st.analysed == seen[0]:
            return
        seen[0] = st.analysed
        if "first hour" not in rss and st.machine_time_s >= 3600.0:
            rss["first hour"] = rss_mb()
        rss["end"] = rss_mb()

    settings = MonitorSettings(bench=bench, out_dir=folder, window_s=WINDOW_S, every_s=every_s, for_s=hours * 3600,
                               keep=KEEP, fast=True, baseline_windows=BASELINE)
    monitor = Monitor(settings, on_status=watch)
    start = time.perf_counter()
    monitor.run()
    rss["seconds"] = time.perf_counter() - start
    return rss, monitor.status


def constant_k(hours: float, every_s: float, seeds: list[int], tmp: Path, out: Console) -> None:
    table = Table(title=f"constant K, {hours:g} simulated h per seed, one 10 s window per {every_s:g} s")
    for c in ("seed", "windows", "excited", "not excited", "excited share of the program", "false alarms", "K − truth % (mean ± sd)", "max |ΔK| %",
              "RSS MB 1st h → end: monitor · with workers", "disk MB", "wall s"):
        table.add_column(c, justify="right")
    for seed in seeds:
        folder = tmp / f"constant_{seed}"
        rss, st = run_monitor(folder, hours, every_s, seed=seed)
        trend = trend_of(folder)
        judged = [p for p in trend.points if p.state in ("before baseline", "baseline", "ok", "alarm")]
        err = [100 * (p.entry.K_Nm_per_rad / p.entry.truth_K_Nm_per_rad - 1) for p in judged]  # type: ignore[operator]
        alarms = sum(p.state == "alarm" for p in trend.points)
        rss_text = " · ".join(f"{a:.0f} → {b:.0f} ({100 * (b / a - 1):+.1f} %)"
                              for a, b in zip(rss["first hour"], rss["end"])) if "first hour" in rss else "—"
        table.add_row(str(seed), str(st.captured), str(st.excited), str(st.not_excited),
                      format_value(None if st.program_excited_fraction is None else 100 * st.program_excited_fraction,
                                   ".0f") + " %", str(alarms),
                      f"{statistics.fmean(err):+.2f} ± {statistics.pstdev(err):.2f}",
                      f"{max(abs(p.change_pct or 0) for p in judged):.1f}", rss_text, f"{st.disk_bytes / 1e6:.0f}",
                      f"{rss['seconds']:.0f}")
    out.print(table)


def wear(decay_pct_h: float, hours: float, every_s: float, tmp: Path, out: Console, png: Path | None) -> None:
    folder = tmp / "wear"
    rss, st = run_monitor(folder, hours, every_s, K_decay_pct_per_hour=decay_pct_h)
    trend = trend_of(folder)
    if png is not None:
        render_trend_png(trend, png)
        out.print(f"trend of the wear shift: {png}")
    k0 = load_bench(ROBOT).sim.K_Nm_per_rad  # type: ignore[union-attr]

    def true_k(p: TrendPoint) -> float:  # the wear is known at every window, analysed or not
        return k0 * (1 - decay_pct_h * float(p.entry.tags[ELAPSED_TAG]) / 3600 / 100)

    base = [p for p in trend.points if p.state == "baseline"]
    if not base:
        out.print(f"wear: no baseline after {st.captured} windows ({st.excited} excited) — run longer")
        return
    true_base = statistics.fmean(true_k(p) for p in base)
    window = {p.entry.session_key: int(p.entry.tags[WINDOW_TAG]) for p in trend.points}
    crossing = next((window[p.entry.session_key] for p in trend.points
                     if true_k(p) < (1 - trend.threshold_pct / 100) * true_base), None)
    if crossing is None:
        out.print(f"wear: the true K never crossed −{trend.threshold_pct:g} % in {st.captured} windows — run longer")
        return
    first_any = next((window[p.entry.session_key] for p in trend.points if p.state == "alarm"), None)
    first_thr = next((window[p.entry.session_key] for p in trend.points if p.threshold_alarm), None)
    table = Table(title=f"wear: K −{decay_pct_h:g} %/h over {hours:g} simulated h, one 10 s window per {every_s:g} s")
    for c in ("windows", "excited", "true K crosses −10 % at window", "first alarm (any rule)",
              "first threshold alarm", "wall s"):
        table.add_column(c, justify="right")

    def rel(w: int | None) -> str:
        return "none" if w is None else f"{w} ({w - crossing:+d} windows)"

    table.add_row(str(st.captured), str(st.excited), str(crossing), rel(first_any), rel(first_thr),
                  f"{rss['seconds']:.0f}")
    out.print(table)


def capturing(folder: Path) -> bool:
    """True while the newest window's file is still being recorded."""
    files = sorted(folder.glob("*.h5"), key=lambda p: p.stat().st_mtime if p.exists() else 0)
    try:
        return bool(files) and load(files[-1]).status == "recording"
    except Exception:  # noqa: BLE001 - a file just created may not be readable yet
        return False


def disk_budget(budget_mb: float, tmp: Path, out: Console) -> None:
    """1 simulated hour, a window per 300 s, --keep 10 under a budget that only ~3 windows fit: the peak size
    of the folder, sampled every 20 ms from another thread (also inside captures)."""
    folder = tmp / "budget"
    bench = load_bench(ROBOT)
    settings = MonitorSettings(bench=bench, out_dir=folder, window_s=WINDOW_S, every_s=300.0, for_s=3600.0, keep=10,
                               max_disk_bytes=int(budget_mb * 1e6), fast=True, baseline_windows=2)
    peak, done = [0], threading.Event()

    def sample() -> None:
        while not done.is_set():
            try:
                peak[0] = max(peak[0], folder_bytes(folder))
            except OSError:  # a file deleted while listed
                pass
            time.sleep(0.02)

    sampler = threading.Thread(target=sample, daemon=True)
    sampler.start()
    monitor = Monitor(settings)
    monitor.run()
    done.set()
    sampler.join()
    st = monitor.status
    table = Table(title=f"disk budget {budget_mb:g} MB, --keep 10, 1 simulated h, one 10 s window per 300 s")
    for c in ("windows captured", "not captured (budget)", "peak folder MB", "raw windows left", "catalogue rows"):
        table.add_column(c, justify="right")
    with Catalogue(folder / "catalogue.sqlite") as cat:
        rows = len(cat.entries("joint1"))
    table.add_row(str(st.captured), str(st.skipped), f"{peak[0] / 1e6:.1f}", str(len(list(folder.glob("*.h5")))),
                  str(rows))
    out.print(table)


def kill_and_restart(tmp: Path, out: Console) -> None:
    folder = tmp / "killed"
    cmd = [sys.executable, "-m", "acq", "monitor", "--bench", str(ROBOT), "--fast", "--every", "600", "--keep", "3",
           "--out", str(folder)]
    proc = subprocess.Popen([*cmd, "--for", "10h"], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                            start_new_session=True)
    catalogue = folder / "catalogue.sqlite"

    def rows() -> int:
        try:
            with sqlite3.connect(catalogue) as db:
                return int(db.execute("SELECT COUNT(*) FROM analyses").fetchone()[0])
        except sqlite3.Error:
            return 0

    while proc.poll() is None and (rows() <= BASELINE or trend_of(folder).baseline_K_Nm_per_rad is None):
        time.sleep(0.5)
    deadline = time.monotonic() + 30
    while proc.poll() is None and time.monotonic() < deadline and not capturing(folder):
        time.sleep(0.02)  # kill inside a window's capture
    os.killpg(proc.pid, signal.SIGKILL)  # the monitor and its workers, as a power cut would
    proc.wait()
    before = trend_of(folder)
    n_before = len(before.points)
    subprocess.run([*cmd, "--for", "1h"], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, check=False)
    after = trend_of(folder)
    marks = [p.entry for p in after.points if p.entry.verdict == "interrupted"]
    windows = sorted(int(p.entry.tags[WINDOW_TAG]) for p in after.points)
    table = Table(title="kill -9 during a --fast monitor, then restart in the same folder")
    for c in ("rows before", "rows after", "windows numbered", "baseline K before", "after", "interrupted (marked)"):
        table.add_column(c, justify="right")
    table.add_row(str(n_before), str(len(after.points)),
                  f"{windows[0]}…{windows[-1]}" + (" (no gaps)" if windows == list(range(len(windows))) else " (gaps!)"),
                  format_value(before.baseline_K_Nm_per_rad, ".2f"), format_value(after.baseline_K_Nm_per_rad, ".2f"),
                  f"{len(marks)}" + (f": {json.dumps(marks[0].reasons[0])}" if marks else ""))
    out.print(table)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--hours", type=float, default=4.0)
    parser.add_argument("--every", type=float, default=900.0)
    parser.add_argument("--wear-every", type=float, default=600.0)
    parser.add_argument("--seeds", default="0,1,2", help="seeds of the constant-K runs ('' for none)")
    parser.add_argument("--decay", type=float, default=3.0)
    parser.add_argument("--decay-hours", type=float, default=6.0)
    parser.add_argument("--no-wear", action="store_true")
    parser.add_argument("--png", type=Path, default=None, help="draw the wear shift's trend into this PNG")
    parser.add_argument("--no-kill", action="store_true")
    parser.add_argument("--budget-mb", type=float, default=12.0, help="disk budget of the budget run (0: skip it)")
    args = parser.parse_args()
    out = Console(width=200)
    with tempfile.TemporaryDirectory(prefix="acq-monitor-bench-") as tmp:
        if args.seeds:
            constant_k(args.hours, args.every, [int(s) for s in args.seeds.split(",")], Path(tmp), out)
        if not args.no_wear:
            wear(args.decay, args.decay_hours, args.wear_every, Path(tmp), out, args.png)
        if args.budget_mb:
            disk_budget(args.budget_mb, Path(tmp), out)
        if not args.no_kill:
            kill_and_restart(Path(tmp), out)


if __name__ == "__main__":
    main()
