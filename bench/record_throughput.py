"""Recorder throughput on the simulated bench (prints figures; not a test).

    python bench/record_throughput.py [--seconds 10] [--realtime-seconds 5] [--repeat 5]

1. ``--fast``: how many samples per second the recorder sustains for 3 current channels at
   51.2 kS/s + encoder at 4 kHz, next to what the simulated bench alone generates, as far as the recorder
   reads it, nothing queued or written (the floor), two ways: both streams read in turn in one thread, and
   each stream read in its own thread as the recorder's two readers read them (each simulated read holds the
   bench's lock for its whole block, :meth:`drivers.sim.bench.SimBench.exclusive`, so the two compute one after
   the other; what contention is left is the simulator's, counted alike in the recorder's figure and this
   floor) — and their ratios (target, issue 17: ≥ 0.9), per wall second and per CPU second of the process (the
   recorder on one CPU as ``acq record --fast`` runs it, :mod:`acq.recording.one_cpu`; the floor where the kernel
   puts it);
   and the recording thread's own rate (its CPU alone: the index checks, the handoff from the readers and the
   writing), the same writing alone (:func:`writer_alone`: the blocks of a recording replayed into a writer, no
   simulator beside it) and its readers' rate (the rest of the process's CPU: the simulator as the recorder reads
   it, to set beside the floor); medians of ``--repeat`` runs, interleaved so that the machine's load hits all
   alike.
2. real time: CPU seconds the whole process spends per recorded second at the same rates.

Measured (2026-11-30, this 2-core machine shared with other work, ``--repeat 5``, BLAS 1 thread, six runs at load 4–6
interleaved with six of the code before the session module was split, which records alike): per CPU second the
recorder is 0.82–0.88 of the simulator alone read in one thread and 0.84–0.88 of it read a thread per stream (the
code before: 0.83–0.88 and 0.84–0.90; per wall second, which the load moves most, 0.79–0.94 and 0.76–0.91); 14–22 ×
real time. The recording thread: 43–53 M samples/s, 30–36 ms CPU per 10 s session (1.58 M samples). The same writing
alone: 73–78 M samples/s, 20–22 ms — creating the file 3 ms, copying the blocks into the write buffers 3 ms, the HDF5
writes 10.5 ms (7.5 ms the three current columns: HDF5 copies each chunk into a buffer of its own, its Fletcher32
filter copies it again and checksums it, ≈ 2.6 ms by perf, the kernel copies it into the page cache), finishing 2 ms.
Beside the simulator the thread adds ≈ 4 ms for the handoff, the index checks and the joining of encoder batches (a
recorder that only drains the queue), and its writing costs 5–11 ms more than alone: the two share caches and memory
bandwidth, and h5py lets go of the GIL in every ``set_extent`` and write (26 times a commit), where a waiting reader
takes it. Its readers spend 6–20 ms more than the floor. Tried and measured without gain (A/B, load 4–8): copies into
the write buffers that keep the GIL, a 25 ms handoff instead of 10 ms, 8 MiB commits (the recording thread −3 ms, its
readers +5 ms) or 0.5–1 MiB ones (both dearer), pausing the readers during a commit, a 20 ms GIL switch interval. The
target (≥ 0.9 per CPU second) is not met: at ≈ 290 ms for the floor it leaves ≈ 32 ms for the recording thread and
the readers' extra together, and the writing alone takes 20 of them, most of it set by what the file holds and checks
(every sample through HDF5's chunk copies and Fletcher32). Real time: 0.06–0.08 CPU s per recorded second.

Where the rest goes (2026-11-30, load ≈ 1, medians of 7, CPU ms of a 10 s session against a floor of 277–289 ms, the
recorder patched in a scratch copy): a recorder that drops every block it receives (file, flush rows and footer
still written) costs 17–21 ms over the floor, 10 of them its own thread; one that keeps the blocks but writes no
samples 28–31 ms; the whole recorder 40–45 ms (ratio 0.86–0.87). The floor's readers alone pay 5 ms more with a
third thread waking every 10 ms, 8 ms more when it also holds their blocks until then (cache-cold memory). Two
structural changes, each measured on the same runs: raw ADC codes stored as the card delivers them (int16 for a
16-bit card, int32 for a 24-bit NI 9234, with the scaling beside them; the simulated card quantising to codes)
0.89 against 0.87 interleaved over 9 runs (per-run 0.86–0.92) — not taken: a format change for 0.02 that leaves the
target unmet. The readers storing their own blocks under the recorder's lock, each commit made by the store that finds
it due, no third thread (built and passing the recorder's tests on branch wp/s8-rec): new/old 1.000 per interleaved
pair over 15 pairs (quartiles 0.97–1.03, load 5) — no gain, not merged. Under load the ratio rises for both (0.90 at
load 5, 0.91–0.94 at 6–7: the floor's own CPU grows more), so only figures at the same load compare.

Session 10 (2026-11-30): the process now runs with ``acq record``'s allocator setting (``acq.entry.keep_freed_memory``;
``--default-allocator`` leaves glibc's defaults), as it runs with its BLAS threads: at load 1.0–1.1, three interleaved
pairs gave per CPU 0.87/0.87, 0.83/0.85, 0.86/0.90 with it against 0.85/0.86, 0.86/0.86, 0.86/0.85 without (floor read
in one thread / a thread per stream) — no effect beyond the spread. Tried and not kept: a reader's end waking the
recording thread at once (a ``threading.Event`` instead of its 10 ms tick, so the last blocks of a ``--fast`` session
wait for nothing), measured with the allocator setting: at load ≈ 1, three pairs interleaved with main gave per wall
second (a thread per stream) 0.87, 0.88, 0.89 against main's 0.90, 0.90, 0.89 — no gain. Where the recorder's extra CPU
goes (``perf record -e cpu-clock`` of 15 recordings against 15 floor runs, per 10 s session): the kernel 14 ms (GIL
hand-overs between three threads — futex wake-ups and context switches, ≈ 640 futex calls and 220 switches more per
session — and the page cache taking 12.6 MB), the interpreter 9 ms, HDF5 8 ms, libc 5 ms, numpy 2.5 ms. Of the writing
alone (18 ms by itself), Fletcher32 is 2.3 ms and storing the current as float32 instead of float64 would save 2.5 ms;
the current's chunk length (1×, 2×, 5× 0.1 s) changes nothing (per-byte costs, not per-chunk ones). A lower bound for
this file format: floor + the writing alone + the handoff ≈ 290 + 18 + 4 ms, 0.93 per CPU second with no interplay at
all; the interplay of three threads on two cores costs 15–25 ms more, and nothing tried removes it.

Session 12 (2026-11-30): durable commits (each commit fdatasyncs the file after its samples and after its ``/flushes``
row; the layout, the folder and the footer synced once): a 10 s ``--fast`` session makes 17 syncs, ≈ 200 ms of wall
waiting on this machine's virtio disk (157–276 ms over 7 sessions) but 4–6 ms of CPU in them; the recording thread
overlaps that wait with the readers, all but the last commit's two syncs and the footer's (≈ 35 ms after the readers
are done). Five pairs of ``--repeat 7 --realtime-seconds 1`` interleaved with main frozen at 4dd6af4 (this branch is
that plus the syncs), load 8.6–9.7, new / old per pair, medians (ranges): the recorder's ``--fast`` rate per wall
second 0.97 (0.92–1.42: ≈ 3 % slower, inside the load's spread), per CPU second 0.98 (0.97–1.02); recorder / sim
alone per CPU second 1.00 / 0.99 (one thread / a thread per stream); the recording thread's own rate 0.90 (39.6 →
34.3 M samples/s), the writing alone 0.78 (67.2 → 52.2 M samples/s: the writeback the syncs start is charged to it,
work the kernel's flusher thread would do later otherwise); real time 0.090 → 0.097 CPU s per recorded second (1.09,
1.03–1.12, higher in all five pairs; a 1 s session carries the once-per-session syncs). An earlier eight pairs
against a main that moved during the runs (load 10–15) gave per wall 1.02, per CPU 0.99 / 0.98, the thread 0.85, the
writing alone 0.74, real time 0.098 → 0.096.

Session 12, the recording thread's GIL releases (2026-11-30, load 6–14 from other work throughout, so every figure is paired: two persistent worker
processes, main and the change, alternating recordings and floor runs in random order, 20–40 pairs a test). GIL
hand-overs counted (perf uprobe on libpython's ``drop_gil``, 3 sessions): the recording thread lets go of the GIL
≈ 1 490 times a session — numpy's copies into the write buffers ≈ 540 (numpy lets go for any copy of more than 500
elements), h5py freeing an ID ≈ 460 (≈ 300 of them creating and finishing the file, no reader running), ``set_extent``
and ``write`` 87 each, its sleeps 60–90, the encoder check's ufuncs ≈ 75 — against 12 600–19 800 of the two readers
between themselves (the simulator's numpy). Tried together (branch wp/s12-rec6, not merged): :class:`acq.recording.pending.Column` reuses its two
dataspaces (the low-level writes were there already; two fresh spaces an append were two more GIL releases when
freed), the encoder blocks of a handoff are one run that a current block no longer breaks, the buffer copies keep
the GIL: ≈ 820 releases. Recorder CPU, paired medians of five tests: −3.6, −8.3, −3.9, −1.5, −5.5 ms (its recording
thread −0.2…−1.8 of it), while the two workers' floors (the same code) differed by −4.1…+6.5 ms, so the per CPU
ratio moved +0.003, +0.022, +0.025, +0.019, −0.003. This script, two sets of 6 interleaved pairs (load 6–8, 9–12),
floor a thread per stream: per CPU main/new medians 0.890/0.885 and 0.885/0.915, new/old per pair 1.022 1.011 0.967
1.011 1.011 0.907 and 1.033 1.011 1.034 1.023 1.057 0.989 (median of the 12: 1.011); per wall 0.85/0.88 and
0.945/0.96 — +0.01, the size of the noise here: not merged (it also let listeners see a handoff's current blocks before encoder blocks that came earlier). Each part alone: nothing (spaces and runs −0.3 ms, copies alone
+3.9 ms). The writing alone is unchanged by it (21.0/22.3 ms against 21.1/20.9, 15 replays).
Tried and not taken: fewer wake-ups — a 100 ms handoff (not admissible, it bounds what waking on a commit's worth
could give) lowered the recording thread by 5–10 ms in each of 6 pairs (sleeps 62 → 9 a session, ≈ 40 µs CPU each
to take the GIL back, and longer encoder runs) but moved the readers by ±13 ms, the per CPU ratio per pair 0.98–1.06
of main's; the real-time bound (a block waits ≤ 10 ms) keeps the tick. Page faults: recorder − floor ≈ +70 a
session (``perf stat``), context switches ≈ +265: not where the readers' extra goes; their profile against the
floor's (15 runs each) spreads it over the interpreter (+4 ms), numpy and malloc. The recording thread's profile
(perf, DWARF call graphs): ``pwrite`` 20 % (≈ 6.6 ms: the page cache allocating pages and ext4's delayed allocation
per 4 KiB; the copy is 6 % of it), Fletcher32 9 %, HDF5's copies 5.5 %. Direct chunk writes (Fletcher32 computed in
numpy) were not built: more passes over the data than HDF5's own checksum. The recorder's figure includes creating
the file (≈ 3.7 ms CPU, 0.011 of the per CPU ratio), which ``acq record`` does before its recording starts.

Session 13, the commits' syncs off the recording thread (2026-11-30; built on branch wp/s13-sync and reverted there):
each commit's fdatasync in a thread of its own (only the system call; HDF5 untouched until it returned) covering the
commit's samples and the previous commit's ``/flushes`` row, written once its samples' sync had returned (with the next
commit's samples, or at the recorder's next 10 ms tick), the last row synced with the footer: one sync per commit
instead of two, two at a session's end instead of three; a row still never written before its samples were on the disk.
Recorder alone, 60 rounds in persistent workers against main 3d6370f (load 11–12), medians of per-round ratios (row at
the tick / with the next commit): wall 1.06 / 1.06 (quartiles 0.87–1.27, 23 and 25 of 60 faster than main), CPU 1.004 /
1.009, the recording thread 0.94 / 0.91 (the syncs' writeback is charged to the other thread); an earlier 30 rounds of
the latter (load 10): wall 0.96 (0.81–1.12), CPU 0.997. This script, ``--repeat 7 --realtime-seconds 1``, 16 pairs
interleaved with main over the variants (load 5–14): recorder / sim alone a thread per stream, medians, per wall 0.86 →
0.845, per CPU 0.86 → 0.87; the recorder's rate new/old per pair per wall 0.70–1.43 (median 1.05, 9 of 16 higher), per
CPU 0.96–1.07 (median 1.00, 8 of 16). No gain: a blocked sync already lets go of the GIL and the readers run meanwhile,
so only the session's end waits on the disk, and the change saved one short row sync there (0.1–8 ms measured). Not
merged: it also let a power cut lose up to two commits instead of one.

Session 14, the writing in a child process (2026-12-01; built on branch wp/s14-writerproc, commits a7b39c9 and 291caa3,
reverted there): an unchanged :class:`SessionWriter` in a child forked by ``Recorder.open_session`` before any reader
thread (h5py's lock held across the fork, SIGINT and SIGTERM ignored in the child, which creates the file and holds its
live lock, and finishes it as ``interrupted`` when its pipe closes); the recording thread kept the checks and the order
and sent each block, event and commit to it, the commits answered with the totals on the disk (failures raised at the
next flush, as the writer's). Two transports: a 1 MiB pipe carrying pickles (protocol 5, the arrays written from their
own buffers by ``os.writev``), or the arrays copied into a 4 MiB shared-memory ring and only the pickles through the
pipe. The script then counted the reaped child's CPU (``getrusage(RUSAGE_CHILDREN)``) in the recorder's. Per 10 s
session, medians of the runs below: the recording thread 40.5 ms → 26.5 (pipe) / 26.1 (ring), its readers 319 → 326 /
325, the recording process as a whole 361 → 352 / 349 (−14 / −17 ms, medians of pairs); the child 61 / 57 ms beside it
(the same writing alone 20–27 ms: the rest is its copy-on-write faults, ≈ 3 450 a session, reading the pipe or ring,
unpickling, the writing beside the simulator). What the fork costs the recording process (``getrusage``, 6 sessions,
load ≈ 5): ≈ 2 450 more minor faults (copy-on-write of the heap pages it shares with the child; the ring ≈ 1 000 more,
its pages touched), the fork 2 ms CPU (61 MB resident), and opening the session 22–49 ms of wall instead of 10–17 (it
waits for the child to create the file) — 4–7 % of a ``--fast`` session's ≈ 0.4 s. Pairs interleaved with main at
a8802db, ``--repeat 7 --realtime-seconds 1``, recorder / sim alone (one thread / a thread per stream), medians:
pipe, 5 pairs at load 6.0–6.8: per wall 0.79 / 0.82 → 0.81 / 0.80 (per-pair differences' medians +0.05 / −0.02), per
CPU 0.85 / 0.88 → 0.75 / 0.77; ring, 5 pairs at load 6.8–9.9: per wall 0.90 / 0.89 → 0.87 / 0.91 (−0.03 / +0.02), per
CPU 0.87 / 0.87 → 0.76 / 0.78; 6 triples main / pipe / ring at load 9.9–18.4: per wall 0.935 / 0.895, 0.825 / 0.810,
0.735 / 0.820 (differences pipe −0.085 / −0.075, ring −0.150 / −0.100), per CPU 0.865 / 0.855, 0.745 / 0.765, 0.760 /
0.775 (differences −0.11 / −0.11, −0.10 / −0.085, every pair lower); pipe, 6 more pairs as the load fell (2.1–5.6):
per wall 0.820 / 0.835 → 0.720 / 0.725 (differences −0.080 / −0.100, 2 of 12 higher by 0.01), per CPU 0.850 / 0.860 →
0.745 / 0.765 (−0.105 / −0.100), the recording thread 36.3 → 21.4 ms but its readers 312 → 325 ms, the process −6 ms.
Not kept: per wall it gains nothing at these loads (the second core is not idle: the child waits for it like everything
else), and even on an idle core it is bounded by what the recording process sheds, 1–4 % of its CPU (the readers pay
back most of the recording thread's saving: the copy-on-write faults), against the 4–7 % the fork and the wait for the
child's file add to a session's wall; per CPU it costs 0.10 (the child's and the parent's copy-on-write faults, the
transport). A child started by exec instead of a fork would share no pages, but its start (a new interpreter importing
the writer, numpy and h5py: 0.33–0.36 s CPU, 0.44–0.47 s wall at load 5) would come before the file exists: more than a
whole ``--fast`` session. The pipe was the cheaper transport for the recording thread (per-message pickling either way;
the ring's copies keep the GIL). Also in the way: a recorder killed with SIGKILL leaves its file finished as
``interrupted`` by the child (``tests/test_recorder.py`` and ``tests/test_live_session.py`` expect ``recording`` and a
repair), and ``tests/test_durability.py`` logs the syncs in the recording process's memory, which the child's syncs
never reach.

Session 16, one CPU (2026-12-01; ``Recorder(one_cpu=True)``, which ``acq record --fast`` and this script's ``--fast``
runs use): pinning the whole process to one CPU (``taskset -c``) first, 5 pairs at load 4.5–4.7: the recorder's CPU
per 10 s session 406 → 388 ms (median), the floor 348 → 344, per CPU 0.87 / 0.87 → 0.89 / 0.89 (one thread / a
thread per stream), the recording thread 38.5 → 33.8 ms, its readers 364 → 353, real time unchanged (0.076–0.085
against 0.076–0.082 CPU s per recorded second). What the three threads paid on two CPUs was cross-CPU: blocks
computed in one CPU's cache and copied from the other's, and GIL hand-overs that wake a thread on the other CPU. Then
the recording thread and its readers alone on the CPU the recording thread is on (the readers inherit it; the thread
gets its CPUs back after), 14 pairs interleaved with main 9605b70 (5 at load 1.8–2.5, 5 at 3.1–5.2, 4 at 5.7–7.0),
``--repeat 5 --realtime-seconds 1``, medians (ranges) main → this: per CPU 0.860 (0.82–0.93) → 0.900 (0.88–0.95) a
thread per stream, higher in 12 of 14 pairs, per-pair difference +0.045 (−0.03…+0.09); 0.845 (0.81–0.91) → 0.890
(0.88–0.91) one thread, higher in 13 of 14, +0.055 (−0.01…+0.08); the recorder's CPU 410 → 385 ms (per pair −26,
−42…−3), the recording thread 37.8 → 32.6 ms, its readers 370 → 351, the floor and the writing alone unchanged (352 /
346, 24.2 / 24.5 ms); real time 0.068–0.082 → 0.070–0.083 (not pinned). Per wall second 0.850 → 0.860 (a thread per
stream) and 0.815 → 0.870 (one thread), the recorder's wall 561 → 425 ms (per pair −27, −233…+260) — but at load
5.7–7.0 the 4 pairs went the other way, 641 → 738 ms (0.915 → 0.805 a thread per stream): a thread held to one busy
CPU cannot move to the other one. Hence --fast only: a real device's reader waits on its device, the gain is none
there and the risk is a reader held behind other work on its CPU. Also measured this session, without gain (each
below 2 ms a session, under the pairs' noise, not built): HDF5's ``set_extent`` is 0.5 ms for 240 calls (the recorder
makes ≈ 90 a session: pre-sizing the extents and cutting them at the end would save ≈ 0.2 ms); writing the current
blocks as parts of one commit straight from the readers' arrays, no copy into the write buffers: 9.4 → 8.4 ms per
session's current (3 channels, 100 chunks each, written alone); Python's cyclic GC runs 0–1 times a session (0.3 ms);
a reader's own per-block work beside the floor's (the covered count and the queue) 0.36 µs a block, 0.4 ms a session;
direct chunk writes (``write_direct_chunk``) with Fletcher32 computed in numpy (bit-exact with HDF5's, the file read
back with its checksums verified) cost 112 µs a chunk for the checksum alone against ≈ 8 µs for HDF5's whole filter:
60–500 ms a session instead of 10. On one CPU the GIL's switch interval (``sys.setswitchinterval`` 1, 5 — the
default — and 20 ms, 3 interleaved rounds at load 2.8–5.0) changed nothing: per CPU 0.89 / 0.90, 0.90 / 0.93 and
0.90 / 0.93 (one thread / a thread per stream, medians), the recording thread 32.3, 32.2 and 31.6 ms.

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
from typing import Any

from rich.console import Console
from rich.table import Table

from acq.config import load_bench, load_profile
from acq.entry import keep_freed_memory
from acq.recording.recorder import Recorder
from acq.recording.room import FLUSH_BYTES
from acq.recording.writer import SessionWriter
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
    recorder = Recorder(bench, load_profile("triangle_0.2s"), current, drive, out, seconds, one_cpu=fast)
    wall0, cpu0, own0 = time.perf_counter(), time.process_time(), time.thread_time()
    result = recorder.run()
    wall, cpu, own = time.perf_counter() - wall0, time.process_time() - cpu0, time.thread_time() - own0
    assert result.status == "complete", result.stop_reason
    return wall, cpu, result.current_samples * len(bench.daq.channels) + result.encoder_samples, own


def writer_alone(bench: Bench, seconds: float, out: Path) -> float:
    """CPU s of the session writer alone: the blocks of one ``--fast`` recording (as its listeners saw them, encoder
    batches joined) replayed into a new :class:`SessionWriter` with the recorder's flush rule by size
    (``FLUSH_BYTES``; in ``--fast`` its 0.5 s rule commits at most once more), no simulator running beside it: what
    the recording thread's writing costs by itself, file creation and footer included."""
    written: list[tuple[str, Any]] = []
    current, drive = open_bench(bench, fast=True)
    recorder = Recorder(bench, load_profile("triangle_0.2s"), current, drive, out, seconds,
                        listeners=[lambda kind, item: written.append((kind, item))])
    assert recorder.run().status == "complete"
    append = {"current": "append_current", "encoder": "append_encoder", "event": "add_event"}
    cpu0 = time.thread_time()
    writer = SessionWriter(out / "replay.h5", bench=bench, profile=recorder.profile, current_info=recorder.current_info,
                           drive_info=recorder.drive_info, host_ns_at_start=time.monotonic_ns())
    for kind, item in written:
        getattr(writer, append[kind])(item)
        if writer.pending_bytes >= FLUSH_BYTES:
            writer.flush()
    writer.finish("complete", "replayed")
    cpu = time.thread_time() - cpu0
    (out / "replay.h5").unlink()
    return cpu


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=10.0, help="recorded seconds in --fast mode")
    parser.add_argument("--realtime-seconds", type=float, default=5.0, help="recorded seconds in real time")
    parser.add_argument("--repeat", type=int, default=5, help="--fast runs of each (medians are shown)")
    parser.add_argument("--blas-threads", default="1",
                        help="BLAS threads: a count, or 'default' (OpenBLAS's own); 1 is what acq record runs with")
    parser.add_argument("--default-allocator", action="store_true",
                        help="glibc's malloc defaults, not acq record's (acq.entry.keep_freed_memory)")
    args = parser.parse_args()
    env = blas_env(args.blas_threads)
    if env != dict(os.environ):  # numpy has loaded its BLAS already: start again with the threads asked for
        os.execve(sys.executable, [sys.executable, *sys.argv], env)
    if not args.default_allocator:
        keep_freed_memory()  # as the acq record process does, for the floor and the recorder alike
    bench = heavy_bench()
    runs: dict[str, list[tuple[float, float, int]]] = {"sim": [], "sim2": [], "recorder": []}
    own_rates: list[float] = []
    reader_rates: list[float] = []
    alone_rates: list[float] = []
    with tempfile.TemporaryDirectory() as tmp:
        for _ in range(args.repeat):
            runs["sim"].append(generate_only(bench, args.seconds))
            runs["sim2"].append(generate_threaded(bench, args.seconds))
            wall, cpu, samples, own = record(bench, args.seconds, True, Path(tmp))
            runs["recorder"].append((wall, cpu, samples))
            own_rates.append(samples / own)
            reader_rates.append(samples / (cpu - own))
            alone_rates.append(samples / writer_alone(bench, args.seconds, Path(tmp)))
        rt_wall, rt_cpu, _, _ = record(bench, args.realtime_seconds, False, Path(tmp))
    rates = {name: (statistics.median(n / wall for wall, _, n in r), statistics.median(n / cpu for _, cpu, n in r))
             for name, r in runs.items()}
    wall = statistics.median(wall for wall, _, _ in runs["recorder"])
    allocator = "glibc's defaults" if args.default_allocator else "acq record's"
    table = Table(title="recorder throughput — 3 × 51.2 kS/s current + 4 kHz encoder, simulated bench "
                        f"(medians of {args.repeat}, BLAS threads: {args.blas_threads}, allocator: {allocator})")
    table.add_column("figure")
    table.add_column("per wall second", justify="right")
    table.add_column("per CPU second", justify="right")
    table.add_row("sim bench alone, one thread, --fast [samples/s]", *(f"{v:,.0f}" for v in rates["sim"]))
    table.add_row("sim bench alone, a thread per stream [samples/s]", *(f"{v:,.0f}" for v in rates["sim2"]))
    table.add_row(f"recorder, --fast, {args.seconds:g} s session [samples/s]", *(f"{v:,.0f}" for v in rates["recorder"]))
    table.add_row("  its recording thread alone: checks, handoff, writing [samples/s]", "",
                  f"{statistics.median(own_rates):,.0f}")
    table.add_row("    the same writing alone: its blocks replayed, no simulator beside it [samples/s]", "",
                  f"{statistics.median(alone_rates):,.0f}")
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
