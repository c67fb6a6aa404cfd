"""Rewrite a session its recorder left unfinished (killed, status ``recording``) into a clean file."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import h5py
import numpy as np

from acq.recording.h5safe import open_read
from acq.recording.layout import EVENT_DTYPE, LIBVER, OPTIONAL_ENCODER, write_footer
from acq.recording.reader import load
from acq.recording.session import Session
from acq.recording.storage import atomic_path, storage_error


def repair(path: Path | str, stop_reason: str) -> Session:
    """Rewrite a session left with status ``recording`` (writer killed) as ``interrupted``; return it as read.

    HDF5 keeps a crashed SWMR writer's file marked as open for writing, so it cannot be reopened
    for writing in place: every committed, intact sample is copied into a fresh file beside it
    (uneven column lengths cut to the common length), which then atomically replaces the original.
    A write failure leaves the original untouched and no temp file.
    """
    p = Path(path)
    session = load(p)
    if session.damage:
        stop_reason = f"{stop_reason}; kept the intact part ({'; '.join(session.damage)})"
    with open_read(p) as src:
        group_attrs = {name: dict(src[name].attrs) for name in ("current", "encoder")}
    with atomic_path(p) as tmp:
        try:
            with h5py.File(tmp, "w", libver=LIBVER) as dst:
                _write_copy(dst, session, stop_reason, group_attrs)
        except OSError:
            raise
        except Exception as e:  # noqa: BLE001 - h5py reports write errors as RuntimeError too
            raise storage_error(e, p) from None
    return load(p)


def _write_copy(dst: h5py.File, session: Session, stop_reason: str, group_attrs: dict[str, dict[str, Any]]) -> None:
    def column(group: h5py.Group, name: str, values: np.ndarray) -> None:
        group.create_dataset(name, data=values, maxshape=(None,), chunks=True, fletcher32=True)

    attrs = {k: v for k, v in session.attrs.items() if k not in ("current_samples", "encoder_samples")}
    dst.attrs.update(attrs)
    cur = dst.create_group("current")
    c = session.current
    cur.attrs.update(group_attrs["current"])
    for ch, values in c.phases_a.items():
        column(cur, f"{ch}_A", values)
    blocks = cur.create_group("blocks")
    for name, values in (("first_index", c.block_first_index), ("count", c.block_count),
                         ("host_ns", c.block_host_ns)):
        column(blocks, name, values)
    enc = dst.create_group("encoder")
    e = session.encoder
    enc.attrs.update(group_attrs["encoder"])
    for name in ("position_counts", "index", "host_ns", *OPTIONAL_ENCODER):
        values = getattr(e, name)
        if values is not None:
            column(enc, name, values)
    rows = np.array([(ev.host_ns, ev.stream.encode(), ev.kind.encode(), ev.detail.encode()[:240])
                     for ev in session.events], dtype=EVENT_DTYPE)
    column(dst, "events", rows)
    write_footer(dst, "interrupted", stop_reason, {n for n in OPTIONAL_ENCODER if n in enc})
