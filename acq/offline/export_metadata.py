"""The metadata ``acq export`` writes beside its CSV pair, so ``acq import`` restores the session's history.

``<stem>.session.json`` holds what the CSV columns cannot: the session's id, joint, start time,
operator, tags, the bench and profile as used, where the data came from, whether both files'
time columns are arrival stamps on one host clock, and the session's status, stop reason and the
spans it could not read (``damage``: an export of a damaged session's intact part). It names each
CSV with its SHA-256, so an import recognises the pair it describes: a file changed since export is
not that pair, and its metadata is not used (the import says so).
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable
from dataclasses import dataclass, fields
from datetime import datetime
from pathlib import Path
from typing import Annotated, Any

from pydantic import AfterValidator, BaseModel, ConfigDict, StrictStr, ValidationError, field_validator

from acq import __version__
from acq.config import validate
from acq.offline.analyze import sha256_of
from acq.recording.layout import Status, utc_now_iso
from acq.recording.root_attrs import not_utf8, shown
from acq.recording.session import Session, SessionHistory
from acqcore.errors import ConfigError
from drivers.config import Bench, Profile

FORMAT = "acq-export-metadata"
FORMAT_VERSION = 1
CURRENT_SUFFIX = ".current.csv"


@dataclass(frozen=True)
class ExportMetadata(SessionHistory):
    """A session's history as exported (:class:`~acq.recording.session.SessionHistory`: identity, start time,
    tags, origin, host clock), with the configs as used.

    Attributes
    ----------
    path : Path
        The metadata file read.
    bench_json, profile_json : str
        The bench and profile as used, JSON (``null``: a passive recording, acq commanded no motion).
    status, stop_reason : str
        The exported session's (``"complete"``, ``""`` in metadata written before they were recorded).
    damage : tuple of str
        The spans the exported session could not read, so the files do not hold ("current: samples 102 400–255 999
        unreadable").
    """

    path: Path
    bench_json: str
    profile_json: str
    status: str = "complete"
    stop_reason: str = ""
    damage: tuple[str, ...] = ()

    def bench(self) -> Bench:
        """The bench as used; a malformed one is a ConfigError naming this file and the key."""
        return validate(Bench, json.loads(self.bench_json), f"{self.path}: bench")

    def profile(self) -> Profile | None:
        """The profile as executed; None for a passive recording (the machine moved the joint, acq commanded none)."""
        doc = json.loads(self.profile_json)
        return None if doc is None else validate(Profile, doc, f"{self.path}: profile")

    def incomplete(self) -> tuple[Status, str | None]:
        """The status a session imported from the files gets, and why it is not ``complete`` (None when it is).

        The exported session's ``interrupted`` or ``failed`` is kept; its intact part only (damaged, or exported
        while ``recording``) is ``interrupted``, as :func:`acq.recording.repair.repair` marks such a session.
        """
        why = []
        if self.status == "recording":
            why.append("the exported session was still recording (status recording): the files hold what was stored")
        elif self.status not in ("", "complete"):
            why.append(f"the exported session's status: {self.status}"
                       + (f" ({self.stop_reason})" if self.stop_reason else ""))
        if self.damage:
            why.append("the exported session was damaged, the files hold its intact part only: "
                       + "; ".join(self.damage))
        if not why:
            return "complete", None
        return ("failed" if self.status == "failed" else "interrupted"), "; ".join(why)


def metadata_path(current_path: Path) -> Path | None:
    """``<stem>.session.json`` beside a current file named ``<stem>.current.csv`` (None for other names)."""
    name = current_path.name
    if not name.endswith(CURRENT_SUFFIX):
        return None
    return current_path.with_name(name[: -len(CURRENT_SUFFIX)] + ".session.json")


def metadata_text(session: Session, current: tuple[str, str], encoder: tuple[str, str]) -> str:
    """The metadata document (JSON) of ``session`` exported to the CSV pair ``current`` and ``encoder``, each
    (file name, SHA-256 hex)."""
    meta = session.meta
    doc = {
        "format": FORMAT, "format_version": FORMAT_VERSION, "exported_utc": utc_now_iso(), "acq_version": __version__,
        **{f.name: getattr(meta, f.name) for f in fields(SessionHistory)},
        "bench": session.bench.model_dump(mode="json"),
        "profile": session.profile.model_dump(mode="json") if session.profile is not None else None,
        "status": session.status, "stop_reason": session.meta.stop_reason, "damage": list(session.damage),
        "files": {"current": {"name": current[0], "sha256": current[1]},
                  "encoder": {"name": encoder[0], "sha256": encoder[1]}},
    }
    return json.dumps(doc, indent=1) + "\n"


def read_metadata(current_path: Path, encoder_path: Path, digest: Callable[[Path], str] = sha256_of,
                  ) -> tuple[ExportMetadata | None, str | None]:
    """The metadata beside an exported pair, if there is one and it describes these two files (their SHA-256 by
    ``digest``: the importer passes one that keeps what it computed, so no file is hashed twice).

    Returns
    -------
    metadata : ExportMetadata or None
        None when there is no metadata file, or it describes other files.
    warning : str or None
        Why a metadata file that is there was not used.

    Raises
    ------
    ConfigError
        The metadata file is there but unreadable or malformed (file and key named).
    """
    path = metadata_path(current_path)
    if path is None or not path.exists():
        return None, None
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as e:
        raise ConfigError(f"{path}: not readable as acq export metadata ({e})") from None
    if not isinstance(doc, dict) or doc.get("format") != FORMAT:
        raise ConfigError(f"{path}: format: not {FORMAT!r}")
    bad = _not_utf8(doc)
    if bad is not None:
        raise ConfigError(f"{path}: {bad[0]} = {shown(bad[1])}: not UTF-8 text")
    try:
        read = _Document.model_validate(doc)
    except ValidationError as e:
        raise ConfigError(f"{path}: {_one_line(e, doc)}") from None
    for role, given in (("current", current_path), ("encoder", encoder_path)):
        if getattr(read.files, role).sha256 != digest(given):
            return None, (f"{path.name} describes another {role} file than {given.name} (SHA-256 differs): "
                          "its metadata is not used, the time columns are not taken as one host clock")
    history = {f.name: getattr(read, f.name) for f in fields(SessionHistory)}
    configs = {"bench_json": json.dumps(read.bench), "profile_json": json.dumps(read.profile)}
    return ExportMetadata(**history, **configs, path=path,
                          status=read.status, stop_reason=read.stop_reason, damage=tuple(read.damage)), None


def _not_utf8(node: Any, key: str = "") -> tuple[str, str] | None:
    """The first text of the document (a key or a value) that is not UTF-8, with its key path ("tags.robot"), or
    None: JSON's ``\\udcc6`` escape reads as a lone surrogate (an export of before acq checked a session's
    attributes wrote one from a damaged byte), which no session attribute may hold."""
    items = node.items() if isinstance(node, dict) else enumerate(node) if isinstance(node, list) else ()
    for name, value in items:
        where = f"{key}.{name}" if key else str(name)
        if not_utf8(name):
            return where, str(name)
        if not_utf8(value):
            return where, value
        found = _not_utf8(value, where)
        if found is not None:
            return found
    return None


def _tag_value(value: Any) -> Any:
    """A tag's value as the session stores it: a text or a finite number (an int stays int: ``monitor_window``;
    NaN or Infinity, which Python's JSON reader takes, would be written back as invalid JSON, as ``--tag`` refuses)."""
    if isinstance(value, bool) or not isinstance(value, str | int | float):
        raise ValueError("a tag's value must be a text or a number")
    if isinstance(value, float) and not math.isfinite(value):
        raise ValueError("a tag's number must be finite")
    return value


