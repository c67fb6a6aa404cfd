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


def main() -> None:
    """Import the command line (numpy, scipy, h5py: seconds on a loaded machine), then run it; a Ctrl-C during
    the imports is the usual one line and exit 130."""
    for name in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ.setdefault(name, BLAS_THREADS)
    try:
        from acq.ui.cli import main as run_cli
    except KeyboardInterrupt:
        sys.stderr.write("acq: interrupted\n")
        sys.exit(130)
    run_cli()
