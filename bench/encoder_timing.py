"""Encoder sample-instant jitter: the estimate against the truth and K, J errors with and without the
drive's time stamps (issue 13 item 3). Prints a table; not a test.

    python bench/encoder_timing.py [--seeds 3] [--duration 10] [--jitter-us 0,2,5,20,50,200]

Each run is a simulated session of the paper's plant (0.2 s triangle, 1000 rpm) whose drive latches the
position when SYNC arrives, k·T + δ_k, δ_k ~ N(0, σ). "no stamps" analyses the positions on k·T (the
jitter is estimated from the data); "stamps" gives the analysis the drive's time stamps (latch instant,
1 µs resolution, another origin), as the serial frame's drive time or CANopen 0x1013 would.
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
from rich.console import Console
from rich.table import Table

ROOT = Path(__file__).resolve().parent.parent
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

NAMES = ("K_Nm_per_rad", "Jm_kgm2", "Jl_kgm2")
STAMP_ORIGIN_S = 42.5  # the drive clock's own origin: must not matter


def run(jitter_s: float, seed: int, duration_s: float) -> list[str]:
    """One session: realised jitter, then (estimate, verdict, errors) without and with stamps."""
    from analysis import AnalysisRequest, analyze
    from drivers.sim.bench import SimBench
    from tests.test_analysis_pipeline import SIM_TOML, sim_recording
    from acq.config import load_bench

    rec, truth, nominal = sim_recording(duration_s=duration_s, seed=seed, sync_jitter_s=jitter_s)
    bench = load_bench(SIM_TOML)
    sim = SimBench(bench.model_copy(update={"sim": bench.sim.model_copy(update={"seed": seed,
                                                                               "sync_jitter_s": jitter_s})}),
                   realtime=False)
    latch = sim.latch_times_s(0, rec.encoder_index.size)
    realised = np.sqrt(np.mean((latch - rec.encoder_index * rec.period_s) ** 2))
    row = [f"{1e6 * jitter_s:g}", str(seed), f"{1e6 * realised:.1f}"]
    stamps = np.round((latch + STAMP_ORIGIN_S) * 1e6) * 1e-6
    for r in (rec, replace(rec, drive_time_s=stamps)):
        res = analyze(r, AnalysisRequest(nominal=nominal))
        err = [100.0 * (getattr(res.fit.values, n) / truth[n] - 1.0) for n in NAMES]
        row += [f"{1e6 * res.quality.encoder_jitter_s:.2f}", res.quality.verdict, *(f"{e:+.2f}" for e in err)]
    return row


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=3)
    parser.add_argument("--duration", type=float, default=10.0)
    parser.add_argument("--jitter-us", default="0,2,5,20,50,200")
    args = parser.parse_args(argv)
    table = Table(title="SYNC-latch jitter: estimate and identification errors [%], paper plant")
    for col in ("σ set µs", "seed", "σ true µs", "est µs", "verdict", "K", "J_m", "J_l",
                "stamped: left µs", "verdict", "K", "J_m", "J_l"):
        table.add_column(col, justify="right")
    for jitter_us in (float(x) for x in args.jitter_us.split(",")):
        for seed in range(1, args.seeds + 1):
            table.add_row(*run(jitter_us * 1e-6, seed, args.duration))
    Console(width=160).print(table)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