class _File(BaseModel):
    name: StrictStr
    sha256: StrictStr


class _Files(BaseModel):
    current: _File
    encoder: _File


class _Document(BaseModel):
    """The metadata document as :func:`metadata_text` writes it, strictly typed: a value of another type is named
    (``bool("no")`` would have claimed one host clock, ``str(None)`` a session id "None")."""

    model_config = ConfigDict(strict=True, extra="ignore")  # format, format_version, exported_utc, acq_version: checked
    # by read_metadata or only informative
    session_id: StrictStr | None
    joint: StrictStr | None
    created_utc: StrictStr | None
    operator: StrictStr = ""
    origin: dict[str, Any]
    tags: dict[str, Annotated[Any, AfterValidator(_tag_value)]]
    host_clock_shared: bool
    bench: dict[str, Any]  # validated as a Bench when used (ExportMetadata.bench): --bench may replace it
    profile: dict[str, Any] | None
    status: StrictStr = "complete"
    stop_reason: StrictStr = ""
    damage: list[StrictStr] = []
    files: _Files

    @field_validator("created_utc")
    @classmethod
    def _iso_time(cls, text: str | None) -> str | None:
        if text is not None:
            try:
                datetime.fromisoformat(text)
            except ValueError:
                raise ValueError("not an ISO 8601 time (e.g. 2026-11-20T10:15:03+00:00)") from None
        return text


def _one_line(error: ValidationError, doc: dict[str, Any]) -> str:
    """The first error of the document in one line, ``key = value: what`` (``key: missing``; a value longer than a
    line is left out), the key path as far as the document holds it."""
    first = error.errors()[0]
    keys: list[str] = []
    node: Any = doc
    for part in first["loc"]:
        if not isinstance(node, dict) or part not in node:
            break
        keys.append(str(part))
        node = node[part]
    key = ".".join(keys) or "(top level)"
    if first["type"] == "missing":
        return f"{key}.{first['loc'][len(keys)]}: missing" if keys else f"{first['loc'][0]}: missing"
    what = str(first["ctx"]["error"]) if first["type"] == "value_error" else (  # not "… or instance of _Files"
        first["msg"].lower().replace("input should be", "must be").split(" or instance of ")[0])
    shown = json.dumps(node)
    return f"{key} = {shown}: {what}" if len(shown) <= 60 else f"{key}: {what}"
