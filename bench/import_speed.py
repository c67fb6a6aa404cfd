"""Import speed: a 60 s CSV pair (1 phase at 25.6 kS/s, encoder at 1 kHz) → session (prints figures).

    python bench/import_speed.py [--seconds 60] [--phases 1] [--repeat 3]

Writes the pair in the form ``acq export`` writes (``t_s`` to the ns, currents in their shortest
exact form, encoder with ``index`` and ``drive_time_s``) into a temporary folder, then times
:func:`acq.offline.importers.import_session` in this process (median of ``--repeat``, wall and CPU), the floor —
pandas' C parser reading the same two files into float64 (``pandas.read_csv(engine="c")``, median of
``--repeat``; ``pip install pandas`` for it), the runs of the two interleaved so that the machine's load hits
both alike — and their ratio, and once the whole ``acq import`` command in a fresh process (Python start-up and
the package's imports included), with the load average. Target (issue 17): import ≤ 2× the floor.
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from rich.console import Console
from rich.table import Table

from acq.config import DEFAULT_BENCH, load_bench, load_profile
from acq.offline.importers import import_session

RATE_HZ = 25600.0
PERIOD_S = 0.001


def write_pair(folder: Path, seconds: float, phases: int) -> tuple[Path, Path]:
    """A synthetic pair: PMSM-like phase currents and a triangle-ish position with host jitter."""
    rng = np.random.default_rng(0)
    t = 0.037 + np.arange(int(seconds * RATE_HZ)) / RATE_HZ
    names = ["i_a_A", "i_b_A", "i_c_A"][:phases]
    currents = [3.0 * np.sin(2 * np.pi * 60.0 * t - k * 2 * np.pi / 3) + rng.normal(0, 0.01, t.size)
                for k in range(phases)]
    rows = zip([f"{x:.9f}" for x in t.tolist()], *([repr(x) for x in c.tolist()] for c in currents))
    cur = folder / "current.csv"
    cur.write_text(",".join(["t_s", *names]) + "\n" + "\n".join(map(",".join, rows)) + "\n")
    k = np.arange(int(seconds / PERIOD_S))
    host = k * PERIOD_S + rng.uniform(2e-4, 1.2e-3, k.size)
    counts = np.rint(131072 * 3 * np.sin(2 * np.pi * 1.25 * k * PERIOD_S)).astype(np.int64)
    enc = folder / "encoder.csv"
    rows = zip([f"{x:.9f}" for x in host.tolist()], map(str, counts.tolist()), map(str, k.tolist()),
               [repr(x) for x in (k * PERIOD_S).tolist()])
    enc.write_text("t_s,position_counts,index,drive_time_s\n" + "\n".join(map(",".join, rows)) + "\n")
    return cur, enc


def pandas_floor(cur: Path, enc: Path) -> tuple[float, float] | None:
    """Wall and CPU seconds of pandas' C parser reading both files into float64; None without pandas."""
    try:
        import pandas as pd
    except ImportError:
        return None
    t0, c0 = time.perf_counter(), time.process_time()
    for path in (cur, enc):
        pd.read_csv(path, engine="c", dtype=np.float64).to_numpy()
    return time.perf_counter() - t0, time.process_time() - c0


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=60.0)
    parser.add_argument("--phases", type=int, default=1, choices=(1, 2, 3))
    parser.add_argument("--repeat", type=int, default=5)
    args = parser.parse_args()
    bench, profile = load_bench(DEFAULT_BENCH), load_profile("triangle_0.2s")
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        cur, enc = write_pair(folder, args.seconds, args.phases)
        walls, cpus, floors = [], [], []
        for i in range(args.repeat):
            t0, c0 = time.perf_counter(), time.process_time()
            import_session(cur, enc, bench, profile, folder / f"s{i}.h5")
            walls.append(time.perf_counter() - t0)
            cpus.append(time.process_time() - c0)
            floors.append(pandas_floor(cur, enc))
        measured = [f for f in floors if f is not None]
        floor = (statistics.median(w for w, _ in measured), statistics.median(c for _, c in measured)) if measured else None
        t0 = time.perf_counter()
        subprocess.run([sys.executable, "-m", "acq", "import", "--current", str(cur), "--encoder", str(enc),
                        "--bench", str(DEFAULT_BENCH), "--profile", "triangle_0.2s", "-o", str(folder / "cli.h5")],
                       check=True, capture_output=True)
        cli_s = time.perf_counter() - t0
        table = Table(title=f"acq import: {args.seconds:g} s, {args.phases} phase(s) at {RATE_HZ:g} S/s + encoder "
                            f"at {1 / PERIOD_S:g} Hz")
        for col in ("what", "value"):
            table.add_column(col)
        table.add_row("current CSV", f"{cur.stat().st_size / 1e6:.1f} MB")
        table.add_row("encoder CSV", f"{enc.stat().st_size / 1e6:.1f} MB")
        wall, cpu = statistics.median(walls), statistics.median(cpus)
        table.add_row(f"import_session (median of {args.repeat})", f"{wall:.3f} s wall, {cpu:.3f} s CPU")
        if floor is None:
            table.add_row("floor: pandas' C parser", "pandas not installed (pip install pandas)")
        else:
            table.add_row(f"floor: pandas' C parser, both files (median of {args.repeat})",
                          f"{floor[0]:.3f} s wall, {floor[1]:.3f} s CPU")
            table.add_row("import / floor (target ≤ 2)", f"{wall / floor[0]:.2f} wall, {cpu / floor[1]:.2f} CPU")
        table.add_row("`acq import` in a fresh process", f"{cli_s:.2f} s  (start-up and imports included)")
        Console().print(table)
        print(f"load average {' '.join(f'{x:.2f}' for x in os.getloadavg())}")


if __name__ == "__main__":
    main()
