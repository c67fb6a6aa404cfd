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
from collections.abc import Callable
from dataclasses import dataclass, fields
from pathlib import Path

from acq import __version__
from acq.offline.analyze import sha256_of
from acq.recording.layout import Status, utc_now_iso
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
                              bench_json=json.dumps(doc["bench"]), profile_json=json.dumps(doc["profile"]),
                              status=str(doc.get("status", "complete")), stop_reason=str(doc.get("stop_reason", "")),
                              damage=tuple(str(line) for line in doc.get("damage", [])))
    except (KeyError, TypeError) as e:
        raise ConfigError(f"{path}: key {e}: missing or malformed") from None
    return meta, None
