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
bench and profile as used, whether the two ``t_s`` columns are stamps on one host clock, its status and the
spans it could not read, so ``acq import`` restores the session's history.

A damaged session (or one still ``recording``) is refused unless asked (``partial``, ``acq export
--partial`` as ``acq analyze --partial``): then its intact part is exported, and the metadata says what is
missing, so the imported session is not taken for the whole recording.

An existing file is not replaced unless asked (``force``); the three are written under temp names in
the output folder and renamed only when all three are complete, so a failed write leaves the folder as
it was. The metadata is renamed last: a rename that fails (a folder in a CSV's place) leaves the old
metadata, whose checksums then no longer match a CSV replaced before it (``acq import`` says so).
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import ExitStack, contextmanager
from pathlib import Path

import numpy as np

from acq.offline.analyze import sha256_of
from acq.offline.export_metadata import metadata_path, metadata_text
from acq.recording.reader import load
from acq.recording.session import Session
from acq.recording.storage import WRITE_FAILURES, atomic_path, make_folders, storage_error
from acqcore.errors import ConfigError

PHASE_COLUMNS = ("i_a", "i_b", "i_c")


def _seconds(t_s: np.ndarray) -> list[str]:
    return [f"{x:.9f}" for x in t_s.tolist()]


def _exact(values: np.ndarray) -> list[str]:
    return [repr(x) for x in values.tolist()]


def _write_columns(path: Path, columns: dict[str, list[str]]) -> None:
    """Write ``name -> formatted cells`` as a CSV."""
    body = "\n".join(map(",".join, zip(*columns.values())))
    path.write_text(",".join(columns) + "\n" + body + "\n", encoding="utf-8")


@contextmanager
def _failure_named(target: Path) -> Iterator[None]:
    """An :class:`OSError` writing ``target``'s temp file becomes the :class:`StorageError` naming ``target`` (in
    the nested temp files' contexts it would reach the innermost one first and name that file)."""
    try:
        yield
    except OSError as e:
        raise storage_error(e, target) from None


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


def export_csv(session_path: Path, out_dir: Path, *, force: bool = False, partial: bool = False,
               ) -> tuple[tuple[Path, Path, Path], tuple[str, ...], str | None]:
    """Write the session's current and encoder CSV files and its metadata into ``out_dir``; return their paths,
    the names of the session's encoder datasets left out (:data:`NOT_EXPORTED` that it holds), and, for a session
    exported with ``partial``, what the files lack (one line naming the spans; None for a whole session).

    Raises
    ------
    ConfigError
        The session is damaged or still ``recording`` and ``partial`` is false, or one of the three files exists
        and ``force`` is false (nothing is written).
    StorageError
        A write failed (the folder is left as it was) or a rename did (the metadata, renamed last, is kept).
    """
    session = load(session_path)
    session.require_usable(partial=partial, action="export")
    session.require_samples()
    stem = Path(session_path).stem
    current_path, encoder_path = out_dir / f"{stem}.current.csv", out_dir / f"{stem}.encoder.csv"
    meta_path = metadata_path(current_path)
    assert meta_path is not None, current_path
    targets = (current_path, encoder_path, meta_path)
    existing = [path for path in targets if path.exists()]
    if existing and not force:
        raise ConfigError(f"{existing[0]}: exists (not overwritten; --force replaces it)")
    try:
        make_folders(out_dir)
    except OSError as e:
        if e.errno in WRITE_FAILURES:  # read-only, full, no permission: a failed write named by the folder asked for
            raise storage_error(e, out_dir) from None
        raise ConfigError(f"--csv {out_dir}: {e.strerror or e}") from None
    try:
        _write(session, targets, exclusive=not force)
    except FileExistsError as e:  # every export renames in the same order: the one that loses a race loses at its
        # current CSV, the first renamed, and leaves nothing of its own
        raise ConfigError(f"{e.filename2}: exists (not overwritten; --force replaces it)") from None
    enc = session.encoder
    left_out = tuple(name for name in NOT_EXPORTED if getattr(enc, name, None) is not None)
    return targets, left_out, _missing_text(session, meta_path)


def _write(session: Session, targets: tuple[Path, Path, Path], *, exclusive: bool) -> None:
    """Write the current CSV, the encoder CSV and the metadata (``targets``, in that order) under temp names, and
    rename them when all three are complete; with ``exclusive`` only onto free names (:class:`FileExistsError`)."""
    current_path, encoder_path, meta_path = targets
    cur, enc = session.current, session.encoder
    with ExitStack() as stack:  # every temp file removed on an error; all three renamed at the end, in reverse order:
        # the metadata last, so a failed rename of a CSV never leaves new metadata beside it
        # without force each is renamed only onto a free name: two exports into one folder at once both found the
        # names free above, and the second rename replaced the first's files (both said "wrote"; the trial, 3 of 6)
        tmp_meta, tmp_encoder, tmp_current = (stack.enter_context(atomic_path(path, exclusive=exclusive))
                                              for path in (meta_path, encoder_path, current_path))
        t_cur = current_t0_s(session) + cur.sample_index() / cur.rate_hz
        phases = {f"{p}_A": _exact(cur.phases_a[p]) for p in PHASE_COLUMNS if p in cur.phases_a}
        with _failure_named(current_path):
            _write_columns(tmp_current, {"t_s": _seconds(t_cur), **phases})
        t_enc = (enc.host_ns - _host_ns_at_start(session)) * 1e-9
        columns = {"t_s": _seconds(t_enc), "position_counts": [str(v) for v in enc.position_counts.tolist()],
                   "index": [str(v) for v in enc.index.tolist()]}
        if enc.drive_time_s is not None:
            columns["drive_time_s"] = _exact(enc.drive_time_s)
        with _failure_named(encoder_path):
            _write_columns(tmp_encoder, columns)
        with _failure_named(meta_path):
            tmp_meta.write_text(metadata_text(session, (current_path.name, sha256_of(tmp_current)),
                                              (encoder_path.name, sha256_of(tmp_encoder))), encoding="utf-8")


def _missing_text(session: Session, meta_path: Path) -> str | None:
    """What an export of ``session``'s intact part lacks, one line (None when the session is whole)."""
    kept = f"{session.current.sample_count} current and {session.encoder.index.size} encoder samples"
    if session.damage:
        return (f"{session.path}: damaged — exported the intact part only ({kept}); left out: "
                f"{'; '.join(session.damage)} (recorded in {meta_path.name})")
    if session.status == "recording":
        return (f"{session.path}: status recording — exported what is stored ({kept}); the rest of the recording "
                f"is not in the files (recorded in {meta_path.name})")
    return None
