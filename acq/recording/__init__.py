"""Record a session: the recorder, the session file it writes (``layout.py`` describes the HDF5 layout; ``writer.py``
writes it, ``reader.py`` reads it into a ``session.Session`` (``commits.py``: what was committed), ``repair.py``
rewrites a killed one: the only code that knows it), safe reads of damaged files, atomic writes and disk-full
handling, and what a session holds in numbers.
"""
