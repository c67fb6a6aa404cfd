"""The ``acq`` console script and ``python -m acq``: a start-up that a Ctrl-C cannot turn into a traceback."""

from __future__ import annotations

import sys


def main() -> None:
    """Import the command line (numpy, scipy, h5py: seconds on a loaded machine), then run it; a Ctrl-C during
    the imports is the usual one line and exit 130."""
    try:
        from acq.cli import main as run_cli
    except KeyboardInterrupt:
        sys.stderr.write("acq: interrupted\n")
        sys.exit(130)
    run_cli()
