"""Read and check the files of other tools — current CSV or TDMS, encoder CSV — for ``acq import``.

Current CSV: header ``t_s`` and one or more of ``i_a_A, i_b_A, i_c_A``; ``t_s`` is the DAQ's own
sample clock (regular), so it gives the rate and each sample's DAQ index (a jump in ``t_s`` is a
gap). Current TDMS (npTDMS): the waveform channels picked with ``GROUP/CHANNEL`` (in phase order
a, b, c); the rate is ``1 / wf_increment``, sample 0 is at ``wf_start_offset``, the recording started
at ``wf_start_time`` (when set); a truncated last segment is read as far as it goes, with a warning.

Encoder CSV: header ``t_s, position_counts`` and optionally ``index`` (the drive cycle counter;
gaps are found from it) and ``drive_time_s``. ``t_s`` are host arrival stamps: jittered stamps that
step back are accepted with a warning (row order is cycle order). Without ``index`` the cycle comes
from ``drive_time_s / period_s``, else from the row number with the gaps the host stamps show (a
step of 1.5 periods or more). 32-bit register wraps of ``position_counts`` and ``index`` are
unwrapped; a jump of more than half the register range that is not a wrap is an error.

A record's length is what its samples cover (samples × period); less than ``MIN_DURATION_S`` is an
error. Errors are one line naming the file, line (or channel/sample) and column.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np
import pyarrow as pa

from acq.offline.csvtable import CsvTable, read_csv
from acqcore.errors import ConfigError

PHASES = ("i_a", "i_b", "i_c")
#: The streams an input file holds (a subset of the session's event streams, :data:`drivers.base.StreamName`).
FileStream = Literal["current", "encoder"]
MIN_DURATION_S = 2.0
RATE_TOLERANCE = 0.01
#: Jittered host stamps may step back (a later row stamped earlier); transfer latencies of 50–150 ms
#: (USB) bound how far. A step back beyond this is rows out of order (files joined), not jitter.
MAX_STEP_BACK_S = 0.5
#: Without an index column, a host-stamp step of at least this many drive periods is a candidate gap.
GAP_STEP_PERIODS = 1.5
#: Rows on each side of such a step whose median stamp − row·T measures the cycles it skipped.
GAP_WINDOW_ROWS = 20
REGISTER_RANGE = 1 << 32
#: A 32-bit wrap moves the value by less than this (after the wrap) — far beyond any real drive cycle.
WRAP_STEP_LIMIT = REGISTER_RANGE // 4


@dataclass(frozen=True)
class Note:
    """An event found in an input file, at time ``t_s`` of that file's time column (:mod:`acq.offline.importers` makes it
    a session event)."""

    t_s: float
    stream: FileStream
    kind: Literal["gap", "warning"]
    detail: str


@dataclass(frozen=True)
class CurrentTable:
    """A current file read and checked: phases in A, DAQ sample index of each sample, rate in Hz.

    ``t0_s`` is the time of DAQ sample index 0 on the file's time axis; ``start_utc`` when the
    recording started (ISO 8601, UTC) if the file says.
    """

    phases_a: dict[str, np.ndarray]
    sample_index: np.ndarray
    rate_hz: float
    t0_s: float
    file_info: dict[str, Any]
    notes: list[Note] = field(default_factory=list)
    start_utc: str | None = None

    def time_s(self, index: np.ndarray | int) -> np.ndarray:
        """File time, s, of DAQ sample ``index``."""
        return self.t0_s + np.asarray(index) / self.rate_hz


@dataclass(frozen=True)
class EncoderTable:
    """An encoder file read and checked (host arrival ``t_s``, unwrapped counts, drive cycle index)."""

    t_s: np.ndarray
    position_counts: np.ndarray
    index: np.ndarray
    drive_time_s: np.ndarray | None
    timestamp_kind: str
    notes: list[Note] = field(default_factory=list)


# ------------------------------------------------------------------------------------ checks

#: Physical bounds of imported CSV values (magnitudes): times up to ~300 years (Unix epoch stamps fit), phase
#: currents up to 10 kA (robot joint motors draw < 1 kA), counters within int64 with headroom.
CSV_BOUNDS = {"t_s": 1e10, "drive_time_s": 1e10, "i_a_A": 1e4, "i_b_A": 1e4, "i_c_A": 1e4,
              "position_counts": 2.0**62, "index": 2.0**62}


def _check_increasing(table: CsvTable, column: str, values: np.ndarray, *, strict: bool,
                      step: np.ndarray | None = None) -> None:
    """Refuse the first row that does not increase on the previous; ``step`` is ``np.diff(values)`` if known."""
    step = np.diff(values) if step is None else step
    bad = np.flatnonzero(step <= 0 if strict else step < 0)
    if bad.size:
        row = int(bad[0]) + 1
        raise table.error(row, column, f"{values[row]:.12g} does not increase (previous row: {values[row - 1]:.12g})")


def _check_duration(path: Path, where: Callable[[], str], duration_s: float) -> None:
    """Refuse less than ``MIN_DURATION_S`` of data; ``duration_s`` is what the samples cover (count × period)."""
    if not duration_s >= MIN_DURATION_S:
        shown = max(duration_s, 0.0)
        decimals = next((d for d in range(3, 10) if float(f"{shown:.{d}f}") < MIN_DURATION_S), 9)
        raise ConfigError(f"{path}: {where()}: only {shown:.{decimals}f} s of data "
                          f"(at least {MIN_DURATION_S:g} s needed)")


def _check_rate(path: Path, where: Callable[[], str], rate_hz: float, expected: float) -> None:
    deviation = abs(rate_hz / expected - 1.0)
    if deviation > RATE_TOLERANCE:
        raise ConfigError(f"{path}: {where()}: sample rate {rate_hz:.6g} Hz disagrees with the bench's [daq] rate_hz = "
                          f"{expected:g} by {100 * deviation:.2f} % (more than {100 * RATE_TOLERANCE:g} %)")


def _cut_notes(table: CsvTable, stream: FileStream, t_s: np.ndarray) -> list[Note]:
    """A warning when the file was cut in its last line (left out by :func:`read_csv`), at the last sample kept."""
    if table.cut_line is None:
        return []
    return [Note(float(t_s[-1]), stream, "warning", f"{table.path.name}: line {table.cut_line} has no end of line "
                 f"(the file was cut in it): left out, {table.rows} rows read")]


def _nonempty(table: CsvTable) -> None:
    if table.rows == 0:
        raise ConfigError(f"{table.path}: line 2: no data rows (at least {MIN_DURATION_S:g} s needed)")


def _register_column(table: CsvTable, column: str) -> np.ndarray:
    """An integer column of a 32-bit register (counts, cycle counter), unwrapped to int64."""
    values = table.columns[column]
    fractional = np.flatnonzero(values != np.rint(values))
    if fractional.size:
        raise table.error(int(fractional[0]), column, f"{values[fractional[0]]:.12g} is not an integer")
    v = values.astype(np.int64)
    step = np.diff(v)
    jumps = np.flatnonzero(np.abs(step) > REGISTER_RANGE // 2)
    if not jumps.size:
        return v
    wrapped = step[jumps] - np.sign(step[jumps]) * REGISTER_RANGE
    in_register = (np.minimum(v[jumps], v[jumps + 1]) >= -(REGISTER_RANGE // 2)) & (
        np.maximum(v[jumps], v[jumps + 1]) < REGISTER_RANGE)
    bad = np.flatnonzero(~(in_register & (np.abs(wrapped) < WRAP_STEP_LIMIT)))
    if bad.size:
        j = int(jumps[bad[0]])
        raise table.error(j + 1, column, f"jumps from {v[j]} to {v[j + 1]}, more than half the 32-bit register "
                                         "range, and is not a wrap")
    correction = np.zeros_like(v)
    correction[jumps + 1] = -np.sign(step[jumps]) * REGISTER_RANGE
    return v + np.cumsum(correction)


def _gap_notes(stream: FileStream, index: np.ndarray, t_s: np.ndarray, unit: str) -> list[Note]:
    missing = np.diff(index) - 1
    return [Note(float(t_s[i + 1]), stream, "gap", f"{missing[i]} {unit} missing before index {index[i + 1]}")
            for i in np.flatnonzero(missing > 0)]


# ------------------------------------------------------------------------------------ current


def _regular_clock(table: CsvTable, dt: np.ndarray) -> tuple[np.ndarray, float]:
    """DAQ sample index of each row (0 at the first) and the rate, Hz, from the regular ``t_s`` and its steps ``dt``."""
    t = table.columns["t_s"]
    if dt.max() < 1.5 * dt.min():  # no gap: every step is in the run, the median need not be found
        step = float(dt.sum() / dt.size)
    else:
        in_run = dt < 1.5 * np.median(dt)
        step = float(dt[in_run].sum() / in_run.sum())
    grid = t - t[0]
    grid /= step  # in place: a 60 s file's columns are 12 MB, each temporary costs its page faults
    nearest = np.rint(grid, out=np.empty(t.size, np.int64), casting="unsafe")  # rounded into int64: exact below 2**53
    deviation = np.abs(np.subtract(grid, nearest, out=grid), out=grid)
    if deviation.max() > 0.25:  # the row is looked for only when one is off
        row = int(np.flatnonzero(deviation > 0.25)[0])
        raise table.error(row, "t_s", f"{t[row]:.12g} is off the regular sample clock of {1 / step:.6g} Hz by "
                                      f"{(t[row] - t[0]) / step - nearest[row]:+.2f} samples")
    return nearest, 1.0 / step


def read_current_csv(path: Path, bench_rate_hz: float, data: pa.Buffer | None = None) -> CurrentTable:
    """Read and check a current CSV (``t_s`` and phase columns ``i_a_A`` ...); its rate must be the bench's
    ``[daq] rate_hz`` (``bench_rate_hz``) within :data:`RATE_TOLERANCE`. ``data``: the file's bytes, if read."""
    table = read_csv(path, ("t_s",), tuple(f"{p}_A" for p in PHASES), bounds=CSV_BOUNDS, data=data)
    _nonempty(table)
    t = table.columns["t_s"]
    dt = np.diff(t)  # once, for the order check and the clock
    _check_increasing(table, "t_s", t, strict=True, step=dt)

    def where() -> str:
        return f"line {table.line(-1)}, column t_s"

    if table.rows < 2:
        _check_duration(path, where, 0.0)
    index, rate = _regular_clock(table, dt)
    _check_duration(path, where, float(index[-1] + 1) / rate)
    _check_rate(path, lambda: f"lines 2–{table.line(-1)}, column t_s", rate, bench_rate_hz)
    phases = {p: table.columns[f"{p}_A"] for p in PHASES if f"{p}_A" in table.columns}
    if not phases:
        raise ConfigError(f"{path}: line 1: no phase column (expected one or more of i_a_A, i_b_A, i_c_A)")
    return CurrentTable(phases, index, rate, float(t[0]), {"format": "csv", "rate_from": "t_s"},
                        _cut_notes(table, "current", t) + _gap_notes("current", index, t, "samples"))


