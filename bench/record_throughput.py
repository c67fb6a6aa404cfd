"""Recorder throughput on the simulated bench (prints figures; not a test).

    python bench/record_throughput.py [--seconds 10] [--realtime-seconds 5] [--repeat 5]

1. ``--fast``: how many samples per second the recorder sustains for 3 current channels at
   51.2 kS/s + encoder at 4 kHz, next to what the simulated bench alone generates, as far as the recorder
   reads it, nothing queued or written (the floor), two ways: both streams read in turn in one thread, and
   each stream read in its own thread as the recorder's two readers read them (each simulated read holds the
   bench's lock for its whole block, :meth:`drivers.sim.bench.SimBench.exclusive`, so the two compute one after
   the other; what contention is left is the simulator's, counted alike in the recorder's figure and this
   floor) — and their ratios (target, issue 17: ≥ 0.9), per wall second and per CPU second of the process;
   and the recording thread's own rate (its CPU alone: the index checks, the handoff from the readers and the
   writing) and its readers' (the rest of the process's CPU: the simulator as the recorder reads it, to set
   beside the floor); medians of ``--repeat`` runs, interleaved so that the machine's
   load hits all alike.
2. real time: CPU seconds the whole process spends per recorded second at the same rates.

Measured (2026-11-30, this 2-core machine shared with other work, ``--repeat 5``, BLAS 1 thread, six runs at load 2–9):
per CPU second the recorder is 0.84–0.87 of the simulator alone read in one thread and 0.87–0.90 of it read a thread per
stream (the code before, in the same interleaved runs: 0.81–0.84 and 0.83–0.88; per wall second, which the load moves
most, 0.83–0.98 and 0.87–1.07); 13–30 × real time. The recording thread alone: 39–54 M samples/s, 29–40 ms CPU per
10 s session (1.58 M samples; before: 35–45 ms) — about 13 ms of it the HDF5 writes themselves (HDF5's chunk copies,
Fletcher32, the kernel's copy into the page cache; a writer fed without a simulator: 21 ms for the whole file), 5 ms
creating and finishing the file, the rest the handoff, the index checks and the joining of encoder batches. Its readers
spend 5–15 ms more than the floor: ≈ 4 ms of it is what handing each block to another thread costs the simulator's
threads (the floor read so, with a consumer that only sums the blocks), the rest follows the writing. The target
(≥ 0.9 per CPU second) is not met: at ≈ 300 ms for the floor it leaves ≈ 33 ms for the recording thread and the
readers' extra together. Real time: 0.07–0.09 CPU s per recorded second.

BLAS threads: ``--blas-threads 1`` (the default) measures what ``acq record`` runs with (``acq/entry.py`` pins one
thread); ``default`` leaves OpenBLAS its own count. The simulator's state interpolation multiplies (5120 × 7) by
(7 × 7) matrices per current block: OpenBLAS splits those over both cores and its second thread costs more than it
saves (measured, 10 s at the rates above: the bench alone 0.29 s CPU with one thread, 0.46 s with the default, 0.09 s
of it in OpenBLAS's own thread), in the floor and in the recorder alike.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import tempfile
import threading
import time
from pathlib import Path

from rich.console import Console
from rich.table import Table

from acq.config import load_bench, load_profile
from acq.recording.recorder import Recorder
from drivers.base import CurrentSource, Drive
from drivers.config import Bench
from drivers.registry import open_bench

_BLAS_VARS = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")


def blas_env(threads: str) -> dict[str, str]:
    """This process's environment with ``threads`` BLAS threads (``default``: none of the variables set)."""
    env = {k: v for k, v in os.environ.items() if k not in _BLAS_VARS}
    if threads != "default":
        env.update(dict.fromkeys(_BLAS_VARS, threads))
    return env


def heavy_bench() -> Bench:
    """The default simulated bench at 3 × 51.2 kS/s current and a 4 kHz encoder."""
    bench = load_bench()
    daq = bench.daq.model_copy(update={"rate_hz": 51200.0, "channels": ["i_a", "i_b", "i_c"]})
    drive = bench.drive.model_copy(update={"period_s": 0.00025})
    return bench.model_copy(update={"daq": daq, "drive": drive})


def generate_only(bench: Bench, seconds: float) -> tuple[float, float, int]:
    """The simulated bench alone, nothing written: (wall s, CPU s, samples over all channels) for ``seconds``.

    The two streams are read in turn (the encoder kept up with the current, as the recorder's two readers keep
    them): reading one stream to its end first makes the bench hold the other's history all along, which costs
    more than generating it.
    """
    current, drive = open_bench(bench, fast=True)
    cur_info, drv_info = current.start(), drive.start()
    drive.start_motion(load_profile("triangle_0.2s"))
    cur_target, enc_target = seconds * cur_info.rate_hz, seconds / drv_info.period_s
    wall0, cpu0, n_cur, n_enc = time.perf_counter(), time.process_time(), 0, 0
    while n_cur < cur_target or n_enc < enc_target:
        if n_cur < cur_target and n_cur / cur_target <= n_enc / enc_target:
            block = current.read(1.0)
            n_cur += block.count if block else 0
        else:
            eblock = drive.read(1.0)
            n_enc += eblock.count if eblock else 0
    wall, cpu = time.perf_counter() - wall0, time.process_time() - cpu0
    drive.stop_motion(), current.stop(), drive.stop()
    return wall, cpu, n_cur * len(cur_info.channels) + n_enc


