"""acq's standard output and error print a path as the bytes it is.

A path is bytes on POSIX; Python reads one that is not UTF-8 (a Latin-1 ``Prüfstand`` folder) with those bytes as
lone surrogates. Under a UTF-8 locale (``LANG=en_US.UTF-8``) Python's standard output refuses them, so printing
``result: <path>`` ended in a UnicodeEncodeError; its standard error wrote ``Pr\\udcfcfstand``. Both now write the
bytes the path holds, as ``ls`` and ``find`` do (the terminal shows what it shows for a Latin-1 name, a pipe gets the
path a script can open); a character the stream's encoding cannot carry otherwise is written ``\\u…``, never an error.
"""

from __future__ import annotations

import codecs
import io
import sys

#: The name of the error handler (:func:`_path_bytes`) the streams use.
HANDLER = "acq-path-bytes"


def _path_bytes(error: UnicodeError) -> tuple[bytes, int]:
    """A path's escaped byte (U+DC80…U+DCFF) back as that byte; any other character it cannot encode as ``\\u…``."""
    if not isinstance(error, UnicodeEncodeError):
        raise error
    part = error.object[error.start:error.end]
    return b"".join(bytes([ord(c) - 0xDC00]) if "\udc80" <= c <= "\udcff" else c.encode("ascii", "backslashreplace")
                    for c in part), error.end


def print_paths_as_bytes() -> None:
    """Standard output and error write a path's bytes (:func:`_path_bytes`) instead of failing or escaping them."""
    codecs.register_error(HANDLER, _path_bytes)
    for stream in (sys.stdout, sys.stderr):
        if isinstance(stream, io.TextIOWrapper):
            stream.reconfigure(errors=HANDLER)