def _tdms_channels(tdms: Any, path: Path, wanted: tuple[str, ...]) -> list[tuple[str, Any]]:
    """The channels picked by ``GROUP/CHANNEL`` names (or the file's only channel), keyed by path."""
    available = {f"{g.name}/{c.name}": c for g in tdms.groups() for c in g.channels()}
    if not wanted:
        if len(available) != 1:
            raise ConfigError(f"{path}: {len(available)} channels; pick the phases (a, b, c in that order) with "
                              f"--current-channel GROUP/CHANNEL (channels: {', '.join(available) or 'none'})")
        wanted = tuple(available)
    if len(wanted) > len(PHASES):
        raise ConfigError(f"--current-channel: {len(wanted)} channels given, at most {len(PHASES)} phases")
    for name in wanted:
        if name not in available:
            raise ConfigError(f"{path}: channel {name}: not in the file (channels: {', '.join(available)})")
    return [(name, available[name]) for name in wanted]


def read_current_tdms(path: Path, bench_rate_hz: float, channels: tuple[str, ...] = ()) -> CurrentTable:
    """Read and check a current TDMS file; ``channels`` are ``GROUP/CHANNEL`` names, phases a, b, c; its rate must be
    the bench's ``[daq] rate_hz`` (``bench_rate_hz``) within :data:`RATE_TOLERANCE`."""
    from nptdms import TdmsFile  # only imports of TDMS files need it
    from nptdms.log import log_manager

    if not path.exists():
        raise ConfigError(f"{path}: no such file")
    level = log_manager.log_level
    # its truncation warnings become our event and one line; npTDMS sets each of its module loggers' level and gives
    # each its own console handler, so the "nptdms" logger's level does not reach them: its log manager does
    log_manager.set_level(logging.ERROR)
    try:
        tdms = TdmsFile.read(path)
    except (ValueError, EOFError, OSError, KeyError) as e:
        raise ConfigError(f"{path}: not a readable TDMS file ({e})") from None
    finally:
        log_manager.set_level(level)
    picked = _tdms_channels(tdms, path, channels)
    increments = []
    for name, ch in picked:
        if "wf_increment" not in ch.properties:
            raise ConfigError(f"{path}: channel {name}: no wf_increment property (not a waveform; rate unknown)")
        increments.append(float(ch.properties["wf_increment"]))
    first = picked[0][0]
    if any(abs(inc / increments[0] - 1.0) > 1e-9 for inc in increments):
        raise ConfigError(f"{path}: channels {', '.join(n for n, _ in picked)}: wf_increment differs between them")
    data = [np.asarray(ch[:], dtype=np.float64) for _, ch in picked]
    n = min(d.size for d in data)
    truncated = (tdms.file_status.incomplete_final_segment or any(d.size != n for d in data)
                 or _cut_in_a_segment(path))
    for (name, _), d in zip(picked, data):
        bad = np.flatnonzero(~np.isfinite(d[:n]))
        if bad.size:
            what = "NaN" if np.isnan(d[bad[0]]) else f"{d[bad[0]]} is not finite"
            raise ConfigError(f"{path}: channel {name}, sample {bad[0]}: {what}")
    rate = 1.0 / increments[0]
    _check_duration(path, lambda: f"channel {first}, sample {n - 1}", n / rate)
    _check_rate(path, lambda: f"channel {first}, wf_increment", rate, bench_rate_hz)
    t0 = float(picked[0][1].properties.get("wf_start_offset", 0.0))
    info = {"format": "tdms", "rate_from": "wf_increment", "channels": [name for name, _ in picked]}
    notes = [Note(t0 + (n - 1) / rate, "current", "warning", f"{path.name}: truncated last segment; read {n} samples "
                  "per channel, the rest of that segment is missing")] if truncated else []
    return CurrentTable(dict(zip(PHASES, (d[:n] for d in data))), np.arange(n, dtype=np.int64), rate, t0, info, notes,
                        _tdms_start_utc(picked[0][1].properties.get("wf_start_time")))


