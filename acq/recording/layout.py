"""The session file's layout: HDF5 via h5py. Only the modules of ``acq.recording`` that write it
(:mod:`~acq.recording.writer`), read it (:mod:`~acq.recording.reader`, :mod:`~acq.recording.session`; the root
attributes checked by :mod:`~acq.recording.root_attrs`) and rewrite it (:mod:`~acq.recording.repair`) know it;
everything else goes through :class:`acq.recording.session.Session`.

Layout (``format = "acq-session"``, ``format_version = 1``)::

    /                   attrs: format, format_version, session_id, created_utc, stopped_utc,
                               host_monotonic_ns_at_start, acq_version, status, stop_reason,
                               current_samples, encoder_samples (-1 until the footer; absent in older files),
                               bench_json, profile_json, joint, operator, tags_json, origin_json,
                               host_clock_shared (both streams' host_ns on one host clock; absent in
                               older files: true for recordings, false for imports)
                               (profile_json holds the profile as executed: a dithered motion's speed_dither
                               and the dither_seed its drive used, drawn by the recorder if the file had none)
    /current            attrs: rate_hz (coerced by the card), device, channels, units
        i_a_A [, i_b_A, i_c_A]   float64, A, one entry per stored sample
        blocks/first_index       int64, cumulative DAQ sample index of each read's first sample
        blocks/count             int64, samples per channel in that read
        blocks/host_ns           int64, host monotonic time when the read returned
    /encoder            attrs: period_s, counts_per_rev, transport, timestamp_kind, device
        position_counts          int64, unwrapped raw position register
        index                    int64, cumulative drive cycle (SYNC counter / sequence)
        host_ns                  int64, host arrival time of each sample
        drive_time_s             float64, optional (the drive's own stamp)
        velocity_counts_per_s    float64, optional
        velocity_demand_counts_per_s  float64, optional (the drive's speed reference, CiA 402 0x606B)
    /events             compound rows (host_ns, stream, kind, detail)

    /flushes            compound rows (host_ns, current_samples, current_blocks, encoder_samples, events):
                        the totals committed by each flush, written after the samples they count

Integrity: every dataset carries HDF5 Fletcher32 checksums per chunk.

A cut copy (a partial copy, a truncated download) keeps what lies before the cut. The writer creates every root
attribute when it creates the file, so the footer (:func:`write_footer`, written by reopening the finished file)
overwrites values in place instead of adding attributes: HDF5 keeps more than 8 in dense storage, whose index a
new attribute rewrites at the end of the file (older files: a cut copy loses every root attribute). The footer's
strings (:data:`FOOTER_TEXT`) are fixed-length UTF-8, null-padded, created at their full size
(:data:`FOOTER_TEXT_BYTES`; h5py reads them as bytes): the footer rewrites them where they are, so finishing a file
takes no new byte of its disk — a recording stopped by a full disk still gets its status ``failed`` and its reason.
A reason longer than its room is cut to fit, ending " … [N bytes cut]" (a device's error text of more than 8 kB;
kept whole it needed new space, and on a full disk the footer was not written at all). Older files hold them as
variable-length strings, whose new value HDF5 may put at the file's end.
"""

from __future__ import annotations

from collections.abc import Sequence
from datetime import UTC, datetime
from typing import Literal

import h5py
import numpy as np

FORMAT = "acq-session"
FORMAT_VERSION = 1
LIBVER = ("v110", "latest")
Status = Literal["recording", "complete", "interrupted", "failed"]

EVENT_DTYPE = np.dtype([("host_ns", "<i8"), ("stream", "S16"), ("kind", "S16"), ("detail", "S240")])
FLUSH_DTYPE = np.dtype([("host_ns", "<i8"), ("current_samples", "<i8"), ("current_blocks", "<i8"),
                        ("encoder_samples", "<i8"), ("events", "<i8")])
#: The footer's counts before the footer is written: no count at all (0 would be one).
NO_COUNT = -1
#: Root attributes of the footer that are strings (of an older file: variable-length, its new value in a heap that may
#: lie at the end of the file).
FOOTER_TEXT = ("status", "stop_reason", "stopped_utc")
#: Bytes each footer string is created with, UTF-8: a status is at most 11 ("interrupted"), a stop time 25
#: ("2026-01-02T03:04:05+00:00"); a reason names a file once or twice (Linux PATH_MAX 4096) in a sentence, or a
#: device's error text. The 8.2 kB of the file this costs is 0.03 % of a 10 s recording at 25.6 kS/s.
FOOTER_TEXT_BYTES = {"status": 16, "stop_reason": 8192, "stopped_utc": 32}
#: Ends a footer string cut to its room (:func:`fitted_text`), with the bytes of UTF-8 left out.
CUT_MARK = " … [{} bytes cut]"
#: The encoder columns a drive may not give (see the layout above).
OPTIONAL_ENCODER = ("drive_time_s", "velocity_counts_per_s", "velocity_demand_counts_per_s")


