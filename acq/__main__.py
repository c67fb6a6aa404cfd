"""``python -m acq`` runs the command line."""

from acq.cli import main

main()