#: A TDMS segment's lead-in (NI, "TDMS File Format Internal Structure"): tag "TDSm", ToC mask (little-endian),
#: version, then the next segment's offset and the raw data's, 8 bytes each, from the lead-in's end.
TDMS_LEAD_IN_BYTES = 28
#: The ToC mask's bit kTocBigEndian: the offsets (and the data) are big-endian.
TDMS_BIG_ENDIAN = 1 << 6
#: The next segment's offset a writer that crashed leaves (the segment runs to the file's end; npTDMS flags it).
TDMS_UNKNOWN_LENGTH = 0xFFFF_FFFF_FFFF_FFFF


def _cut_in_a_segment(path: Path) -> bool:
    """True when the file ends inside a segment, its lead-in and metadata included, by the segments' own lengths.
    npTDMS flags a cut in the data (``incomplete_final_segment``) but drops a last segment cut in its lead-in or
    metadata with no more than a log line ("Last segment metadata is incomplete"), the rest read as a whole file."""
    size = path.stat().st_size
    position = 0
    with path.open("rb") as f:
        while position < size:
            f.seek(position)
            lead_in = f.read(TDMS_LEAD_IN_BYTES)
            if len(lead_in) < TDMS_LEAD_IN_BYTES:
                return True
            big = int.from_bytes(lead_in[4:8], "little") & TDMS_BIG_ENDIAN
            offset = int.from_bytes(lead_in[12:20], "big" if big else "little")
            if offset == TDMS_UNKNOWN_LENGTH:
                return False
            position += TDMS_LEAD_IN_BYTES + offset
    return position > size