def _footer_text(name: str, text: str) -> np.ndarray:
    """``text`` as the fixed-length footer string ``name`` (:data:`FOOTER_TEXT_BYTES`); longer: its own length. A byte
    of a path that is not UTF-8 (a Latin-1 folder name) is written as its escape, ``\\udcfc`` as Python's standard
    error shows it (the catalogue's :func:`acq.monitoring.catalogue_text.readable` alike): the footer stays text."""
    data = text.encode(errors="backslashreplace")
    return np.array(data, dtype=h5py.string_dtype("utf-8", max(FOOTER_TEXT_BYTES[name], len(data), 1)))


def footer_unwritten() -> dict[str, np.ndarray | np.int64]:
    """The footer's root attributes as a file is created with them (status ``recording``, no counts): created with
    the file's other attributes, before any data, at their full size, so that :func:`write_footer` overwrites them in
    place (no new byte of the disk)."""
    return {"stopped_utc": _footer_text("stopped_utc", ""), "status": _footer_text("status", "recording"),
            "stop_reason": _footer_text("stop_reason", ""), "current_samples": np.int64(NO_COUNT),
            "encoder_samples": np.int64(NO_COUNT)}


def fitted_text(text: str, room_bytes: int) -> bytes:
    """``text`` as UTF-8 in at most ``room_bytes``: whole when it fits, else cut at a character's boundary and ended
    with :data:`CUT_MARK` naming the bytes left out (a reason is read by a person: its start says what happened). A
    byte of a path that is not UTF-8 is written as its escape (``\\udcfc``; strictly encoded it raised, and a recording
    in a Latin-1 folder stopped by a failed write was left without its footer)."""
    data = text.encode(errors="backslashreplace")
    if len(data) <= room_bytes:
        return data
    mark = CUT_MARK.format(len(data)).encode()
    head = data[:room_bytes - len(mark)].decode(errors="ignore").encode()  # a character cut in two is dropped whole
    return head + CUT_MARK.format(len(data) - len(head)).encode()


def _write_text(f: h5py.File, name: str, text: str) -> None:
    """Overwrite the footer string ``name`` with ``text`` where it is (its fixed length: a longer text is cut to fit,
    :func:`fitted_text` — a file on a full disk has no new byte for it); an older file's variable-length string is
    replaced, the whole text in new space."""
    dtype = f.attrs.get_id(name).dtype
    if dtype.kind == "S":
        f.attrs.modify(name, np.array(fitted_text(text, dtype.itemsize), dtype=dtype))
    else:
        del f.attrs[name]
        f.attrs[name] = _footer_text(name, text)


def utc_now_iso() -> str:
    """The current UTC time as ISO 8601 with seconds."""
    return datetime.now(UTC).isoformat(timespec="seconds")


def analysis_time_utc() -> str:
    """When an analysis is made: the current UTC time, ISO 8601 with microseconds ("2026-01-02T03:04:05.678901+00:00").

    Two analyses of one window made in the same second stay ordered (the catalogue keeps the later: a window that
    waited in the monitor's spool against ``acq analyze`` of its file). As text these order with the whole-second
    stamps of earlier results, which read as .000000 ("+" sorts before "."), and on both catalogue back ends."""
    return datetime.now(UTC).isoformat(timespec="microseconds")


def _datasets(f: h5py.File) -> list[h5py.Dataset]:
    found: list[h5py.Dataset] = []
    f.visititems(lambda name, obj: found.append(obj) if isinstance(obj, h5py.Dataset) else None)
    return found


def committed_rows(name: str, committed: dict[str, int]) -> int | None:
    """Rows of dataset ``name`` (no leading /) that the ``committed`` totals count; None for one they do not."""
    group = name.rsplit("/", 1)[0] if "/" in name else name
    return {"current/blocks": committed["current_blocks"], "current": committed["current_samples"],
            "encoder": committed["encoder_samples"], "events": committed["events"]}.get(group)


def write_footer(f: h5py.File, status: Status, stop_reason: str, filled_optional: set[str],
                 committed: dict[str, int] | None = None, datasets: Sequence[str] | None = None) -> None:
    """Status, reason, stop time and sample counts; with ``committed``, the ``datasets`` named (default: every
    dataset in the file) are first cut to the committed totals (rows written by a flush that did not complete are
    not kept)."""
    if committed is not None:
        for ds in _datasets(f) if datasets is None else [f[name] for name in datasets]:
            n = committed_rows(ds.name.lstrip("/"), committed)
            if n is not None and ds.shape[0] > n:
                ds.resize((n,))
    for name in OPTIONAL_ENCODER:
        if name in f["encoder"] and name not in filled_optional:
            del f["encoder"][name]
    # modify: the value overwritten where it is (assignment would add an attribute and delete the old one); the
    # counts before the status, which tells a reader they are written
    f.attrs.modify("current_samples", np.int64(f["current/blocks/count"][...].sum()))
    f.attrs.modify("encoder_samples", np.int64(f["encoder/index"].shape[0]))
    _write_text(f, "stop_reason", stop_reason)
    _write_text(f, "stopped_utc", utc_now_iso())
    _write_text(f, "status", status)
