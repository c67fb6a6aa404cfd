"""Export a session to the CSV pair that ``acq import`` reads.

``<stem>.current.csv``: ``t_s`` and the phases in A. ``t_s`` is the DAQ's own regular clock
(sample index / rate), placed on the host timeline of the encoder file: sample 0 sits at the
earliest host arrival of any block minus that block's duration (the least-delayed read), so the
importer can rebuild block host stamps from it. Gaps in the DAQ index are jumps in ``t_s``.

``<stem>.encoder.csv``: ``t_s`` (host arrival, s after the session's ``host_monotonic_ns_at_start``,
to the ns), ``position_counts`` (unwrapped), ``index`` (drive cycle) and ``drive_time_s`` when
the session has it. Floats are written in their shortest exact form, so a round trip is lossless
except for host stamps rounded to the ns.

``<stem>.session.json`` (:mod:`acq.offline.export_metadata`): the session's id, joint, start time, tags,
bench and profile as used, and whether the two ``t_s`` columns are stamps on one host clock, so
``acq import`` restores the session's history.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from acq.offline.export_metadata import write_metadata
from acq.recording.session import Session, load
from acq.recording.storage import write_text_atomically
from acqcore.errors import ConfigError

PHASE_COLUMNS = ("i_a", "i_b", "i_c")


def _seconds(t_s: np.ndarray) -> list[str]:
    return [f"{x:.9f}" for x in t_s.tolist()]


def _exact(values: np.ndarray) -> list[str]:
    return [repr(x) for x in values.tolist()]


def _write_columns(path: Path, columns: dict[str, list[str]]) -> None:
    """Write ``name -> formatted cells`` as a CSV under a temporary name, then rename (no temp file left on error)."""
    body = "\n".join(map(",".join, zip(*columns.values())))
    write_text_atomically(path, ",".join(columns) + "\n" + body + "\n")


def _host_ns_at_start(session: Session) -> int:
    """The host clock at the session's start, ns; :class:`ConfigError` naming the file when it lacks it."""
    if session.meta.host_ns_at_start is None:
        raise ConfigError(f"{session.path}: malformed session: no host_monotonic_ns_at_start attribute")
    return session.meta.host_ns_at_start


def current_t0_s(session: Session) -> float:
    """Host time, s after ``host_monotonic_ns_at_start``, of DAQ sample 0 (least-delayed block)."""
    cur = session.current
    last_index = cur.block_first_index + cur.block_count - 1
    host_s = (cur.block_host_ns - _host_ns_at_start(session)) * 1e-9
    return float(np.min(host_s - last_index / cur.rate_hz))


#: Encoder datasets a session may hold that the CSV pair does not carry (``acq import`` does not read them yet).
NOT_EXPORTED = ("velocity_counts_per_s", "velocity_demand_counts_per_s")


def export_csv(session_path: Path, out_dir: Path) -> tuple[tuple[Path, Path, Path], tuple[str, ...]]:
    """Write the session's current and encoder CSV files and its metadata into ``out_dir``; return their paths and
    the names of the session's encoder datasets left out (:data:`NOT_EXPORTED` that it holds)."""
    session = load(session_path)
    session.require_samples()
    out_dir.mkdir(parents=True, exist_ok=True)
    cur, enc = session.current, session.encoder
    stem = Path(session_path).stem
    current_path, encoder_path = out_dir / f"{stem}.current.csv", out_dir / f"{stem}.encoder.csv"
    t_cur = current_t0_s(session) + cur.sample_index() / cur.rate_hz
    phases = {f"{p}_A": _exact(cur.phases_a[p]) for p in PHASE_COLUMNS if p in cur.phases_a}
    _write_columns(current_path, {"t_s": _seconds(t_cur), **phases})
    t_enc = (enc.host_ns - _host_ns_at_start(session)) * 1e-9
    columns = {"t_s": _seconds(t_enc), "position_counts": [str(v) for v in enc.position_counts.tolist()],
               "index": [str(v) for v in enc.index.tolist()]}
    if enc.drive_time_s is not None:
        columns["drive_time_s"] = _exact(enc.drive_time_s)
    _write_columns(encoder_path, columns)
    left_out = tuple(name for name in NOT_EXPORTED if getattr(enc, name, None) is not None)
    return (current_path, encoder_path, write_metadata(session, current_path, encoder_path)), left_out