def _tdms_start_utc(value: Any) -> str | None:
    """A TDMS ``wf_start_time`` (UTC) as ISO 8601; None when unset (LabVIEW writes its epoch, 1904-01-01)."""
    if value is None:
        return None
    when = np.datetime64(value, "s")
    if when <= np.datetime64("1904-01-01T00:00:00", "s"):
        return None
    return f"{np.datetime_as_string(when, unit='s')}+00:00"


# ------------------------------------------------------------------------------------ encoder


def _stamps_stepping_back(table: CsvTable, t: np.ndarray) -> list[Note]:
    """A warning when host stamps step back (jitter; rows stay in file order), an error beyond ``MAX_STEP_BACK_S``."""
    step = np.diff(t)
    back = np.flatnonzero(step < 0)
    if not back.size:
        return []
    too_far = back[-step[back] > MAX_STEP_BACK_S]
    if too_far.size:
        row = int(too_far[0]) + 1
        raise table.error(row, "t_s", f"{t[row]:.12g} does not increase (previous row: {t[row - 1]:.12g})")
    return [Note(float(t[back[0] + 1]), "encoder", "warning",
                 f"{table.path.name}: host stamps t_s step back {back.size} time(s), by up to "
                 f"{-1e3 * float(step[back].min()):.3f} ms (first at line {table.line(int(back[0]) + 1)}); rows taken "
                 "in file order as the drive cycle order")]


