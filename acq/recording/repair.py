"""Rewrite a session its recorder left unfinished (killed, status ``recording``) into a clean file; copy the intact
part of a damaged one (a cut copy, a chunk that fails its checksum) into a new session beside it."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import h5py
import numpy as np

from acq.recording.h5safe import open_read, superblock_eof
from acq.recording.layout import EVENT_DTYPE, LIBVER, OPTIONAL_ENCODER, footer_unwritten, write_footer
from acq.recording.live import refuse_if_recorded
from acq.recording.reader import load
from acq.recording.session import Session
from acq.recording.storage import atomic_path, storage_error


#: A copy is written in this many slices of each column, each flushed: a cut copy of it keeps the slices of both
#: streams before the cut, as one of a recording keeps its commits (columns written whole put the encoder, written
#: last, past a 90 % cut). 20: a cut then costs about 1/20 of each stream beyond its share of the bytes (measured on a
#: 9 s copy: a 90 % cut keeps 89 % of the current and 87.5 % of the encoder; 50 %: 48 % and 50 %).
SLICES = 20


def repair(path: Path | str, stop_reason: str) -> Session:
    """Rewrite a session left with status ``recording`` (writer killed) as ``interrupted``; return it as read.

    HDF5 keeps a crashed SWMR writer's file marked as open for writing, so it cannot be reopened
    for writing in place: every committed sample is copied into a fresh file beside it
    (uneven column lengths cut to the common length), which then atomically replaces the original.
    A write failure leaves the original untouched and no temp file. A file a running recorder still holds is not
    touched (:class:`~acq.recording.live.SessionBeingRecorded`).

    A damaged file (anything unreadable: a chunk failing its checksum, the commit table ``/flushes``, a cut) is never
    rewritten: what the reader cannot use now (samples no readable block row places, rows of a damaged chunk)
    would be gone for good. Its readable part is copied into :func:`recovered_path` instead (:func:`recover`), and
    that copy is returned: its ``path`` is not ``path``.
    """
    p = Path(path)
    refuse_if_recorded(p)
    session = load(p)
    if session.damage:
        return _recover(p, session)
    return _copy(p, session, p, stop_reason)


def recovered_path(path: Path | str) -> Path:
    """Where :func:`recover` writes the intact part of ``path``: ``<name>.recovered.h5`` beside it."""
    p = Path(path)
    return p.with_name(f"{p.stem}.recovered{p.suffix}")


def recover(path: Path | str) -> Session:
    """Copy the intact part of the damaged session ``path`` into :func:`recovered_path` (replaced if it exists),
    status ``interrupted``, the loss in its stop reason; return the copy as read. ``path`` itself is not written.

    The stop reason says what was lost and what is kept, e.g. "recovered from a file cut at 1 279 293 of 2 558 587
    bytes: 4.8 s of current, 5.5 s of encoder kept (was complete: recorded 10 s)". A file a running recorder still
    holds is not copied (:class:`~acq.recording.live.SessionBeingRecorded`).
    """
    p = Path(path)
    refuse_if_recorded(p)
    return _recover(p, load(p))


def _recover(p: Path, session: Session) -> Session:
    """:func:`recover` of ``session``, read from ``p``."""
    c, e = session.current, session.encoder
    kept = f"{c.sample_count / c.rate_hz:.1f} s of current, {e.index.size * e.period_s:.1f} s of encoder kept"
    size, eof = p.stat().st_size, superblock_eof(p)
    if eof is not None and size < eof:
        what = f"a file cut at {size:,} of {eof:,} bytes".replace(",", " ")
    else:
        what = f"a damaged file ({'; '.join(session.damage)})"
    was = f"{session.status}: {session.meta.stop_reason}" if session.meta.stop_reason else session.status
    reason = f"recovered from {what}: {kept}" + (f" (was {was})" if was else "")
    return _copy(p, session, recovered_path(p), reason)


def _copy(source: Path, session: Session, target: Path, stop_reason: str) -> Session:
    """Write ``session`` (read from ``source``) into ``target`` through a temp file, status ``interrupted``; read it
    back. A write failure leaves ``target`` as it was and no temp file."""
    with open_read(source) as src:
        group_attrs = {name: dict(src[name].attrs) for name in ("current", "encoder")}
    with atomic_path(target) as tmp:
        try:
            with h5py.File(tmp, "w", libver=LIBVER) as dst:
                _write_copy(dst, session, group_attrs)
                write_footer(dst, "interrupted", stop_reason, {n for n in OPTIONAL_ENCODER if n in dst["encoder"]})
        except OSError:
            raise
        except Exception as e:  # noqa: BLE001 - h5py reports write errors as RuntimeError too
            raise storage_error(e, target) from None
    return load(target)


def _write_copy(dst: h5py.File, session: Session, group_attrs: dict[str, dict[str, Any]]) -> None:
    """The attributes and data of ``session``, status ``recording`` and no counts until the footer. Every attribute,
    group and dataset is created before any data is written, as the writer does: what locates the root attributes
    then lies before the data, so a cut copy of this file keeps them (the footer overwrites them in place); the data
    follows in :data:`SLICES` slices."""
    c, e = session.current, session.encoder
    events = np.array([(ev.host_ns, ev.stream.encode(), ev.kind.encode(), ev.detail.encode()[:240])
                       for ev in session.events], dtype=EVENT_DTYPE)
    columns = {**{f"current/{ch}_A": values for ch, values in c.phases_a.items()},
               "current/blocks/first_index": c.block_first_index, "current/blocks/count": c.block_count,
               "current/blocks/host_ns": c.block_host_ns,
               **{f"encoder/{name}": getattr(e, name) for name in ("position_counts", "index", "host_ns",
                                                                  *OPTIONAL_ENCODER) if getattr(e, name) is not None},
               "events": events}
    dst.attrs.update({**session.attrs, **footer_unwritten()})
    for name in ("current", "encoder"):
        dst.create_group(name).attrs.update(group_attrs[name])
    made = {name: dst.create_dataset(name, shape=values.shape, dtype=values.dtype, maxshape=(None,), chunks=True,
                                     fletcher32=True) for name, values in columns.items()}
    dst.flush()  # the layout's metadata placed now (HDF5 places what is not flushed at the end of the file)
    for k in range(1, SLICES + 1):  # both streams in time order, as a recording commits them
        for name, values in columns.items():
            rows = np.s_[(k - 1) * values.size // SLICES:k * values.size // SLICES]
            made[name][rows] = values[rows]
        dst.flush()
