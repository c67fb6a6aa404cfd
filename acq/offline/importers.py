"""``acq import``: a current file (CSV or TDMS) and an encoder CSV recorded by other tools become a session.

The files are read and checked by :mod:`acq.offline.import_files`. Beside a pair written by ``acq export``
its metadata (:mod:`acq.offline.export_metadata`) restores the session's id, joint, start time, tags, bench
and profile; otherwise ``--started`` (or a TDMS ``wf_start_time``) dates the recording. Without a profile (an
exported passive recording, or files of a bench whose machine moves the joint) the session is passive, as
``acq record`` stores one: profile None.

Host stamps: the encoder file's ``t_s`` are stored uncorrected as ``host_ns``; the current's blocks
(0.1 s) are stamped with their last sample's time on the same axis. The two time columns are one
host clock only for a pair from ``acq export`` (its metadata says so) or with ``--same-clock``; the
session's ``host_clock_shared`` says which, and only then does the analysis let the stamps narrow its
clock search. Files from separate tools keep their time columns when they overlap; when they do not,
the current is shifted to start with the encoder. Every choice is written into the session's
``origin`` with the files' names and SHA-256.
"""

from __future__ import annotations

import contextlib
import hashlib
import uuid
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass
from datetime import UTC, datetime, timedelta
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa

from acq import __version__
from acq.config import with_joint
from acq.offline.analyze import sha256_of
from acq.offline.csvtable import file_bytes
from acq.offline.export_metadata import ExportMetadata, read_metadata
from acq.offline.import_files import (CurrentTable, EncoderTable, host_ns, read_current_csv, read_current_tdms,
                                      read_encoder_csv)
from acq.recording.writer import SessionWriter
from acq.recording.storage import WRITE_FAILURES, make_folders, replace_durably, storage_error
from drivers.base import CurrentSourceInfo, DriveInfo, EncoderBlock, StreamEvent
from drivers.config import Bench, Profile
from acqcore.errors import ConfigError, StorageError

BLOCK_S = 0.1


def _timeline(cur: CurrentTable, enc: EncoderTable, shared_by: str | None) -> tuple[float, str]:
    """Shift, s, that puts the current's file time on the encoder's, and what it rests on.

    ``shared_by`` names what says the two time columns are one host clock (None: separate tools).
    """
    c0, c1 = (float(x) for x in cur.time_s(cur.sample_index[[0, -1]]))
    e0, e1 = float(enc.t_s[0]), float(enc.t_s[-1])
    overlap = min(c1, e1) - max(c0, e0)
    overlapping = overlap >= 0.5 * min(c1 - c0, e1 - e0)
    if shared_by is not None:
        if not overlapping:
            raise ConfigError(f"{shared_by}: the files' time columns do not overlap (current {c0:.3f}–{c1:.3f} s, "
                              f"encoder {e0:.3f}–{e1:.3f} s), so they cannot be one host clock")
        return 0.0, (f"shared ({shared_by}): both files' time columns are stamps on one host clock; each current block "
                     "(0.1 s) is stamped with its last sample's time, without transfer latency")
    if overlapping:
        return 0.0, ("separate: the files come from separate tools (no acq export metadata, no --same-clock); their "
                     "time columns are stored as given but are not one host clock (the analysis aligns the streams "
                     "from the data alone)")
    shift = e0 - c0
    return shift, (f"separate: the files' time columns do not overlap; the current was shifted by {shift:+.6f} s to "
                   "start with the encoder, so host stamps carry no offset between the streams (the analysis "
                   "aligns them from the data)")


