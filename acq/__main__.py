"""``python -m acq`` runs the command line."""

from acq.entry import main

main()
