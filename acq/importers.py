"""Import a recording made with other tools — current CSV or TDMS, encoder CSV — into a session.

Current CSV: header ``t_s`` and one or more of ``i_a_A, i_b_A, i_c_A``; ``t_s`` is the DAQ's own
sample clock (regular), so it gives the rate and each sample's DAQ index (a jump in ``t_s`` is a
gap). Current TDMS (npTDMS): the waveform channels picked with ``GROUP/CHANNEL`` (in phase order
a, b, c); the rate is ``1 / wf_increment``, sample 0 is at ``wf_start_offset``; a truncated last
segment is read as far as it goes, with a warning event.

Encoder CSV: header ``t_s, position_counts`` and optionally ``index`` (the drive cycle counter;
gaps are found from it) and ``drive_time_s``. ``t_s`` are host arrival stamps, stored uncorrected
as ``host_ns``. Without ``index`` the cycle comes from ``drive_time_s / period_s``, else from the
row number (then gaps cannot be seen; a warning event says so). 32-bit register wraps of
``position_counts`` and ``index`` are unwrapped; a jump of more than half the register range that
is not a wrap is an error.

Host stamps of the current: a CSV/TDMS current file carries only the DAQ's clock. When the two
files' time columns overlap they are taken as one timeline (as written by ``acq export``), and each
synthetic 0.1 s block is stamped with the time of its last sample (no transfer latency). When they
do not overlap, the current is shifted to start with the encoder and the origin says so; the
analysis then aligns the clocks from the data alone. Every choice is written into the session's
``origin`` with the files' names and SHA-256.
"""

from __future__ import annotations

import logging
import os
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import click
import numpy as np
from rich.console import Console
from rich.markup import escape

from acq import __version__
from acq.analyze import sha256_of
from acq.catalogue import parse_tags, tag_option
from acq.config import load_bench, load_profile, with_joint
from acq.csvtable import CsvTable, read_csv
from acq.session import SessionWriter, load
from acq.storage import storage_error
from acq.summary import summarize, summary_table
from drivers.base import (CurrentBlock, CurrentSourceInfo, DriveInfo, EncoderBlock, EventKind, StreamEvent,
                          StreamName)
from drivers.config import Bench, Profile
from drivers.errors import ConfigError, StorageError

PHASES = ("i_a", "i_b", "i_c")
MIN_DURATION_S = 2.0
RATE_TOLERANCE = 0.01
BLOCK_S = 0.1
REGISTER_RANGE = 1 << 32
#: A 32-bit wrap moves the value by less than this (after the wrap) — far beyond any real drive cycle.
WRAP_STEP_LIMIT = REGISTER_RANGE // 4


@dataclass(frozen=True)
class Note:
    """An event found in an input file, at time ``t_s`` of that file's time column."""

    t_s: float
    stream: StreamName
    kind: EventKind
    detail: str

    def event(self, shift_s: float) -> StreamEvent:
        """The session event, its file time moved onto the host timeline by ``shift_s``."""
        return StreamEvent(int(_ns(self.t_s + shift_s)), self.stream, self.kind, self.detail)


@dataclass(frozen=True)
class CurrentTable:
    """A current file read and checked: phases in A, DAQ sample index of each sample, rate in Hz.

    ``t0_s`` is the time of DAQ sample index 0 on the file's time axis.
    """

    phases_a: dict[str, np.ndarray]
    sample_index: np.ndarray
    rate_hz: float
    t0_s: float
    file_info: dict[str, Any]
    notes: list[Note] = field(default_factory=list)

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


def _check_increasing(table: CsvTable, column: str, values: np.ndarray, *, strict: bool) -> None:
    step = np.diff(values)
    bad = np.flatnonzero(step <= 0 if strict else step < 0)
    if bad.size:
        row = int(bad[0]) + 1
        raise table.error(row, column, f"{values[row]:.12g} does not increase (previous row: {values[row - 1]:.12g})")


def _check_duration(path: Path, where: Callable[[], str], span_s: float) -> None:
    if not span_s >= MIN_DURATION_S:
        raise ConfigError(f"{path}: {where()}: only {max(span_s, 0.0):.3f} s of data "
                          f"(at least {MIN_DURATION_S:g} s needed)")


