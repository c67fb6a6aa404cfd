"""Keep a recording's threads on one CPU (``acq record --fast``: a simulated bench computed as fast as it goes).

In --fast mode the reader threads compute the simulated bench one after the other (its lock) while the recording
thread writes what they handed over: on two CPUs every block crosses from one CPU's cache to the other's and every
GIL hand-over wakes a thread on the other CPU. On one CPU the recorder's CPU time for a 10 s session of
bench/record_throughput.py fell from 410 to 385 ms (medians of 14 pairs; its readers −17 ms, the recording thread
−7; the simulator read alone, nothing written, unchanged), and at loads up to 5 its wall time with it (the readers
never ran in parallel anyway), but at load 6–7 the wall time rose (641 → 738 ms): a thread held to one busy CPU
cannot move to the other. In real time it changes nothing measurable (0.07–0.08 CPU s per recorded second either
way), and a real device's reader waits on its device, not on a CPU, and must not wait behind other work on its
CPU: so it is only asked for --fast.
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from contextlib import contextmanager, suppress


def current_cpu() -> int | None:
    """The CPU the calling thread runs on (Linux: ``/proc/thread-self/stat``'s field 39); None where unknown."""
    try:
        with open("/proc/thread-self/stat", "rb") as f:
            fields = f.read().rsplit(b")", 1)[1].split()  # after the command name, which may hold spaces
        return int(fields[36])  # field 39 of the line; the split starts at field 3
    except (OSError, IndexError, ValueError):  # no /proc, or a kernel that writes the line otherwise
        return None


@contextmanager
def on_one_cpu(enabled: bool = True) -> Iterator[None]:
    """While inside, the calling thread — and every thread it starts meanwhile, which inherits it — runs on the
    CPU it is on now; its own CPUs are given back on leaving. Nothing where the platform cannot pin a thread or
    refuses to.

    Only the calling thread gets its CPUs back: a thread, a subprocess or a native pool (BLAS, a DAQ driver's) started
    inside keeps the pin for its whole life — start nothing long-lived inside that should use every CPU."""
    cpu = current_cpu() if enabled and hasattr(os, "sched_setaffinity") else None
    if cpu is None:
        yield
        return
    allowed = os.sched_getaffinity(0)  # 0: the calling thread alone (Linux sets a thread's affinity, not a process's)
    try:
        os.sched_setaffinity(0, {cpu})
    except OSError:  # the CPU was taken from this process meanwhile (cpuset): record as it was
        yield
        return
    try:
        yield
    finally:
        try:
            os.sched_setaffinity(0, allowed)
        except OSError:  # EINVAL: none of ``allowed`` is left to the process (its cpuset changed meanwhile)
            with suppress(OSError):  # every CPU, which the kernel narrows to the cpuset's
                os.sched_setaffinity(0, range(os.cpu_count() or 1))
