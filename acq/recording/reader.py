"""Read a session file (layout: :mod:`acq.recording.layout`) into a :class:`~acq.recording.session.Session`.

Integrity: every dataset carries HDF5 Fletcher32 checksums per chunk. A reader trusts only what
was committed (the footer's counts, or the last ``/flushes`` row of a session still ``recording``),
reads chunk by chunk with bounded metadata reads (:mod:`acq.recording.h5safe`) and reports what it could not
read as :attr:`Session.damage` ("current: samples 62 550–102 399 unreadable", one line per span). A chunk whose
checksum fails costs its own rows only (a hole, :mod:`acq.recording.holes`: the rows after it are kept, the loss
seen as a gap); a chunk never written or beyond the file's end ends the intact part (the tail).
"""

from __future__ import annotations

import errno
from pathlib import Path
from typing import Any

import h5py
import numpy as np
from pydantic import ValidationError

from acq.recording.h5safe import open_read, superblock_eof, zero_tail_start
from acq.recording.commits import FLUSHES, commit_stamps, committed_counts, flushes_damage, stamped
from acq.recording.holes import Column, Span, current_rows, lost_spans, only_zeroed, readable
from acq.recording.layout import FOOTER_TEXT, FORMAT, FORMAT_VERSION, OPTIONAL_ENCODER
from acq.recording.paths import require_session_file
from acq.recording.root_attrs import check_root_attributes, check_text
from acq.recording.session import CurrentData, EncoderData, Session
from acq.recording.zeroed import invented, zero_chunks
from acq.recording.storage import cause_of
from drivers.base import StreamEvent
from drivers.config import Bench, Profile
from acqcore.errors import ConfigError


def _attr(value: Any) -> Any:
    """An attribute as Python: a fixed-length text (bytes, the footer's) decoded as h5py decodes a variable-length one —
    a byte that is not UTF-8 (a flipped bit) kept as a surrogate escape, for :mod:`acq.recording.root_attrs` to name."""
    if isinstance(value, bytes):
        return value.decode("utf-8", "surrogateescape")
    if isinstance(value, np.generic):
        return value.item()
    return value


def _open_for_reading(path: Path) -> tuple[h5py.File, list[str]]:
    """Open a session for reading with bounds; a file shorter than its superblock says is reported as cut."""
    require_session_file(path)
    notes: list[str] = []
    size = path.stat().st_size
    if size == 0:  # HDF5 would say "file signature not found"
        raise ConfigError(f"{path}: empty (0 bytes), not a session file")
    try:
        eof = superblock_eof(path)
    except OSError as e:
        raise ConfigError(f"{path}: cannot read ({cause_of(e)})") from None
    if eof is not None and size < eof:
        notes.append(f"file cut: {size:,} of {eof:,} bytes".replace(",", " "))
    try:
        return open_read(path), notes
    except (OSError, RuntimeError) as e:
        first_line = str(e).splitlines()[0] if str(e) else type(e).__name__
        if "file signature not found" in first_line:  # HDF5's words for a file of another kind
            first_line = "no HDF5 signature: another kind of file"
        # EAGAIN/EWOULDBLOCK (11 on Linux): a writer holds HDF5's lock — a recorder making the file has it until its
        # SWMR writing starts (tens of ms), any other HDF5 writer for as long as it writes: a file being written, not
        # one cut, whatever its size says. Any other errno: the file system's locks failed (open_read skips ENOSYS)
        locked = "unable to lock file" in first_line
        if locked and any(f"errno = {n}," in first_line for n in {errno.EAGAIN, errno.EWOULDBLOCK}):
            first_line = "locked by a process writing it (a recording just starting?) — try again in a moment"
        elif locked:
            first_line += " — where the file system has no working locks, HDF5_USE_FILE_LOCKING=FALSE reads without"
        why = notes[0] if notes and not locked else first_line
        raise ConfigError(f"{path}: not a readable HDF5 session file ({why})") from None


def _span(stream: str, first: int, end: int, what: str = "unreadable") -> str:
    """One damage line: a stream's samples, or the rows of a table dataset (``/flushes``, ``current/blocks/…``)."""
    if stream == FLUSHES or "/" in stream:
        rows = f"row {first:,}" if end - first == 1 else f"rows {first:,}–{end - 1:,}"
        return f"{stream}: {rows} {what}".replace(",", " ")
    return f"{stream}: samples {first:,}–{end - 1:,} {what}".replace(",", " ")


