"""The ``acq`` console script and ``python -m acq``: a start-up that a Ctrl-C cannot turn into a traceback."""

from __future__ import annotations

import os
import sys

from acq.environment import pin_blas_threads
from acq.output_bytes import print_paths_as_bytes

#: BLAS threads of one acq process, set before numpy loads its BLAS (a variable the user set wins). The analysis
#: multiplies many small, wide matrices (the torque's spline solves): there a second BLAS thread only spins.
#: Measured on 2 cores, `acq analyze` of a 10 min session: 14.5 s wall either way, 12.4 s CPU with one thread and
#: 21.5 s with two; with the machine loaded (load 2.6) OpenBLAS's default threads took 71 s wall against 12.4 s.
#: After the blocked spline products (issue 17; bench/analysis_speed.py, load ≈ 14): 60 s session 1.16 s CPU with
#: one thread, 2.29 s with the default; 10 min 10.8 s against 26.3 s, and 70 s wall against 152 s. Batch and monitor
#: workers pin one thread as well (acq/monitoring/analysis_pool.py).
BLAS_THREADS = "1"
#: glibc's malloc gives freed memory at the top of its heap back to the system once more than its trim threshold lies
#: free (by default twice the largest array it has mapped, at most 64 MB) and maps arrays above its mmap threshold
#: afresh. The analysis allocates and frees arrays of a few MB by the dozen per 20 s chunk of a session, so that memory
#: went back and forth, each page faulted in again: a 60 s session took 44 000 page faults in a process's first analysis
#: and 18 700 in each further one (0.05 s of system time on 0.43 s of CPU). Arrays up to 32 MB (glibc's own ceiling
#: for its dynamic mmap threshold) from the heap and up to 256 MB of freed memory kept for the next ones: 22 000 faults
#: in the first analysis, none in the next (bench/analysis_speed.py; peak RSS of a 10 min session 507 MB instead of
#: 504). Measured again (bench/analysis_speed.py --repeat 3 --threads 1 --sizes 60, load 4): 60 s session 0.36–0.37 s
#: CPU with it, 0.39–0.40 s with glibc's defaults (--default-allocator). The price is memory kept while idle
#: (bench/idle_memory.py, 3 analyses, VmRSS afterwards): 60 s session 289 MB against 174 MB with the defaults (157 MB
#: with malloc_trim), 10 min 512 MB against 340 MB (318 MB); the peaks are the same (288 MB, 507–512 MB). So only a
#: one-shot ``acq analyze``/``acq record`` process sets it (mallopt, for itself alone: nothing is exported to its
#: children, so batch and monitor workers, the report drawer and ``--on-alarm`` commands run with glibc's defaults),
#: never the long-running ``acq monitor``; and not at all when the user tuned malloc (GLIBC_TUNABLES glibc.malloc.*,
#: or a MALLOC_* variable): a mallopt would override their setting. Other C libraries read neither.
MALLOPT_SETTINGS = ((-3, 32 << 20), (-1, 256 << 20))  # (glibc's M_MMAP_THRESHOLD, bytes), (M_TRIM_THRESHOLD, bytes)
#: Commands whose process runs once and ends: they keep freed memory (:func:`keep_freed_memory`).
ONE_SHOT_COMMANDS = ("analyze", "record")

def user_tuned_malloc() -> bool:
    """Whether the user set glibc's malloc parameters (GLIBC_TUNABLES glibc.malloc.*, or a MALLOC_* variable)."""
    return "glibc.malloc" in os.environ.get("GLIBC_TUNABLES", "") or any(name.startswith("MALLOC_")
                                                                          for name in os.environ)


def keep_freed_memory() -> bool:
    """:data:`MALLOPT_SETTINGS` into this process's allocator (glibc: mallopt), unless the user tuned malloc; return
    whether they were set. Child processes are not affected."""
    if not sys.platform.startswith("linux") or user_tuned_malloc():
        return False
    import ctypes

    try:
        mallopt = ctypes.CDLL(None).mallopt
    except (OSError, AttributeError):  # no C library symbols to look up, or no mallopt
        return False
    return all(mallopt(param, value) == 1 for param, value in MALLOPT_SETTINGS)


def main() -> None:
    """Import the command line (numpy, scipy, h5py: seconds on a loaded machine), then run it; a Ctrl-C during
    the imports is the usual one line and exit 130."""
    pin_blas_threads(BLAS_THREADS)
    print_paths_as_bytes()
    if sys.argv[1:2] and sys.argv[1] in ONE_SHOT_COMMANDS:  # the command line's only options come after its command
        keep_freed_memory()
    try:
        from acq.ui.cli import main as run_cli
        run_cli()  # its own Ctrl-C handling begins a few steps in: a Ctrl-C before it is caught here too
    except KeyboardInterrupt:
        sys.stderr.write("acq: interrupted\n")
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(130)  # not through the interpreter's teardown, where a second signal kills without a word
