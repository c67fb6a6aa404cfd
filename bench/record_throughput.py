"""Recorder throughput on the simulated bench (prints figures; not a test).

    python bench/record_throughput.py [--seconds 10] [--realtime-seconds 5]

1. ``--fast``: how many samples per second the recorder sustains for 3 current channels at
   51.2 kS/s + encoder at 4 kHz, next to what the simulated bench alone generates (so the
   recorder's own cost is visible).
2. real time: CPU seconds the whole process spends per recorded second at the same rates.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

from rich.console import Console
from rich.table import Table

from acq.config import load_bench, load_profile
from acq.recorder import Recorder
from drivers.config import Bench
from drivers.registry import open_bench


def heavy_bench() -> Bench:
    """The default simulated bench at 3 × 51.2 kS/s current and a 4 kHz encoder."""
    bench = load_bench()
    daq = bench.daq.model_copy(update={"rate_hz": 51200.0, "channels": ["i_a", "i_b", "i_c"]})
    drive = bench.drive.model_copy(update={"period_s": 0.00025})
    return bench.model_copy(update={"daq": daq, "drive": drive})


def generate_only(bench: Bench, seconds: float) -> float:
    """Samples per second the simulated bench produces when nothing is written."""
    current, drive = open_bench(bench, fast=True)
    cur_info, drv_info = current.start(), drive.start()
    drive.start_motion(load_profile("triangle_0.2s"))
    t0, n_cur, n_enc = time.perf_counter(), 0, 0
    while n_cur < seconds * cur_info.rate_hz:
        block = current.read(1.0)
        n_cur += block.count if block else 0
    while n_enc < seconds / drv_info.period_s:
        eblock = drive.read(1.0)
        n_enc += eblock.count if eblock else 0
    elapsed = time.perf_counter() - t0
    drive.stop_motion(), current.stop(), drive.stop()
    return (n_cur * len(cur_info.channels) + n_enc) / elapsed


def record(bench: Bench, seconds: float, fast: bool, out: Path) -> tuple[float, float, int]:
    """Record; return (wall s, CPU s, samples stored over all channels)."""
    current, drive = open_bench(bench, fast=fast)
    recorder = Recorder(bench, load_profile("triangle_0.2s"), current, drive, out, seconds)
    wall0, cpu0 = time.perf_counter(), time.process_time()
    result = recorder.run()
    wall, cpu = time.perf_counter() - wall0, time.process_time() - cpu0
    assert result.status == "complete", result.stop_reason
    return wall, cpu, result.current_samples * len(bench.daq.channels) + result.encoder_samples


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=10.0, help="recorded seconds in --fast mode")
    parser.add_argument("--realtime-seconds", type=float, default=5.0, help="recorded seconds in real time")
    args = parser.parse_args()
    bench = heavy_bench()
    with tempfile.TemporaryDirectory() as tmp:
        gen_rate = generate_only(bench, args.seconds)
        wall, cpu, n = record(bench, args.seconds, True, Path(tmp))
        rt_wall, rt_cpu, _ = record(bench, args.realtime_seconds, False, Path(tmp))
    table = Table(title="recorder throughput — 3 × 51.2 kS/s current + 4 kHz encoder, simulated bench")
    table.add_column("figure")
    table.add_column("value", justify="right")
    table.add_row("sim bench alone, --fast [samples/s]", f"{gen_rate:,.0f}")
    table.add_row(f"recorder, --fast, {args.seconds:g} s session [samples/s]", f"{n / wall:,.0f}")
    table.add_row("  = real-time factor", f"{args.seconds / wall:.1f} ×")
    table.add_row(f"real time, {args.realtime_seconds:g} s: CPU per recorded second [s/s]",
                  f"{rt_cpu / args.realtime_seconds:.3f}")
    table.add_row("real time: wall / recorded", f"{rt_wall / args.realtime_seconds:.3f}")
    Console().print(table)


if __name__ == "__main__":
    main()