def _check_rate(path: Path, where: Callable[[], str], rate_hz: float, bench: Bench) -> None:
    expected = bench.daq.rate_hz
    deviation = abs(rate_hz / expected - 1.0)
    if deviation > RATE_TOLERANCE:
        raise ConfigError(f"{path}: {where()}: sample rate {rate_hz:.6g} Hz disagrees with the bench's [daq] rate_hz = "
                          f"{expected:g} by {100 * deviation:.2f} % (more than {100 * RATE_TOLERANCE:g} %)")


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


def _gap_notes(stream: StreamName, index: np.ndarray, t_s: np.ndarray, unit: str) -> list[Note]:
    missing = np.diff(index) - 1
    return [Note(float(t_s[i + 1]), stream, "gap", f"{missing[i]} {unit} missing before index {index[i + 1]}")
            for i in np.flatnonzero(missing > 0)]


# ------------------------------------------------------------------------------------ current


def _regular_clock(table: CsvTable) -> tuple[np.ndarray, float]:
    """DAQ sample index of each row (0 at the first) and the rate, Hz, from the regular ``t_s``."""
    t = table.columns["t_s"]
    dt = np.diff(t)
    in_run = dt < 1.5 * np.median(dt)
    step = float(dt[in_run].sum() / in_run.sum())
    grid = (t - t[0]) / step
    index = np.rint(grid).astype(np.int64)
    off = np.flatnonzero(np.abs(grid - index) > 0.25)
    if off.size:
        row = int(off[0])
        raise table.error(row, "t_s", f"{t[row]:.12g} is off the regular sample clock of {1 / step:.6g} Hz by "
                                      f"{grid[row] - index[row]:+.2f} samples")
    return index, 1.0 / step


def read_current_csv(path: Path, bench: Bench) -> CurrentTable:
    """Read and check a current CSV (``t_s`` and phase columns ``i_a_A`` ...)."""
    table = read_csv(path, ("t_s",), tuple(f"{p}_A" for p in PHASES), bounds=CSV_BOUNDS)
    _nonempty(table)
    t = table.columns["t_s"]
    _check_increasing(table, "t_s", t, strict=True)
    _check_duration(path, lambda: f"line {table.line(-1)}, column t_s", float(t[-1] - t[0]))
    index, rate = _regular_clock(table)
    _check_rate(path, lambda: f"lines 2–{table.line(-1)}, column t_s", rate, bench)
    phases = {p: table.columns[f"{p}_A"] for p in PHASES if f"{p}_A" in table.columns}
    if not phases:
        raise ConfigError(f"{path}: line 1: no phase column (expected one or more of i_a_A, i_b_A, i_c_A)")
    return CurrentTable(phases, index, rate, float(t[0]), {"format": "csv", "rate_from": "t_s"},
                        _gap_notes("current", index, t, "samples"))


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


def read_current_tdms(path: Path, bench: Bench, channels: tuple[str, ...] = ()) -> CurrentTable:
    """Read and check a current TDMS file; ``channels`` are ``GROUP/CHANNEL`` names, phases a, b, c."""
    from nptdms import TdmsFile  # only imports of TDMS files need it

    if not path.exists():
        raise ConfigError(f"{path}: no such file")
    nptdms_log = logging.getLogger("nptdms")
    level = nptdms_log.level
    nptdms_log.setLevel(logging.ERROR)  # its truncation warnings become our event and one line
    try:
        tdms = TdmsFile.read(path)
    except (ValueError, EOFError, OSError, KeyError) as e:
        raise ConfigError(f"{path}: not a readable TDMS file ({e})") from None
    finally:
        nptdms_log.setLevel(level)
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
    truncated = tdms.file_status.incomplete_final_segment or any(d.size != n for d in data)
    for (name, _), d in zip(picked, data):
        bad = np.flatnonzero(~np.isfinite(d[:n]))
        if bad.size:
            what = "NaN" if np.isnan(d[bad[0]]) else f"{d[bad[0]]} is not finite"
            raise ConfigError(f"{path}: channel {name}, sample {bad[0]}: {what}")
    rate = 1.0 / increments[0]
    _check_duration(path, lambda: f"channel {first}, sample {n - 1}", (n - 1) / rate)
    _check_rate(path, lambda: f"channel {first}, wf_increment", rate, bench)
    t0 = float(picked[0][1].properties.get("wf_start_offset", 0.0))
    info = {"format": "tdms", "rate_from": "wf_increment", "channels": [name for name, _ in picked]}
    notes = [Note(t0 + (n - 1) / rate, "current", "warning", f"{path.name}: truncated last segment; read {n} samples "
                  "per channel, the rest of that segment is missing")] if truncated else []
    return CurrentTable(dict(zip(PHASES, (d[:n] for d in data))), np.arange(n, dtype=np.int64), rate, t0, info, notes)