def _current_blocks(cur: CurrentTable, shift_s: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The block table of the current cut in blocks of ``BLOCK_S`` that never straddle a gap: each block's
    first DAQ sample index, sample count and host stamp (its last sample's time on the host timeline, ns)."""
    per_block = max(1, round(cur.rate_hz * BLOCK_S))
    bounds = [0, *(np.flatnonzero(np.diff(cur.sample_index) != 1) + 1), cur.sample_index.size]
    starts = np.concatenate([np.arange(a, b, per_block) for a, b in zip(bounds[:-1], bounds[1:])])
    ends = np.append(starts[1:], cur.sample_index.size)  # blocks are back to back: one ends where the next starts
    return cur.sample_index[starts], ends - starts, host_ns(cur.time_s(cur.sample_index[ends - 1]) + shift_s)


def _file_entry(role: str, path: Path, extra: dict[str, Any], sha256: Future[str] | None = None) -> dict[str, Any]:
    digest = sha256_of(path) if sha256 is None else sha256.result()
    return {"role": role, "name": path.name, "path": str(path.resolve()), "sha256": digest, **extra}


#: How far ``--started`` may lie ahead of this host's clock: a local time given without its zone is read as UTC, so
#: one east of Greenwich reads up to 14 h ahead (UTC+14, the largest offset in use).
STARTED_AHEAD_ALLOWED = timedelta(hours=14)


def parse_started(text: str) -> str:
    """``--started``: an ISO 8601 time (UTC when it names no zone) as the sessions' ``created_utc`` form."""
    try:
        when = datetime.fromisoformat(text)
    except ValueError:
        raise ConfigError(f"--started {text}: not an ISO 8601 time (e.g. 2026-11-20T10:15:03Z)") from None
    if when.tzinfo is None:
        when = when.replace(tzinfo=UTC)
    now = datetime.now(UTC)
    if when - now > STARTED_AHEAD_ALLOWED:
        raise ConfigError(f"--started {text}: after now ({now.isoformat(timespec='seconds')}): a recording cannot "
                          "start in the future — a typo in the year, or a local time with the wrong zone?")
    return when.astimezone(UTC).isoformat(timespec="seconds")


def _configs(meta: ExportMetadata | None, bench: Bench | None, profile: Profile | None, joint: str | None,
             current_path: Path, meta_warning: str | None = None) -> tuple[Bench, Profile | None]:
    """Bench and profile as given, else as used when the exported session was recorded; ``joint`` applied.
    ``meta_warning``: why metadata that is there was not used (it is then the reason a config is needed).

    The profile is None — a passive session, as ``acq record`` stores one — when the machine moved the joint: the
    exported session had none, or the bench says so (``[drive] motion = "external"``). As the recorder does, the
    bench's motion and the profile must agree: a profile the data did not have is never written."""
    profile_given = profile is not None
    if meta is not None:
        recorded = meta.profile()
        if profile is not None and recorded is None:
            raise ConfigError(f"--profile: {meta.path.name} says the exported session was recorded passively (profile "
                              "null: the machine's own controller moved the joint, acq commanded none) — leave out "
                              "--profile")
        if bench is not None and profile is None and bench.listens() != (recorded is None):
            was, want = (("recorded passively (no profile)", "external") if recorded is None
                         else ("commanded by acq (its profile is in the file)", "commanded"))
            raise ConfigError(f"--bench: [drive] motion = \"{bench.drive.motion}\", but {meta.path.name} says the "
                              f"exported session was {was} — give a bench with motion = \"{want}\", or leave out "
                              "--bench to use the bench as recorded")
        bench = bench or meta.bench()
        profile = profile or recorded
    why = meta_warning or (f"no acq export metadata beside {current_path.name}" if meta is None
                           else f"{meta.path.name} holds no profile")
    if bench is None:
        raise ConfigError(f"--bench: needed ({why})")
    if profile is None and not bench.listens():
        raise ConfigError(f"--profile: needed ({why}): give the profile acq commanded, or a --bench with [drive] "
                          "motion = \"external\" if the machine's own controller moved the joint (a passive import)")
    if profile is not None and bench.listens():
        if meta is not None and not profile_given:  # both from metadata no recorder writes (it refuses the pair)
            raise ConfigError(f"{meta.path.name}: the exported session has a profile, yet its bench has [drive] "
                              "motion = \"external\" (acq commands no motion there) — give --bench")
        raise ConfigError("--profile: the bench has [drive] motion = \"external\": the machine's own controller "
                          "moved the joint and acq commanded no motion — leave out --profile to import a passive "
                          "recording, or give a --bench that commands the motion")
    return with_joint(bench, joint), profile


def _start_time(started_utc: str | None, meta: ExportMetadata | None, cur: CurrentTable) -> tuple[str | None, str]:
    """When the recording started (ISO 8601, UTC; None: now) and what says so."""
    if started_utc:
        return started_utc, "--started"
    if meta is not None and meta.created_utc:
        return meta.created_utc, "acq export metadata"
    if cur.start_utc:
        return cur.start_utc, "TDMS wf_start_time"
    return None, "the time of import"


@dataclass(frozen=True)
class ImportResult:
    """Where the session went, and the warnings found on the way (also stored as events)."""

    path: Path
    warnings: list[str]


def import_session(current_path: Path, encoder_path: Path, bench: Bench | None, profile: Profile | None, out: Path,
                   current_channels: tuple[str, ...] = (), tags: dict[str, str | float] | None = None, *,
                   joint: str | None = None, same_clock: bool = False, started_utc: str | None = None) -> ImportResult:
    """Turn a current file (CSV or TDMS) and an encoder CSV into the session file ``out``.

    Every check runs before anything is written (``out``'s folder is made only then, if missing); the file
    is written under a temporary name and renamed at the end, so bad input never leaves a session file behind.

    Parameters
    ----------
    bench, profile : the configs; None takes them from the ``acq export`` metadata beside the files. Without
        metadata, profile None imports a passive recording (the bench's ``[drive] motion = "external"``).
    tags : tags, added to (and overriding) those the metadata restores.
    joint : joint name overriding the bench's.
    same_clock : the two files' ``t_s`` are stamps on one host clock (``--same-clock``).
    started_utc : when the recording started (ISO 8601, UTC); default from the metadata, a TDMS
        ``wf_start_time``, else the time of import.

    Raises
    ------
    ConfigError
        Bad input, one line naming the file, line (or channel/sample) and column.
    """
    _require_session_name(out)
    if out.exists():
        raise ConfigError(f"-o {out}: exists (not overwritten)")
    _require_folder_possible(out)
    for given in (current_path, encoder_path):  # a mistyped name before anything that looks beside it
        if not given.exists():
            raise ConfigError(f"{given}: no such file")
    # the configs first: a missing bench or bad metadata is one line at once, not after hashing the files
    known: dict[Path, str] = {}  # an exported pair's metadata check hashes the files the session records

    def digest(path: Path) -> str:
        if path not in known:
            known[path] = sha256_of(path)
        return known[path]

    meta, meta_warning = read_metadata(current_path, encoder_path, digest)
    bench, profile = _configs(meta, bench, profile, joint, current_path, meta_warning)
    # a CSV not hashed yet is read once into memory (if it fits one parse block): its SHA-256 is taken in a thread
    # from the very bytes that are parsed meanwhile (hashlib and Arrow release the GIL)
    data = {path: file_bytes(path) for path in (current_path, encoder_path)
            if path.suffix.lower() != ".tdms" and path not in known}
    with ThreadPoolExecutor(max_workers=1) as hashing:
        sha256 = {path: hashing.submit(digest, path) if data.get(path) is None else
                  hashing.submit(_sha256_hex, data[path]) for path in (current_path, encoder_path)}
        return _import(current_path, encoder_path, bench, profile, out, current_channels, tags, meta, meta_warning,
                       same_clock, started_utc, sha256, data)


def _require_session_name(out: Path) -> None:
    """Refuse an ``out`` not named ``*.h5``: a batch (``acq analyze FOLDER``) and so the catalogue and the trend
    see only ``*.h5`` files. ``-o imports/`` (a folder meant) reaches here as ``imports`` and would become a
    session file of that name, invisible to them."""
    if out.suffix != ".h5":
        example = out.with_suffix(".h5") if out.suffix else f"{out / 'session.h5'} or {out}.h5"
        raise ConfigError(f"-o {out}: a session file's name must end in .h5 (acq analyze FOLDER finds only *.h5), "
                          f"e.g. {example}")


def _require_folder_possible(out: Path) -> None:
    """Refuse ``out`` when a file stands where its folder (or one of the folders above it) must be: one line before
    the input files are read. A folder that does not exist yet is made when the session is written."""
    existing = next(folder for folder in out.parents if folder.exists())  # "." or "/" at the latest
    if not existing.is_dir():
        raise ConfigError(f"-o {out}: {existing} is a file, not a folder")


def _make_folder(out: Path) -> None:
    """Make the folder of the session file ``out`` (and those above it) if missing, as ``acq record --out`` and
    ``acq export --csv`` do; a folder the storage refuses is a failed write, any other failure bad input."""
    try:
        make_folders(out.parent)
    except OSError as e:
        if e.errno in WRITE_FAILURES:  # read-only, full, no permission
            raise storage_error(e, out.parent) from None
        raise ConfigError(f"-o {out}: cannot make its folder {out.parent} ({e.strerror or e})") from None


def _sha256_hex(data: pa.Buffer) -> str:
    """SHA-256 of bytes in memory, hex (:func:`acq.offline.analyze.sha256_of` of the file they were read from)."""
    return hashlib.sha256(data).hexdigest()


def _import(current_path: Path, encoder_path: Path, bench: Bench, profile: Profile | None, out: Path,
            current_channels: tuple[str, ...], tags: dict[str, str | float] | None, meta: ExportMetadata | None,
            meta_warning: str | None, same_clock: bool, started_utc: str | None,
            sha256: dict[Path, Future[str]], data: dict[Path, pa.Buffer | None]) -> ImportResult:
    """:func:`import_session` with the configs resolved, the files' SHA-256 under way and the bytes of those read."""
    if current_path.suffix.lower() == ".tdms":
        cur = read_current_tdms(current_path, bench.daq.rate_hz, current_channels)
    else:
        if current_channels:
            raise ConfigError(f"--current-channel: only for TDMS files, not {current_path}")
        cur = read_current_csv(current_path, bench.daq.rate_hz, data.get(current_path))
    period_s = bench.drive.period_s
    enc = read_encoder_csv(encoder_path, period_s, data.get(encoder_path))
    shared_by = "--same-clock" if same_clock else (
        meta.path.name if meta is not None and meta.host_clock_shared else None)
    shift, timeline = _timeline(cur, enc, shared_by)
    created_utc, started_from = _start_time(started_utc, meta, cur)
    origin: dict[str, Any] = {
        "kind": "imported",
        "importer": f"acq {__version__}",
        "files": [_file_entry("current", current_path, cur.file_info, sha256[current_path]),
                  _file_entry("encoder", encoder_path, {}, sha256[encoder_path])],
        "host_timeline": timeline,
        "encoder_host_ns": "the encoder file's t_s (host arrival stamps), uncorrected",
        "encoder_index": enc.timestamp_kind,
        "started_from": started_from,
    }
    if meta is not None:
        origin["restored"] = {"metadata": _file_entry("metadata", meta.path, {}), "origin": meta.origin,
                              "session_id": meta.session_id}
    if meta_warning:
        origin["metadata_not_used"] = meta_warning
    notes = [*cur.notes, *enc.notes]
    events = sorted((StreamEvent(int(host_ns(n.t_s + (shift if n.stream == "current" else 0.0))), n.stream, n.kind,
                                 n.detail) for n in notes), key=lambda e: e.host_ns)  # file times onto the host timeline
    status, incomplete = meta.incomplete() if meta is not None else ("complete", None)
    if meta is not None and meta.damage:  # where the files end: what the exported session could not read follows
        end_ns = int(host_ns(max(float(cur.time_s(cur.sample_index[-1])) + shift, float(enc.t_s[-1]))))
        events += [StreamEvent(end_ns, _stream_of(span), "warning", f"not in the exported files: {span}")
                   for span in meta.damage]
    cpr = getattr(bench.drive, "counts_per_rev", None) or bench.encoder.counts_per_rev
    _make_folder(out)
    tmp = out.with_name(f".{out.name}.importing")
    try:
        tmp.unlink(missing_ok=True)  # an earlier import's, killed (on a read-only disk this fails: a failed write)
        writer = SessionWriter(
            tmp, bench=bench, profile=profile,
            current_info=CurrentSourceInfo(cur.rate_hz, tuple(cur.phases_a), f"imported: {current_path.name}"),
            drive_info=DriveInfo(period_s, cpr, "imported", enc.timestamp_kind, f"imported: {encoder_path.name}"),
            host_ns_at_start=int(host_ns(min(float(cur.time_s(0)) + shift, float(enc.t_s[0])))), origin=origin,
            tags={**(meta.tags if meta else {}), **(tags or {})}, operator=meta.operator if meta else "",
            host_clock_shared=shared_by is not None, session_id=_restored_id(meta),
            created_utc=created_utc, bulk=True)
        writer.append_current_blocks(list(cur.phases_a.values()), *_current_blocks(cur, shift))
        writer.append_encoder(EncoderBlock(enc.index, enc.position_counts, host_ns(enc.t_s), enc.drive_time_s))
        for event in events:
            writer.add_event(event)
        writer.finish(status, f"imported from {current_path.name} and {encoder_path.name}"
                      + (f"; {incomplete}" if incomplete else ""))
        if writer.failure is not None:
            raise writer.failure
        replace_durably(tmp, out)
    except StorageError as e:  # named by the file asked for; the half-written temp file is removed below
        raise StorageError(str(e).split(" — ")[0].replace(str(tmp), str(out))) from None
    except OSError as e:
        raise storage_error(e, out) from None
    finally:
        with contextlib.suppress(OSError):  # nothing to remove where nothing could be written
            tmp.unlink(missing_ok=True)
    return ImportResult(out, [*([meta_warning] if meta_warning else []), *([incomplete] if incomplete else []),
                              *(n.detail for n in notes if n.kind == "warning")])


def _restored_id(meta: ExportMetadata | None) -> str | None:
    """The session id an import keeps: the exported session's, unless the files hold only part of it (a damaged
    session exported with --partial) — that is other data, and under the same id its analysis would replace the whole
    session's in a shared catalogue (the review). Its id is then derived from the exported id and what is missing, so
    importing the same partial export twice gives the same session, not two (the second read); its origin keeps the
    exported id."""
    if meta is None:
        return None
    if meta.damage:
        return str(uuid.uuid5(uuid.NAMESPACE_URL, f"acq-partial:{meta.session_id}:{'|'.join(meta.damage)}"))
    return meta.session_id


def _stream_of(span: str) -> str:
    """The stream a damaged span names ("current: samples …"); "session" for a whole-file note ("file cut: …")."""
    stream = span.split(":", 1)[0]
    return stream if stream in ("current", "encoder", "events") else "session"
