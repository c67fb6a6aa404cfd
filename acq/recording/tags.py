"""Session tags (``pose=home``, ``payload_kg=2.5``): read from ``KEY=VALUE`` texts and matched against a session's.

The recorder and the importer store them in the session; the catalogue's readers (trend, fleet) select sessions
by them.
"""

from __future__ import annotations

import math
import re
import unicodedata
from collections.abc import Iterable
from typing import Any

from acq.recording.root_attrs import escaped, shown
from acqcore.errors import ConfigError


#: A tag key: letters, digits, ``_``, ``.`` and ``-`` (no spaces, no ``=``).
_KEY = re.compile(r"[\w.-]+")
#: A number's canonical spelling: an optional minus, an integer part without leading zeros, an optional fraction and
#: exponent (2.5, -3, 31, 1e-3). Anything else that float() would also read (007, +5, .5, 5., 1_000) stays text: a
#: serial number or code keeps its spelling.
_NUMBER = re.compile(r"-?(?:0|[1-9][0-9]*)(?:\.[0-9]+)?(?:[eE][-+]?[0-9]+)?", re.ASCII)


def parse_tags(texts: Iterable[str]) -> dict[str, str | float]:
    """``KEY=VALUE`` texts as a tag dict; a value spelt as a number (:data:`_NUMBER`) becomes a float
    (``payload_kg=2.5`` → 2.5), any other stays text (``serial=007`` → "007").

    Raises :class:`ConfigError` naming the tag for a text that is not UTF-8 or holds a control character
    (:func:`require_plain_text`), without ``=``, a key with other than letters, digits, ``_ . -``, an empty value, a
    number's spelling beyond a float's range (1e999: inf, a tag that could never be matched, and not JSON) and a key
    given twice.
    """
    tags: dict[str, str | float] = {}
    given: dict[str, str] = {}
    for text in texts:
        require_plain_text("--tag", text)  # in a key or a value (a value went as it was into the catalogue and terminals)
        key, sep, value = (part.strip() for part in text.partition("="))
        if not sep or not key:
            raise ConfigError(f"--tag {text}: must be KEY=VALUE, e.g. payload_kg=2.5")
        if not _KEY.fullmatch(key):
            raise ConfigError(f"--tag {text}: the key {key!r} may hold only letters, digits, _ . - (no spaces)")
        if not value:
            raise ConfigError(f"--tag {text}: the value is empty — give KEY=VALUE, e.g. pose=home")
        if key in given:
            raise ConfigError(f"--tag {text}: {key} is given twice ({given[key]}, {text}) — give each key once")
        given[key] = text
        tags[key] = _value(text, value)
    return tags


def require_plain_text(option: str, text: str) -> str:
    """``text`` as given for ``option`` ("--operator", "--tag"), refused (:class:`ConfigError`, naming the option and
    the byte or character) before anything is recorded when it holds
    - a byte that is not UTF-8: Python reads such a command-line byte as a lone surrogate (a shell or terminal in
      Latin-1 sends "é" as the one byte 0xe9), which a session file, its JSON and the catalogue cannot hold as text —
      not stored escaped nor met by HDF5 as a codec error;
    - a control character (ESC, a line break): the trend and the info print such text to a terminal, which would act
      on it."""
    bad = next((c for c in text if "\udc80" <= c <= "\udcff"), None)
    if bad is not None:
        raise ConfigError(f"{option} {shown(text)}: byte 0x{ord(bad) - 0xDC00:02x} is not UTF-8 (a shell or terminal "
                          "in Latin-1 sends é as 0xe9) — give the text in UTF-8")
    control = next((c for c in text if unicodedata.category(c) == "Cc"), None)
    if control is not None:
        raise ConfigError(f"{option} {shown(text)}: holds the control character {escaped(control)} — give it "
                          "without control characters (a terminal that prints it would act on them)")
    return text


def _value(text: str, value: str) -> str | float:
    """A tag's value: a float when spelt as a number, else the text (``nan``, ``Inf`` too: words, as ``operator=Nan``
    may be); a number's spelling that does not fit a float (1e999) is refused."""
    if not _NUMBER.fullmatch(value):
        return value
    number = float(value)
    if not math.isfinite(number):
        raise ConfigError(f"--tag {text}: {value} is not a finite number (a tag's number must be finite)")
    return number


def tag_number(value: Any) -> float | None:
    """The number a tag value stands for, None for a text that is no number.

    A stored number, or a text any spelling of a finite number (``007``, ``+5``, ``1_000``): acq before session 11
    stored every such spelling as the number (``robot=007`` → 7.0), so the text given today and the number stored
    then are one tag — the one rule :func:`tags_match` and :func:`tag_group` keep.
    """
    if isinstance(value, int | float) and not isinstance(value, bool):
        return float(value)
    try:
        number = float(str(value))
    except ValueError:
        return None
    return number if math.isfinite(number) else None


def tag_group(value: Any) -> str | float:
    """A key under which a tag's values that are one tag (:func:`tag_number`: 7.0 stored by earlier acq, "007"
    today) group together; any other value groups by its text."""
    number = tag_number(value)
    return str(value) if number is None else number


def tags_match(tags: dict[str, Any], wanted: dict[str, str | float]) -> bool:
    """True when ``tags`` has every wanted key with an equal value: numbers compared as numbers, and a stored number
    also matched by a text spelling its value another way (``007`` finds the 7.0 earlier acq stored for it,
    :func:`tag_number`); a stored text matches only its own spelling."""
    def same(have: Any, want: str | float) -> bool:
        number = tag_number(want)
        if number is not None and isinstance(have, int | float) and not isinstance(have, bool):
            return math.isclose(have, number, rel_tol=1e-9)
        return str(have) == str(want)

    return all(key in tags and same(tags[key], want) for key, want in wanted.items())
