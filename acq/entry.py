"""The ``acq`` console script and ``python -m acq``: a start-up that a Ctrl-C cannot turn into a traceback."""

from __future__ import annotations

import os
import sys

#: BLAS threads of one acq process, set before numpy loads its BLAS (a variable the user set wins). The analysis
#: multiplies many small, wide matrices (the torque's spline solves): there a second BLAS thread only spins.
#: Measured on 2 cores, `acq analyze` of a 10 min session: 14.5 s wall either way, 12.4 s CPU with one thread and
#: 21.5 s with two; with the machine loaded (load 2.6) OpenBLAS's default threads took 71 s wall against 12.4 s.
#: After the blocked spline products (issue 17; bench/analysis_speed.py, load ≈ 14): 60 s session 1.16 s CPU with
#: one thread, 2.29 s with the default; 10 min 10.8 s against 26.3 s, and 70 s wall against 152 s. Batch and monitor
#: workers pin one thread as well (acq/monitoring/batch.py).
BLAS_THREADS = "1"
#: glibc's malloc gives freed memory at the top of its heap back to the system once more than its trim threshold lies
#: free (by default twice the largest array it has mapped, at most 64 MB) and maps arrays above its mmap threshold
#: afresh. The analysis allocates and frees arrays of a few MB by the dozen per 20 s chunk of a session, so that memory
#: went back and forth, each page faulted in again: a 60 s session took 44 000 page faults in a process's first analysis
#: and 18 700 in each further one (0.05 s of system time on 0.43 s of CPU). Arrays up to 32 MB (glibc's own ceiling
#: for its dynamic mmap threshold) from the heap and up to 256 MB of freed memory kept for the next ones: 22 000 faults
#: in the first analysis, none in the next (bench/analysis_speed.py; peak RSS of a 10 min session 507 MB instead of
#: 504). Set for this process (mallopt) and, through the environment, for its children (batch and monitor workers);
#: a variable the user set wins. Other C libraries read neither.
MALLOC_SETTINGS = {"MALLOC_MMAP_THRESHOLD_": str(32 << 20), "MALLOC_TRIM_THRESHOLD_": str(256 << 20)}
_MALLOPT_PARAMS = {"MALLOC_MMAP_THRESHOLD_": -3, "MALLOC_TRIM_THRESHOLD_": -1}  # glibc's M_MMAP_/M_TRIM_THRESHOLD


def keep_freed_memory() -> None:
    """:data:`MALLOC_SETTINGS` into the environment (unless set) and, on glibc, into this process's allocator."""
    for name, value in MALLOC_SETTINGS.items():
        os.environ.setdefault(name, value)
    if not sys.platform.startswith("linux"):
        return
    import ctypes

    try:
        mallopt = ctypes.CDLL(None).mallopt
    except (OSError, AttributeError):  # no C library symbols to look up, or no mallopt
        return
    for name, param in _MALLOPT_PARAMS.items():
        value = os.environ[name]
        if value.isdigit():
            mallopt(param, int(value))


def main() -> None:
    """Import the command line (numpy, scipy, h5py: seconds on a loaded machine), then run it; a Ctrl-C during
    the imports is the usual one line and exit 130."""
    for name in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ.setdefault(name, BLAS_THREADS)
    keep_freed_memory()
    try:
        from acq.ui.cli import main as run_cli
    except KeyboardInterrupt:
        sys.stderr.write("acq: interrupted\n")
        sys.exit(130)
    run_cli()