#: A damaged span found while reading: (stream, first row, end row, what), the words of :func:`_span`.
Damage = tuple[str, int, int, str]
#: Said of a file whose current's host stamps are all lost and that :func:`acq.recording.holes.current_rows` stamped
#: by its commits: read with ``host_clock_shared`` false, the analysis relates the streams' clocks from the data alone.
STAMPS_FROM_COMMITS = ("current/blocks/host_ns: every host stamp lost — the current kept on the DAQ's clock, each read "
                       "stamped by the commit that stored it; its clock is related to the encoder's from the data alone")
#: What a span lost to chunks the storage zeroed is called (a checksum failure or a tail: "unreadable").
ZEROED = "zeroed on disk"


def _lost(stream: str, keep: np.ndarray, zeroed: np.ndarray, total: int) -> list[Damage]:
    """The spans of rows ``[0, total)`` of ``stream`` not in ``keep``, in order: :data:`ZEROED` those in ``zeroed``
    (lost to zeroed chunks only), "unreadable" the others."""
    spans = [(stream, a, b, "unreadable") for a, b in lost_spans(keep | zeroed, total)]
    spans += [(stream, a, b, ZEROED) for a, b in lost_spans(~zeroed, zeroed.size)]
    return sorted(spans, key=lambda span: span[1])


