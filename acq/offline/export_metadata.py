"""The metadata ``acq export`` writes beside its CSV pair, so ``acq import`` restores the session's history.

``<stem>.session.json`` holds what the CSV columns cannot: the session's id, joint, start time,
operator, tags, the bench and profile as used, where the data came from, and whether both files'
time columns are arrival stamps on one host clock. It names each CSV with its SHA-256, so an import
recognises the pair it describes: a file changed since export is not that pair, and its metadata is
not used (the import says so).
"""

from __future__ import annotations

import json
from collections.abc import Callable
from dataclasses import dataclass, fields
from pathlib import Path

from acq import __version__
from acq.offline.analyze import sha256_of
from acq.recording.layout import utc_now_iso
from acq.recording.session import Session, SessionHistory
from acqcore.errors import ConfigError

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
        The bench and profile as used, JSON.
    """

    path: Path
    bench_json: str
    profile_json: str


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
    try:
        files = {role: doc["files"][role] for role in ("current", "encoder")}
        for role, given in (("current", current_path), ("encoder", encoder_path)):
            if files[role]["sha256"] != digest(given):
                return None, (f"{path.name} describes another {role} file than {given.name} (SHA-256 differs): "
                              "its metadata is not used, the time columns are not taken as one host clock")
        meta = ExportMetadata(session_id=str(doc["session_id"]), joint=str(doc["joint"]),
                              created_utc=str(doc["created_utc"]), operator=str(doc.get("operator", "")),
                              origin=dict(doc["origin"]), tags=dict(doc["tags"]),
                              host_clock_shared=bool(doc["host_clock_shared"]), path=path,
                              bench_json=json.dumps(doc["bench"]), profile_json=json.dumps(doc["profile"]))
    except (KeyError, TypeError) as e:
        raise ConfigError(f"{path}: key {e}: missing or malformed") from None
    return meta, None