def generate_threaded(bench: Bench, seconds: float) -> tuple[float, float, int]:
    """The simulated bench alone read as the recorder reads it: one thread per stream, each reading (and asking for
    events) until it has ``seconds``, nothing queued or written; (wall s, CPU s, samples over all channels)."""
    current, drive = open_bench(bench, fast=True)
    cur_info, drv_info = current.start(), drive.start()
    drive.start_motion(load_profile("triangle_0.2s"))
    counts = {"current": 0, "encoder": 0}

    def read(name: str, device: CurrentSource | Drive, target: float) -> None:
        while counts[name] < target:
            block = device.read(1.0)
            device.events()
            counts[name] += block.count if block else 0

    readers = [threading.Thread(target=read, args=("current", current, seconds * cur_info.rate_hz)),
               threading.Thread(target=read, args=("encoder", drive, seconds / drv_info.period_s))]
    wall0, cpu0 = time.perf_counter(), time.process_time()
    for reader in readers:
        reader.start()
    for reader in readers:
        reader.join()
    wall, cpu = time.perf_counter() - wall0, time.process_time() - cpu0
    drive.stop_motion(), current.stop(), drive.stop()
    return wall, cpu, counts["current"] * len(cur_info.channels) + counts["encoder"]


def record(bench: Bench, seconds: float, fast: bool, out: Path) -> tuple[float, float, int, float]:
    """Record; return (wall s, CPU s, samples stored over all channels, CPU s of the recording thread alone: the
    checks, the handoff and the writing, not the readers)."""
    current, drive = open_bench(bench, fast=fast)
    recorder = Recorder(bench, load_profile("triangle_0.2s"), current, drive, out, seconds)
    wall0, cpu0, own0 = time.perf_counter(), time.process_time(), time.thread_time()
    result = recorder.run()
    wall, cpu, own = time.perf_counter() - wall0, time.process_time() - cpu0, time.thread_time() - own0
    assert result.status == "complete", result.stop_reason
    return wall, cpu, result.current_samples * len(bench.daq.channels) + result.encoder_samples, own


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=10.0, help="recorded seconds in --fast mode")
    parser.add_argument("--realtime-seconds", type=float, default=5.0, help="recorded seconds in real time")
    parser.add_argument("--repeat", type=int, default=5, help="--fast runs of each (medians are shown)")
    parser.add_argument("--blas-threads", default="1",
                        help="BLAS threads: a count, or 'default' (OpenBLAS's own); 1 is what acq record runs with")
    args = parser.parse_args()
    env = blas_env(args.blas_threads)
    if env != dict(os.environ):  # numpy has loaded its BLAS already: start again with the threads asked for
        os.execve(sys.executable, [sys.executable, *sys.argv], env)
    bench = heavy_bench()
    runs: dict[str, list[tuple[float, float, int]]] = {"sim": [], "sim2": [], "recorder": []}
    own_rates: list[float] = []
    reader_rates: list[float] = []
    with tempfile.TemporaryDirectory() as tmp:
        for _ in range(args.repeat):
            runs["sim"].append(generate_only(bench, args.seconds))
            runs["sim2"].append(generate_threaded(bench, args.seconds))
            wall, cpu, samples, own = record(bench, args.seconds, True, Path(tmp))
            runs["recorder"].append((wall, cpu, samples))
            own_rates.append(samples / own)
            reader_rates.append(samples / (cpu - own))
        rt_wall, rt_cpu, _, _ = record(bench, args.realtime_seconds, False, Path(tmp))
    rates = {name: (statistics.median(n / wall for wall, _, n in r), statistics.median(n / cpu for _, cpu, n in r))
             for name, r in runs.items()}
    wall = statistics.median(wall for wall, _, _ in runs["recorder"])
    table = Table(title="recorder throughput — 3 × 51.2 kS/s current + 4 kHz encoder, simulated bench "
                        f"(medians of {args.repeat}, BLAS threads: {args.blas_threads})")
    table.add_column("figure")
    table.add_column("per wall second", justify="right")
    table.add_column("per CPU second", justify="right")
    table.add_row("sim bench alone, one thread, --fast [samples/s]", *(f"{v:,.0f}" for v in rates["sim"]))
    table.add_row("sim bench alone, a thread per stream [samples/s]", *(f"{v:,.0f}" for v in rates["sim2"]))
    table.add_row(f"recorder, --fast, {args.seconds:g} s session [samples/s]", *(f"{v:,.0f}" for v in rates["recorder"]))
    table.add_row("  its recording thread alone: checks, handoff, writing [samples/s]", "",
                  f"{statistics.median(own_rates):,.0f}")
    table.add_row("  its readers: the simulator as the recorder reads it (the rest of its CPU) [samples/s]", "",
                  f"{statistics.median(reader_rates):,.0f}")
    for name, floor in (("one thread", "sim"), ("a thread per stream", "sim2")):
        table.add_row(f"  recorder / sim alone, {name} (target ≥ 0.9)",
                      *(f"{r / g:.2f}" for r, g in zip(rates["recorder"], rates[floor])))
    table.add_row("  = real-time factor", f"{args.seconds / wall:.1f} ×", "")
    table.add_row(f"real time, {args.realtime_seconds:g} s: CPU per recorded second [s/s]", "",
                  f"{rt_cpu / args.realtime_seconds:.3f}")
    table.add_row("real time: wall / recorded", f"{rt_wall / args.realtime_seconds:.3f}", "")
    Console().print(table)
    print(f"load average {' '.join(f'{x:.2f}' for x in os.getloadavg())}")


if __name__ == "__main__":
    main()