class _Reader:
    """Reads datasets of one open file chunk by chunk, up to the committed length; never past the file's end."""

    def __init__(self, f: h5py.File, path: Path, notes: list[str], end: int) -> None:
        self.f, self.path, self.notes = f, path, notes
        self.size = end  # where its data ends: the file's size, or where a tail of zeros begins

    def node(self, name: str) -> Any:
        try:
            return self.f[name]
        except (KeyError, OSError, RuntimeError):
            what = "damaged" if self.notes else "malformed session"
            why = f" ({self.notes[0]})" if self.notes else ""
            raise ConfigError(f"{self.path}: {what}: /{name} is missing or unreadable{why}") from None

    def column(self, name: str, n: int | None) -> Column:
        """The first ``n`` rows (all stored if None) of dataset ``name``, its holes and the first row not readable.

        Rows are read one chunk at a time when a single read fails: a chunk whose checksum fails is a hole (its rows
        are marked, the next chunks read on); a chunk beyond the end of the file, never written (its rows would read
        as zeros) or whose place HDF5 cannot tell ends the readable rows. A chunk the storage zeroed (it passes its
        checksum) is a hole when its rows cannot be real (:mod:`acq.recording.zeroed`).
        """
        ds = self.node(name)
        if not isinstance(ds, h5py.Dataset) or ds.ndim != 1:
            raise ConfigError(f"{self.path}: malformed session: /{name} is not a 1-D dataset")
        stored = ds.shape[0]
        want = stored if n is None else n
        have = min(want, stored)
        out = np.empty(have, dtype=ds.dtype)
        chunked = ds.chunks is not None
        step = ds.chunks[0] if chunked else max(have, 1)
        zero_step = step if chunked else 0  # chunks to look for zeroed ones in (none without checksums)
        short = have if have < want else None
        if have and chunked and self._all_on_disk(ds, have, step):
            try:  # the usual case, an intact file: one read (checksums verified), 4× faster than chunk by chunk
                ds.read_direct(out, np.s_[0:have], np.s_[0:have])
                return _checked_for_zeros(name, ds, zero_step, out, short, ())
            except (OSError, RuntimeError, ValueError):
                pass  # a checksum fails somewhere: find where, chunk by chunk
        holes: list[Span] = []
        for start in range(0, have, step):
            stop = min(start + step, have)
            try:
                if chunked and not self._on_disk(ds.id.get_chunk_info_by_coord((start,))):
                    return _checked_for_zeros(name, ds, zero_step, out[:start], start, tuple(holes))
            except (OSError, RuntimeError, ValueError):
                return _checked_for_zeros(name, ds, zero_step, out[:start], start, tuple(holes))
            try:
                out[start:stop] = ds[start:stop]
            except (OSError, RuntimeError, ValueError):
                if not chunked:  # no checksums to fail: the data cannot be read at all
                    return Column(out[:start], start, tuple(holes))
                if holes and holes[-1][1] == start:
                    holes[-1] = (holes[-1][0], stop)
                else:
                    holes.append((start, stop))
        return _checked_for_zeros(name, ds, zero_step, out, short, tuple(holes))

    def _on_disk(self, info: Any) -> bool:
        """A chunk (HDF5's chunk info) was written and lies inside the file (a never-written one reads as zeros)."""
        return info.byte_offset is not None and info.byte_offset + info.size <= self.size

    def _all_on_disk(self, ds: h5py.Dataset, rows: int, step: int) -> bool:
        """Every chunk holding the first ``rows`` rows was written and lies inside the file (HDF5's chunk
        iteration: one pass over the chunk index, ≈ 1 µs a chunk); False when it cannot tell."""
        if not hasattr(ds.id, "chunk_iter"):  # HDF5 < 1.12.3
            return False
        inside: list[bool] = []

        def visit(info: Any) -> None:
            if info.chunk_offset[0] < rows:
                inside.append(self._on_disk(info))

        try:
            ds.id.chunk_iter(visit)
        except (OSError, RuntimeError, ValueError):
            return False
        return len(inside) == -(-rows // step) and all(inside)


def _checked_for_zeros(name: str, ds: h5py.Dataset, step: int, values: np.ndarray, lost_from: int | None,
                       holes: tuple[Span, ...]) -> Column:
    """The column read (of chunks of ``step`` rows; 0: not chunked, no checksums), with the chunks the storage zeroed
    whose rows cannot be real (:mod:`acq.recording.zeroed`)."""
    chunks = zero_chunks(ds, step, values, holes) if step else []
    return Column(values, lost_from, holes, invented(name, values, chunks, holes) if chunks else ())


def _read_current(reader: _Reader, committed: dict[str, int] | None, damage: list[Damage],
                  flushes: Column | None) -> tuple[CurrentData, bool]:
    """The current as read, and whether its reads are stamped by their commits (every host stamp of its own lost,
    :func:`acq.recording.holes.current_rows`)."""
    g = reader.node("current")
    n_blocks = None if committed is None else committed.get("current_blocks")
    table = [reader.column(f"current/blocks/{name}", n_blocks) for name in ("count", "first_index", "host_ns")]
    if committed is None:
        table = stamped(table, table[2])
    try:
        rate_hz, device = float(g.attrs["rate_hz"]), str(_attr(g.attrs["device"]))
        channels = [c for c in str(_attr(g.attrs["channels"])).split(",") if c]
    except (KeyError, ValueError, TypeError):
        raise ConfigError(f"{reader.path}: malformed session: /current lacks a valid rate_hz, device or channels "
                          "attribute") from None
    for name, value in (("device", device), ("channels", ",".join(channels))):
        check_text(reader.path, f"current/{name}", value)
    if not channels:
        raise ConfigError(f"{reader.path}: malformed session: /current names no channels")
    want = None if committed is None else committed["current_samples"]
    columns = {ch: reader.column(f"current/{ch}_A", want) for ch in channels}
    if any(c.lost for c in [*table, *columns.values()]):
        return _current_with_holes(rate_hz, device, table, columns, want, damage,
                                   commit_stamps(flushes, min(len(c.values) for c in table)))
    counts, first, host = (c.values for c in table)
    phases = {ch: c.values for ch, c in columns.items()}
    stored = min(len(first), len(counts), len(host))
    counts, first, host = counts[:stored], first[:stored], host[:stored]
    n = min([int(counts.sum())] + [len(v) for v in phases.values()])
    while stored and int(counts.sum()) > n:  # a kill between writing samples and the block row, or damage
        stored -= 1
        counts, first, host = counts[:stored], first[:stored], host[:stored]
    n = int(counts.sum())
    total = want if want is not None else max([n] + [len(v) for v in phases.values()])
    if any(c.damaged for c in [*table, *columns.values()]) and n < total:
        damage.append(("current", n, total, "unreadable"))
    return CurrentData(rate_hz=rate_hz, device=device, phases_a={ch: v[:n] for ch, v in phases.items()},
                       block_first_index=first, block_count=counts, block_host_ns=host), False


def _current_with_holes(rate_hz: float, device: str, table: list[Column], columns: dict[str, Column],
                        want: int | None, damage: list[Damage], commit_ns: np.ndarray | None
                        ) -> tuple[CurrentData, bool]:
    """The current of a file with a hole in a phase or the block table (:func:`acq.recording.holes.current_rows`):
    the samples after it kept, the loss a jump in the DAQ sample index, one damage line per span lost."""
    rows = current_rows(*table, list(columns.values()), want, commit_ns)
    keep = rows.sample_keep
    total = want if want is not None else max(len(c.values) for c in columns.values())
    for name, column in zip(("count", "first_index", "host_ns"), table):  # the block rows, named by their dataset
        damage.extend((f"current/blocks/{name}", a, b, ZEROED if (a, b) in column.zeroed else "unreadable")
                      for a, b in sorted(column.lost))
    damage.extend(_lost("current", keep, rows.zeroed, total))
    return CurrentData(rate_hz=rate_hz, device=device,
                       phases_a={ch: c.values[:keep.size][keep] for ch, c in columns.items()},
                       block_first_index=rows.first_index, block_count=rows.count,
                       block_host_ns=rows.host_ns), rows.stamps_from_commits


def _read_encoder(reader: _Reader, committed: dict[str, int] | None, damage: list[Damage]) -> EncoderData:
    g = reader.node("encoder")
    want = None if committed is None else committed["encoder_samples"]
    columns = {name: reader.column(f"encoder/{name}", want) for name in ("position_counts", "index", "host_ns")}
    for name in OPTIONAL_ENCODER:
        if name in g:
            columns[name] = reader.column(f"encoder/{name}", want)
    if committed is None:
        columns = dict(zip(columns, stamped(list(columns.values()), columns["host_ns"])))
    n = min(len(c.values) for c in columns.values())
    total = want if want is not None else max(len(c.values) for c in columns.values())
    keep = readable(list(columns.values()), n)  # a row lost in one column is lost in all: a jump in the cycle index
    if any(c.damaged for c in columns.values()):
        damage.extend(_lost("encoder", keep, only_zeroed(list(columns.values()), n), total))
    kept = {name: c.values[:n] if keep.all() else c.values[:n][keep] for name, c in columns.items()}

    def optional(name: str) -> np.ndarray | None:
        """The column, None when absent or all NaN: the writer creates every optional column and fills what a drive
        does not give with NaN until :func:`acq.recording.layout.write_footer` deletes it, so while a session records
        (or after its recorder was killed) a column of NaN only is one the drive has not given."""
        values = kept.get(name)
        return None if values is None or np.isnan(values).all() else values

    try:
        period_s, counts_per_rev = float(g.attrs["period_s"]), int(g.attrs["counts_per_rev"])
        transport, kind = str(_attr(g.attrs["transport"])), str(_attr(g.attrs["timestamp_kind"]))
        device = str(_attr(g.attrs["device"]))
    except (KeyError, ValueError, TypeError):
        raise ConfigError(f"{reader.path}: malformed session: /encoder lacks a valid period_s, counts_per_rev, "
                          "transport, timestamp_kind or device attribute") from None
    for name, value in (("transport", transport), ("timestamp_kind", kind), ("device", device)):
        check_text(reader.path, f"encoder/{name}", value)
    return EncoderData(
        period_s=period_s, counts_per_rev=counts_per_rev, transport=transport, timestamp_kind=kind, device=device,
        position_counts=kept["position_counts"], index=kept["index"], host_ns=kept["host_ns"],
        **{name: optional(name) for name in OPTIONAL_ENCODER},
    )


def _read_events(reader: _Reader, committed: dict[str, int] | None, damage: list[Damage]) -> list[StreamEvent]:
    events = reader.column("events", None if committed is None else committed.get("events"))
    rows, bad = events.values[readable((events,), len(events.values))], events.lost_from
    damage.extend(sorted([*(("events", a, b, "lost") for a, b in events.holes),
                          *(("events", a, b, ZEROED) for a, b in events.zeroed)], key=lambda span: span[1]))
    if bad is not None:
        n = len(events.values)
        damage.append(("events", n, bad + 1 if bad >= n else n + 1, "lost"))
    return [
        StreamEvent(int(r["host_ns"]), r["stream"].decode("utf-8", "replace"), r["kind"].decode("utf-8", "replace"),  # type: ignore[arg-type]
                    r["detail"].decode("utf-8", "replace"))
        for r in rows
    ]


def _config_attr(p: Path, attrs: dict[str, Any], name: str, model: type[Bench] | type[Profile]) -> Any:
    text = attrs.get(name)
    if not isinstance(text, str):
        raise ConfigError(f"{p}: malformed session: attribute {name} is missing")
    try:
        return model.model_validate_json(text)
    except ValidationError as e:
        err = e.errors()[0]
        where = ".".join(str(part) for part in err["loc"])
        detail = f"{where}: {err['msg']}" if where else err["msg"]
        raise ConfigError(f"{p}: malformed session: attribute {name} is not a valid {model.__name__.lower()} "
                          f"({detail})") from None


def read_status(path: Path | str) -> str:
    """The ``status`` attribute alone (cheap: no data read); ``""`` when the file has none."""
    p = Path(path)
    f, _ = _open_for_reading(p)
    with f:
        try:
            return str(_attr(f.attrs.get("status", "")))
        except (OSError, RuntimeError):
            return ""


def load(path: Path | str) -> Session:
    """Read a whole session (also one still being recorded, left by a killed recorder, or damaged).

    Only committed samples are read (see the module doc); what cannot be read is listed in
    :attr:`Session.damage`. A file that is not a session, or lacks a group or attribute, raises
    :class:`ConfigError` naming the file and what is wrong.
    """
    p = Path(path)
    f, notes = _open_for_reading(p)
    try:
        with f:
            return _load_open(p, f, notes)
    except (OSError, RuntimeError, KeyError, ValueError) as e:  # h5py's errors for metadata it cannot read
        first = (str(e).splitlines() or [type(e).__name__])[0].strip("'\"")
        why = f"{notes[0]}: {first}" if notes else first
        raise ConfigError(f"{p}: damaged, cannot be read ({why})") from None


def _root_attrs(p: Path, f: h5py.File, notes: list[str]) -> tuple[dict[str, Any], int]:
    """The root attributes and where the file's data ends, in bytes. Of a cut file, the footer's strings HDF5 put past
    the cut are left out and named in ``notes`` ("file cut: … bytes, stop_reason lost"); so are they when the file
    ends in zeros from before them (a cut copy pre-allocated to its full size: "file zeroed from byte … to its end"),
    and its data ends there. Any other attribute unreadable: not a session to read."""
    why = f"{notes[0]}, root attributes lost" if notes else "root attributes unreadable"
    attrs: dict[str, Any] = {}
    lost: list[str] = []
    end = p.stat().st_size
    try:
        names = list(f.attrs)
    except (OSError, RuntimeError, KeyError):
        raise ConfigError(f"{p}: not a readable HDF5 session file ({why})") from None
    for name in names:
        try:
            attrs[name] = _attr(f.attrs[name])
        except (OSError, RuntimeError, KeyError):
            if not notes and name in FOOTER_TEXT and (zeros := zero_tail_start(p)) < end:
                notes.append(f"file zeroed from byte {zeros:,} to its end ({end:,} bytes)".replace(",", " "))
                end = zeros
            if not notes or name not in FOOTER_TEXT:
                raise ConfigError(f"{p}: not a readable HDF5 session file ({why})") from None
            lost.append(name)
    if lost:
        notes[0] += f", {' and '.join(lost)} lost"
    return attrs, end


def _load_open(p: Path, f: h5py.File, notes: list[str]) -> Session:
    attrs, end = _root_attrs(p, f, notes)
    if attrs.get("format") != FORMAT:
        raise ConfigError(f"{p}: not an acq session (format attribute is {attrs.get('format')!r})")
    try:
        version = int(attrs.get("format_version", 0))
    except (TypeError, ValueError):
        raise ConfigError(f"{p}: malformed session: format_version {attrs.get('format_version')!r}") from None
    if version > FORMAT_VERSION:
        raise ConfigError(f"{p}: format_version {version} is newer than this acq reads ({FORMAT_VERSION})")
    check_root_attributes(p, attrs)
    bench = _config_attr(p, attrs, "bench_json", Bench)
    profile = None if attrs.get("profile_json") == "null" else _config_attr(p, attrs, "profile_json", Profile)
    reader = _Reader(f, p, notes, end)
    flushes = reader.column(FLUSHES, None) if FLUSHES in f else None  # read whole: its checksums verified too
    committed = committed_counts(attrs, flushes)
    damage: list[Damage] = [] if flushes is None else flushes_damage(flushes, reader.node(FLUSHES).shape[0],
                                                                      committed)
    current, stamped_by_commits = _read_current(reader, committed, damage, flushes)
    if stamped_by_commits:  # the commits' stamps are late by up to a commit's interval: no prior for the clock search
        notes.append(STAMPS_FROM_COMMITS)
        attrs = {**attrs, "host_clock_shared": False}
    encoder = _read_encoder(reader, committed, damage)
    events = _read_events(reader, committed, damage)
    lines = (*notes, *(_span(*span) for span in damage))
    return Session(path=p, attrs=attrs, bench=bench, profile=profile, current=current, encoder=encoder,
                   events=events, damage=lines, damage_spans=tuple(span[:3] for span in damage))