# ------------------------------------------------------------------------------------ encoder


def read_encoder_csv(path: Path, period_s: float) -> EncoderTable:
    """Read and check an encoder CSV (``t_s, position_counts[, index][, drive_time_s]``)."""
    table = read_csv(path, ("t_s", "position_counts"), ("index", "drive_time_s"), bounds=CSV_BOUNDS)
    _nonempty(table)
    t = table.columns["t_s"]
    _check_increasing(table, "t_s", t, strict=False)  # host stamps: several samples may arrive at once
    _check_duration(path, lambda: f"line {table.line(-1)}, column t_s", float(t[-1] - t[0]))
    position = _register_column(table, "position_counts")
    drive_time = table.columns.get("drive_time_s")
    notes: list[Note] = []
    if "index" in table.columns:
        index, kind = _register_column(table, "index"), "index column"
        _check_increasing(table, "index", index, strict=True)
    elif drive_time is not None:
        index, kind = np.rint((drive_time - drive_time[0]) / period_s).astype(np.int64), "drive_time_s / period_s"
        _check_increasing(table, "drive_time_s", index, strict=True)
    else:
        index, kind = np.arange(table.rows, dtype=np.int64), "row number"
        notes.append(Note(float(t[0]), "encoder", "warning", f"{path.name}: no index or drive_time_s column; drive "
                                                             "cycles taken as row numbers, gaps cannot be detected"))
    notes += _gap_notes("encoder", index, t, "drive cycles")
    return EncoderTable(t, position, index, drive_time, kind, notes)


# ------------------------------------------------------------------------------------ session


def _ns(t_s: np.ndarray | float) -> np.ndarray:
    return np.rint(np.asarray(t_s, dtype=np.float64) * 1e9).astype(np.int64)


def _timeline(cur: CurrentTable, enc: EncoderTable) -> tuple[float, str]:
    """Shift, s, that puts the current's file time on the encoder's, and what it rests on."""
    c0, c1 = (float(x) for x in cur.time_s(cur.sample_index[[0, -1]]))
    e0, e1 = float(enc.t_s[0]), float(enc.t_s[-1])
    overlap = min(c1, e1) - max(c0, e0)
    if overlap >= 0.5 * min(c1 - c0, e1 - e0):
        return 0.0, ("shared: the files' time columns overlap, so they are taken as one host timeline; each current "
                     "block (0.1 s) is stamped with its last sample's time, without transfer latency")
    shift = e0 - c0
    return shift, (f"separate: the files' time columns do not overlap; the current was shifted by {shift:+.6f} s to "
                   "start with the encoder, so host stamps carry no offset between the streams (the analysis "
                   "aligns them from the data)")


def _current_blocks(cur: CurrentTable, shift_s: float) -> Iterator[CurrentBlock]:
    """The current in blocks of ``BLOCK_S`` that never straddle a gap, stamped on the host timeline."""
    values = np.vstack(list(cur.phases_a.values()))
    per_block = max(1, round(cur.rate_hz * BLOCK_S))
    bounds = [0, *(np.flatnonzero(np.diff(cur.sample_index) != 1) + 1), cur.sample_index.size]
    for a, b in zip(bounds[:-1], bounds[1:]):
        for s in range(a, b, per_block):
            e = min(s + per_block, b)
            host = int(_ns(cur.time_s(cur.sample_index[e - 1]) + shift_s))
            yield CurrentBlock(int(cur.sample_index[s]), values[:, s:e], host)


def _file_entry(role: str, path: Path, extra: dict[str, Any]) -> dict[str, Any]:
    return {"role": role, "name": path.name, "path": str(path.resolve()), "sha256": sha256_of(path), **extra}


@dataclass(frozen=True)
class ImportResult:
    """Where the session went, and the warnings found on the way (also stored as events)."""

    path: Path
    warnings: list[str]


