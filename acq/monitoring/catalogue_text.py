"""Text the catalogue stores that UTF-8 cannot carry: a path whose bytes are not UTF-8.

A path is bytes on POSIX; Python reads one that is not UTF-8 (a Latin-1 ``Prüfstand`` folder from a Windows USB
stick) with its other bytes as lone surrogates (``surrogateescape``), which neither SQLite's nor PostgreSQL's text
takes. Such text is stored as its bytes percent-encoded after ``file://``: for an absolute path that is its file URI
(RFC 8089). The catalogue's paths are otherwise stored absolute, beginning with ``/``, so the two forms never meet and
a stored path reads back to the very bytes (:func:`from_db`). Text UTF-8 can carry is stored as it is: a catalogue
of earlier versions reads as before.
"""

from __future__ import annotations

import os
from urllib.parse import quote_from_bytes, unquote_to_bytes

#: What begins the stored form of text UTF-8 cannot carry.
_ENCODED = "file://"


def to_db(value: object) -> object:
    """``value`` as the catalogue stores it: text UTF-8 cannot carry percent-encoded (see the module), anything else
    as it is."""
    if not isinstance(value, str):
        return value
    try:
        value.encode("utf-8")
    except UnicodeEncodeError:
        return _ENCODED + quote_from_bytes(os.fsencode(value), safe="/:")
    return value


def from_db(text: str) -> str:
    """A stored path back as Python's path text (the bytes it was, surrogate-escaped)."""
    if text.startswith(_ENCODED):
        return os.fsdecode(unquote_to_bytes(text[len(_ENCODED):]))
    return text


def readable(text: str | None) -> str | None:
    """A message (an error naming such a path) as UTF-8 can carry it: its lone surrogates written ``\\udcfc``, as
    Python's standard error shows them; it is read, never opened."""
    return None if text is None else text.encode("utf-8", "backslashreplace").decode("utf-8")