def _cycles_from_stamps(t: np.ndarray, period_s: float) -> np.ndarray:
    """Drive cycle of each row: its row number plus the cycles missing where the host stamps step by
    ``GAP_STEP_PERIODS`` periods or more.

    The cycles such a step skipped are the shift it leaves in stamp − row·T (medians of up to
    ``GAP_WINDOW_ROWS`` rows on each side, never across the next step), so a jittered stamp or a batch of
    rows stamped together (steps of several periods that the rows in between make up) is no gap.
    """
    rows = np.arange(t.size, dtype=np.int64)
    steps = np.flatnonzero(np.diff(t) >= GAP_STEP_PERIODS * period_s)
    if not steps.size:
        return rows
    lag = t - rows * period_s
    bounds = np.concatenate(([0], steps + 1, [t.size]))
    missing = np.zeros(t.size, dtype=np.int64)
    for j, i in enumerate(steps):
        before = lag[max(bounds[j], i + 1 - GAP_WINDOW_ROWS):i + 1]
        after = lag[i + 1:min(bounds[j + 2], i + 1 + GAP_WINDOW_ROWS)]
        missing[i + 1] = max(0, int(np.rint((np.median(after) - np.median(before)) / period_s)))
    return rows + np.cumsum(missing)


def read_encoder_csv(path: Path, period_s: float, data: pa.Buffer | None = None) -> EncoderTable:
    """Read and check an encoder CSV (``t_s, position_counts[, index][, drive_time_s]``); ``data``: its bytes, if
    read."""
    table = read_csv(path, ("t_s", "position_counts"), ("index", "drive_time_s"), bounds=CSV_BOUNDS, data=data)
    _nonempty(table)
    t = table.columns["t_s"]
    notes = _stamps_stepping_back(table, t)  # host stamps: several samples may arrive at once, or jitter
    position = _register_column(table, "position_counts")
    drive_time = table.columns.get("drive_time_s")
    if "index" in table.columns:
        index, kind = _register_column(table, "index"), "index column"
        _check_increasing(table, "index", index, strict=True)
    elif drive_time is not None:
        index, kind = np.rint((drive_time - drive_time[0]) / period_s).astype(np.int64), "drive_time_s / period_s"
        _check_increasing(table, "drive_time_s", index, strict=True)
    else:
        index, kind = _cycles_from_stamps(t, period_s), "row number, gaps from host stamps"
        notes.append(Note(float(t[0]), "encoder", "warning",
                          f"{path.name}: no index or drive_time_s column; drive cycles taken as row numbers, gaps "
                          f"found where the host stamps step by {GAP_STEP_PERIODS:g} periods or more"))
    _check_duration(path, lambda: f"line {table.line(-1)}, column t_s", float(index[-1] - index[0] + 1) * period_s)
    notes += _cut_notes(table, "encoder", t) + _gap_notes("encoder", index, t, "drive cycles")
    return EncoderTable(t, position, index, drive_time, kind, notes)


def host_ns(t_s: np.ndarray | float) -> np.ndarray:
    """Seconds on a host timeline as int64 ns."""
    return np.rint(np.asarray(t_s, dtype=np.float64) * 1e9).astype(np.int64)