def import_session(current_path: Path, encoder_path: Path, bench: Bench, profile: Profile, out: Path,
                   current_channels: tuple[str, ...] = (), tags: dict[str, str | float] | None = None) -> ImportResult:
    """Turn a current file (CSV or TDMS) and an encoder CSV into the session file ``out``.

    Every check runs before anything is written; the file is written under a temporary name and
    renamed at the end, so bad input never leaves a session file behind.

    Raises
    ------
    ConfigError
        Bad input, one line naming the file, line (or channel/sample) and column.
    """
    if out.exists():
        raise ConfigError(f"-o {out}: exists (not overwritten)")
    if current_path.suffix.lower() == ".tdms":
        cur = read_current_tdms(current_path, bench, current_channels)
    else:
        if current_channels:
            raise ConfigError(f"--current-channel: only for TDMS files, not {current_path}")
        cur = read_current_csv(current_path, bench)
    period_s = bench.drive.period_s
    enc = read_encoder_csv(encoder_path, period_s)
    shift, timeline = _timeline(cur, enc)
    origin = {
        "kind": "imported",
        "importer": f"acq {__version__}",
        "files": [_file_entry("current", current_path, cur.file_info), _file_entry("encoder", encoder_path, {})],
        "host_timeline": timeline,
        "encoder_host_ns": "the encoder file's t_s (host arrival stamps), uncorrected",
        "encoder_index": enc.timestamp_kind,
    }
    notes = [*cur.notes, *enc.notes]
    events = sorted((n.event(shift if n.stream == "current" else 0.0) for n in notes), key=lambda e: e.host_ns)
    cpr = getattr(bench.drive, "counts_per_rev", None) or bench.encoder.counts_per_rev
    tmp = out.with_name(f".{out.name}.importing")
    tmp.unlink(missing_ok=True)
    try:
        writer = SessionWriter(
            tmp, bench=bench, profile=profile,
            current_info=CurrentSourceInfo(cur.rate_hz, tuple(cur.phases_a), f"imported: {current_path.name}"),
            drive_info=DriveInfo(period_s, cpr, "imported", enc.timestamp_kind, f"imported: {encoder_path.name}"),
            host_ns_at_start=int(_ns(min(float(cur.time_s(0)) + shift, float(enc.t_s[0])))), origin=origin,
            tags=tags)
        for block in _current_blocks(cur, shift):
            writer.append_current(block)
        writer.append_encoder(EncoderBlock(enc.index, enc.position_counts, _ns(enc.t_s), enc.drive_time_s))
        for event in events:
            writer.add_event(event)
        writer.finish("complete", f"imported from {current_path.name} and {encoder_path.name}")
        if writer.failure is not None:
            raise writer.failure
        os.replace(tmp, out)
    except StorageError as e:  # named by the file asked for; the half-written temp file is removed below
        raise StorageError(str(e).split(" — ")[0].replace(str(tmp), str(out))) from None
    except OSError as e:
        raise storage_error(e, out) from None
    finally:
        tmp.unlink(missing_ok=True)
    return ImportResult(out, [n.detail for n in notes if n.kind == "warning"])


@click.command("import")
@click.option("--current", "current_path", required=True, type=click.Path(path_type=Path),
              help="Current file: CSV (t_s, i_a_A [, i_b_A, i_c_A]) or TDMS.")
@click.option("--current-channel", "current_channels", multiple=True, metavar="GROUP/CHANNEL",
              help="TDMS channel of a phase, repeat in phase order a, b, c (default: the file's only channel).")
@click.option("--encoder", "encoder_path", required=True, type=click.Path(path_type=Path),
              help="Encoder CSV (t_s, position_counts [, index] [, drive_time_s]).")
@click.option("--bench", "bench_path", required=True, type=click.Path(path_type=Path), help="Bench TOML.")
@click.option("--profile", "profile_name", required=True, help="Profile name in configs/profiles/ or a TOML path.")
@click.option("--joint", default=None, help="Joint name (default: the bench config's).")
@click.option("-o", "--out", "out_path", required=True, type=click.Path(path_type=Path), help="Session file to write.")
@tag_option
def import_command(current_path: Path, current_channels: tuple[str, ...], encoder_path: Path, bench_path: Path,
                   profile_name: str, joint: str | None, out_path: Path, tags: tuple[str, ...]) -> int:
    """Turn a current file and an encoder CSV recorded by other tools into a session."""
    bench = load_bench(bench_path)
    bench = with_joint(bench, joint)
    result = import_session(current_path, encoder_path, bench, load_profile(profile_name), out_path, current_channels,
                            tags=parse_tags(tags))
    console = Console()
    console.print(summary_table(summarize(load(result.path))))
    for warning in result.warnings:
        Console(stderr=True).print(f"[yellow]warning[/]: {escape(warning)}")
    console.print(f"imported → {escape(str(result.path))}")
    return 0
