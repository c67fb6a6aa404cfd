"""The session file's root attributes checked as :func:`acq.recording.reader.load` reads them, so every command
refuses a damaged or malformed one with the same line naming the file, the attribute and its value.

A byte of a text attribute that is not UTF-8 (a flipped bit on disk) comes back from h5py as a lone surrogate
(``'j\\udcc6int1'``), which any later write of it (the catalogue, JSON, a terminal) fails to encode; a value of the
right kind that makes no sense (status ``bogus``, a ``created_utc`` that is no time, ``tags_json`` that is a JSON
list, ``host_clock_shared = 'maybe'``) would be shown or used as it is.
"""

from __future__ import annotations

import json
from datetime import datetime
from pathlib import Path
from typing import Annotated, Any

from pydantic import AfterValidator, BaseModel, ConfigDict, StrictBool, StrictInt, StrictStr, ValidationError

from acq.recording.layout import NO_COUNT, Status
from acqcore.errors import ConfigError

#: Characters of a bad value shown either side of its first fault (a JSON attribute holds kilobytes).
SHOWN_AROUND = 30


def shown(value: Any, at: int | None = None) -> str:
    """``value`` for a one-line message: quoted, a byte that is not UTF-8 as ``\\xc6``, a text longer than 2 ×
    :data:`SHOWN_AROUND` cut with ``…`` around character ``at`` (default: its first such byte, else its start)."""
    if not isinstance(value, str):
        return repr(value)
    bad = at if at is not None else next((i for i, c in enumerate(value) if "\udc80" <= c <= "\udcff"), 0)
    lo, hi = (0, len(value)) if len(value) <= 2 * SHOWN_AROUND else (max(bad - SHOWN_AROUND, 0), bad + SHOWN_AROUND)
    return f"'{'…' if lo else ''}{escaped(value[lo:hi])}{'…' if hi < len(value) else ''}'"


def escaped(text: str, keep: str = "") -> str:
    """``text`` safe to print: a byte that is not UTF-8 as ``\\xc6``, any other character that is not printable
    (a control character: ESC would start a terminal's escape sequence) as its Python escape (``\\x1b``), those in
    ``keep`` (a caption's line breaks) as they are."""
    return "".join(f"\\x{ord(c) - 0xDC00:02x}" if "\udc80" <= c <= "\udcff"
                   else c if c.isprintable() or c in keep else c.encode("unicode_escape").decode("ascii") for c in text)


def not_utf8(value: Any) -> bool:
    """A text h5py decoded with surrogate escapes: it held bytes that are not UTF-8."""
    if not isinstance(value, str):
        return False
    try:
        value.encode("utf-8")
    except UnicodeEncodeError:
        return True
    return False


def _iso_time(text: str) -> str:
    try:
        datetime.fromisoformat(text)
    except ValueError:
        raise ValueError("not an ISO 8601 time (e.g. 2026-11-20T10:15:03+00:00)") from None
    return text


def _iso_time_or_empty(text: str) -> str:
    return text if text == "" else _iso_time(text)


def _json_object(text: str) -> str:
    try:
        doc = json.loads(text)
    except ValueError:
        raise ValueError("not JSON") from None
    if not isinstance(doc, dict):
        raise ValueError(f"not a JSON object but a {type(doc).__name__}")
    return text


class RootAttributes(BaseModel):
    """The root attributes that say what a session is (:mod:`acq.recording.layout`), strictly typed; each may be
    absent (older files; a cut copy loses the footer's strings). The configs (``bench_json``, ``profile_json``) are
    validated as a :class:`~drivers.config.Bench` and :class:`~drivers.config.Profile` by the reader."""

    model_config = ConfigDict(strict=True, extra="allow")
    session_id: StrictStr | None = None
    joint: StrictStr | None = None
    operator: StrictStr = ""
    acq_version: StrictStr = ""
    created_utc: Annotated[StrictStr, AfterValidator(_iso_time)] | None = None
    stopped_utc: Annotated[StrictStr, AfterValidator(_iso_time_or_empty)] = ""
    status: Status | None = None
    stop_reason: StrictStr = ""
    tags_json: Annotated[StrictStr, AfterValidator(_json_object)] = "{}"
    origin_json: Annotated[StrictStr, AfterValidator(_json_object)] = "{}"
    host_clock_shared: StrictBool | None = None
    host_monotonic_ns_at_start: StrictInt | None = None
    current_samples: StrictInt = NO_COUNT
    encoder_samples: StrictInt = NO_COUNT


def check_root_attributes(path: Path, attrs: dict[str, Any]) -> None:
    """Raise :class:`ConfigError` naming ``path``, the first bad attribute and its value: a text that is not UTF-8
    (any attribute: "damaged"), or a value :class:`RootAttributes` refuses ("malformed session")."""
    for name, value in attrs.items():
        check_text(path, name, value)
    try:
        RootAttributes.model_validate(attrs)
    except ValidationError as e:
        first = e.errors()[0]
        name = str(first["loc"][0])
        what = (str(first["ctx"]["error"]) if first["type"] == "value_error"
                else first["msg"].replace("Input should be", "must be"))
        raise ConfigError(f"{path}: malformed session: attribute {name} = {shown(attrs[name])}: {what}") from None


def check_text(path: Path, name: str, value: Any) -> None:
    """Raise :class:`ConfigError` when the attribute ``name`` (``current/device``: a group's) is a text that is not
    UTF-8: one line naming ``path``, the attribute and its value."""
    if not_utf8(value):
        raise ConfigError(f"{path}: damaged: attribute {name} = {shown(value)}: not UTF-8 text")
