"""Record a session: the recorder, the session file it writes (``session.py``, the only code that knows
the HDF5 layout), safe reads of damaged files, atomic writes and disk-full handling, and what a session
holds in numbers.
"""
