"""Session tags (``pose=home``, ``payload_kg=2.5``): read from ``KEY=VALUE`` texts and matched against a session's.

The recorder and the importer store them in the session; the catalogue's readers (trend, fleet) select sessions
by them.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from typing import Any

from acqcore.errors import ConfigError


def parse_tags(texts: Iterable[str]) -> dict[str, str | float]:
    """``KEY=VALUE`` texts as a tag dict; numeric values become floats (``payload_kg=2.5`` → 2.5).

    Raises :class:`ConfigError` naming a text without ``=`` or with an empty key.
    """
    tags: dict[str, str | float] = {}
    for text in texts:
        key, sep, value = text.partition("=")
        if not sep or not key.strip():
            raise ConfigError(f"--tag {text}: must be KEY=VALUE, e.g. payload_kg=2.5")
        try:
            tags[key.strip()] = float(value)
        except ValueError:
            tags[key.strip()] = value.strip()
    return tags


def tags_match(tags: dict[str, Any], wanted: dict[str, str | float]) -> bool:
    """True when ``tags`` has every wanted key with an equal value (numbers compared as numbers)."""
    def same(have: Any, want: str | float) -> bool:
        if isinstance(want, float) and isinstance(have, int | float):
            return math.isclose(have, want, rel_tol=1e-9)
        return str(have) == str(want)

    return all(key in tags and same(tags[key], want) for key, want in wanted.items())
