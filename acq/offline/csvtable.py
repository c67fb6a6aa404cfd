"""Read a numeric CSV table fast, and name the file, line and column of anything wrong in it.

The body is parsed by Apache Arrow's CSV reader (:func:`pyarrow.csv.read_csv`: 0.08 s CPU for 1.5 M
rows × 2 columns, numpy's :func:`numpy.loadtxt` took 0.34 s; both read every value to the same bits, as
Arrow's float parser rounds correctly). Only when Arrow refuses the file is it read the old way —
:func:`numpy.loadtxt`, and when that refuses it too, line by line to find the first bad cell — so
valid files pay nothing for the diagnosis and a bad one gets the same message as before. Errors are :class:`~acqcore.errors.ConfigError` s of the
form ``FILE: line L, column NAME: what`` (line 1 is the header).
"""

from __future__ import annotations

import csv
import difflib
import re
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.csv as pa_csv

from acqcore.errors import ConfigError

#: Largest block Arrow's CSV reader parses at once: a 60 s file of one phase at 25.6 kS/s (49 MB) is one block.
#: Bounds the reader's buffer for longer files (read in blocks of this size, their columns joined once).
BLOCK_BYTES = 64 << 20
#: Data lines looked at for decimal commas (:func:`_decimal_comma`): a tool writes every line alike.
DECIMAL_COMMA_LINES = 20
_INTEGER = re.compile(r"-?\d+(?:[eE][-+]?\d+)?")  # what a decimal-comma number's two halves look like
_WITH_LEADING_ZERO = re.compile(r"0\d+(?:[eE][-+]?\d+)?")  # "0374" of "0,0374": no integer is written so
_READS_DECIMAL_COMMA = "write the file with '.' decimals (acq reads ',' between columns and '.' as the decimal point)"


@dataclass(frozen=True)
class CsvTable:
    """The columns of a CSV file, float64, by header name, with the way back to line numbers.

    Attributes
    ----------
    path : Path
        The file read.
    columns : dict of str to ndarray
        One float64 array per header name, in header order; possibly read-only (a view of Arrow's memory).
    """

    path: Path
    columns: dict[str, np.ndarray]
    #: The line left out as the file was cut in it (its last line, without an end of line), or None.
    cut_line: int | None = None

    @property
    def rows(self) -> int:
        """Data rows read."""
        return next(iter(self.columns.values())).shape[0]

    def line(self, row: int) -> int:
        """The file's line number (1-based, header = 1) of data row ``row`` (0-based; -1 is the last).

        Found by reading the file again (blank lines are not rows): for error messages only.
        """
        return _data_line_numbers(self.path)[row]

    def error(self, row: int, column: str, what: str) -> ConfigError:
        """A one-line error naming the file, the line of ``row`` and ``column``."""
        return ConfigError(f"{self.path}: line {self.line(row)}, column {column}: {what}")


def read_csv(path: Path, required: tuple[str, ...], optional: tuple[str, ...] = (),
             bounds: dict[str, float] | None = None, data: pa.Buffer | None = None) -> CsvTable:
    """Read a comma-separated file whose header names its columns.

    Parameters
    ----------
    path : Path
        The CSV file: one header row, then one row of numbers per sample.
    required : tuple of str
        Column names that must be present.
    optional : tuple of str
        Column names that may be present; any other name is an error (a misspelt header).
    bounds : dict of str to float, optional
        Physical bound per column: a cell whose magnitude exceeds it is an error.
    data : pyarrow.Buffer, optional
        The file's bytes as :func:`file_bytes` read them: parsed from memory instead of reading the file again.

    Returns
    -------
    CsvTable

    Raises
    ------
    ConfigError
        No such file, an unknown, duplicate or missing column, a wrong number of fields, a cell that
        is not a number, or a cell that is NaN or infinite.

    A last data line without its end of line is where the file was cut (a copy or a writer stopped mid-line:
    "4.963957424,-0." would read as −0.0): it is left out, and :attr:`CsvTable.cut_line` names it.
    """
    names = _header(path, required, optional)
    fault = _decimal_comma(path, len(names))
    if fault is not None:
        raise ConfigError(f"{path}: {fault}")
    cut = _unended_last_line(path, data)
    if cut is not None:
        data = (data if data is not None else pa.memory_map(str(path)).read_buffer()).slice(0, cut[1])
    columns = _parse_with_arrow(path, names, data)
    if columns is None:
        rows = _parse_with_numpy(path, names, None if cut is None else cut[0])
        columns = [np.ascontiguousarray(rows[:, i]) for i in range(len(names))]
    table = CsvTable(path, dict(zip(names, columns)), None if cut is None else cut[0])
    limits = bounds or {}
    for name, values in table.columns.items():
        # min and max propagate NaN: two passes without temporaries clear a valid column; the cell is looked
        # for only when something is wrong
        low, high = (values.min(), values.max()) if values.size else (0.0, 0.0)
        limit = limits.get(name, np.inf)
        if not (-limit <= low and high <= limit and np.isfinite(low) and np.isfinite(high)):
            raise _first_bad_value(table, limits)
    return table


def _first_bad_value(table: CsvTable, limits: dict[str, float]) -> ConfigError:
    """The error for the first cell (row by row) that is not finite, else the first beyond its column's bound."""
    names = list(table.columns)
    data = np.column_stack(list(table.columns.values()))
    bad = ~np.isfinite(data)
    if bad.any():
        row, col = np.unravel_index(int(np.argmax(bad)), data.shape)
        value = data[row, col]
        return table.error(int(row), names[int(col)], "NaN" if np.isnan(value) else f"{value} is not finite")
    name, limit = next((n, limit) for n, limit in limits.items()
                       if n in table.columns and (np.abs(table.columns[n]) > limit).any())
    row = int(np.argmax(np.abs(table.columns[name]) > limit))
    return table.error(row, name, f"{table.columns[name][row]:g} is beyond the physical bound ±{limit:g}")


def file_bytes(path: Path) -> pa.Buffer | None:
    """A file's bytes read at once, to be parsed and hashed alike (one read; the hash is of the bytes parsed), when
    it fits one parse block (``BLOCK_BYTES``); None for a larger file (parsed in blocks) or one not readable (then
    :func:`read_csv` says why)."""
    try:
        if path.stat().st_size > BLOCK_BYTES:
            return None
        with pa.OSFile(str(path)) as f:
            return f.read_buffer()
    except (OSError, pa.ArrowException):
        return None


def _parse_with_arrow(path: Path, names: list[str], data: pa.Buffer | None) -> list[np.ndarray] | None:
    """The data columns as contiguous float64 arrays, or None when Arrow refuses anything in them.

    As strict as :func:`numpy.loadtxt` below, or stricter: no quotes, no empty cell read as missing, blank lines
    skipped; any row with another number of fields, or a cell that is not a number, refuses the file.
    """
    try:
        # one thread: Arrow's pool costs ≈ 10 % more CPU for no shorter wall time on 2 cores while the import
        # hashes the file in another thread (acq.offline.importers). One block for a file up to BLOCK_BYTES: each
        # column is then one chunk, handed to numpy without a copy (and the per-block work is done once)
        block_bytes = min((path.stat().st_size if data is None else data.size) + 1, BLOCK_BYTES)
        table = pa_csv.read_csv(
            path if data is None else pa.BufferReader(data),
            read_options=pa_csv.ReadOptions(column_names=names, skip_rows=1, use_threads=False,
                                            block_size=block_bytes),
            parse_options=pa_csv.ParseOptions(delimiter=",", quote_char=False, double_quote=False, escape_char=False,
                                              newlines_in_values=False, ignore_empty_lines=True),
            convert_options=pa_csv.ConvertOptions(column_types=dict.fromkeys(names, pa.float64()), null_values=[],
                                                  strings_can_be_null=False, quoted_strings_can_be_null=False))
    except (pa.ArrowException, UnicodeDecodeError):
        return None
    if any(column.null_count for column in table.columns):
        return None
    # one chunk: a read-only view of Arrow's memory (nothing writes into a table's columns); several: joined, a copy
    return [column.to_numpy() for column in table.columns]


def _parse_with_numpy(path: Path, names: list[str], cut_line: int | None = None) -> np.ndarray:
    """The data rows as :func:`numpy.loadtxt` reads them (those before ``cut_line``, if given); where it cannot, the
    error names the first bad cell."""
    rows = None if cut_line is None else len(_data_line_numbers(path)) - 1  # blank lines are not counted either
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # "input contained no data": the caller checks length
        try:
            data = np.loadtxt(path, delimiter=",", skiprows=1, comments=None, quotechar=None, ndmin=2,
                              dtype=np.float64, encoding="utf-8-sig", max_rows=rows)
        except ValueError as e:
            raise _first_bad_cell(path, names, cut_line) or ConfigError(f"{path}: {e}") from None
    if data.shape[0] and data.shape[1] != len(names):  # every row wider than the header: loadtxt reads them all
        raise (_first_bad_cell(path, names, cut_line)
               or ConfigError(f"{path}: {data.shape[1]} fields, the header has {len(names)}"))
    return data if data.shape[0] else np.zeros((0, len(names)))


def _header(path: Path, required: tuple[str, ...], optional: tuple[str, ...]) -> list[str]:
    known = (*required, *optional)
    expected = ", ".join(known)
    try:
        with path.open(encoding="utf-8-sig", newline="") as f:
            first = f.readline()
            if not first.strip():  # no header: a file with nothing in it, or the header not on line 1
                if not any(line.strip() for line in f):
                    raise ConfigError(f"{path}: the file is empty (expected a header line {expected}, then data rows)")
                raise ConfigError(f"{path}: line 1: empty, the header must be the first line (expected {expected})")
    except FileNotFoundError:
        raise ConfigError(f"{path}: no such file") from None
    except (OSError, UnicodeDecodeError) as e:
        raise ConfigError(f"{path}: cannot be read as text ({e})") from None
    names = [n.strip() for n in first.strip().split(",")]
    for name in names:
        if name not in known:
            close = difflib.get_close_matches(name, known, n=1, cutoff=0.6)
            other = next((sep for sep in (";", "\t", "|") if any(n in known for n in name.split(sep))), None)
            commas = "" if other is None else _decimal_comma_in(path, other)
            decimals = " with '.' decimals" if commas else ""
            hint = (f"the columns are separated by {other!r}{commas}; acq reads comma-separated files{decimals}: "
                    if other is not None else f"did you mean {close[0]}? " if close else "")
            raise ConfigError(f"{path}: line 1, column {name or '(empty)'}: unknown column ({hint}expected {expected})")
        if names.count(name) > 1:
            raise ConfigError(f"{path}: line 1, column {name}: appears twice")
    for name in required:
        if name not in names:
            raise ConfigError(f"{path}: line 1, column {name}: missing (the header is {first.strip()!r})")
    return names


def _data_lines(path: Path) -> list[tuple[int, str]]:
    """The first :data:`DECIMAL_COMMA_LINES` non-blank data lines with their line numbers (empty if unreadable)."""
    found: list[tuple[int, str]] = []
    try:
        with path.open(encoding="utf-8-sig", newline="") as f:
            for line, text in enumerate(f, start=1):
                if line > 1 and text.strip():
                    found.append((line, text.strip()))
                    if len(found) == DECIMAL_COMMA_LINES:
                        break
    except (OSError, UnicodeDecodeError):
        pass  # the parser names what is wrong with the file
    return found


def _decimal_comma(path: Path, columns: int) -> str | None:
    """What is wrong when the first data lines read as numbers written with a decimal comma, else None.

    A comma-separated line without any '.' whose fields are all integers, either more of them than the header
    has columns (each "0,0374" became two fields) or one with a leading zero after another ("0,0374": no tool
    writes the integer 0374) — a line of equal width would otherwise parse into wrong numbers (a current of
    3.7·10⁷ A, an index that does not increase) and be blamed on the value.
    """
    for line, text in _data_lines(path):
        if "." in text:
            continue
        fields = [f.strip() for f in text.split(",")]
        if not all(_INTEGER.fullmatch(f) for f in fields):
            continue
        if len(fields) > columns:
            return f"line {line} has {len(fields)} fields for {columns} columns — decimal commas? ({text}): " + \
                _READS_DECIMAL_COMMA
        pair = next((f"{a},{b}" for a, b in zip(fields, fields[1:]) if _WITH_LEADING_ZERO.fullmatch(b)), None)
        if pair is not None:
            return f"line {line}: {pair!r} looks like a number with a decimal comma — {_READS_DECIMAL_COMMA}"
    return None


def _decimal_comma_in(path: Path, separator: str) -> str:
    """`` and the numbers have decimal commas (line L: 'x,y')`` when a data line separated by ``separator`` has a
    field like ``0,0374``, else ``""``."""
    for line, text in _data_lines(path)[:1]:
        field = next((f.strip() for f in text.split(separator) if re.fullmatch(r"-?\d+,\d+", f.strip())), None)
        if field is not None:
            return f" and the numbers have decimal commas (line {line}: {field!r})"
    return ""


def _first_bad_cell(path: Path, names: list[str], cut_line: int | None = None) -> ConfigError | None:
    """The first row numpy could not read (before ``cut_line``, if given), found by reading the file again line by
    line."""
    with path.open(encoding="utf-8-sig", newline="") as f:
        for line, fields in enumerate(csv.reader(f), start=1):
            if line == cut_line:
                break
            if line == 1 or not fields:
                continue
            if len(fields) != len(names):
                return ConfigError(f"{path}: line {line}: {len(fields)} fields, the header has {len(names)}")
            for name, cell in zip(names, fields):
                try:
                    float(cell)
                except ValueError:
                    what = "empty cell" if not cell.strip() else f"{cell.strip()!r} is not a number"
                    return ConfigError(f"{path}: line {line}, column {name}: {what}")
    return None


def _unended_last_line(path: Path, data: pa.Buffer | None) -> tuple[int, int] | None:
    """The line number and first byte of the file's last line when it is a data line (not the header) with text but
    no end of line — the file was cut in it; else None."""
    if data is None:
        data = pa.memory_map(str(path)).read_buffer()  # mapped, not read: only its end is looked at unless cut
    if data.size == 0 or data.slice(data.size - 1).to_pybytes() in (b"\r", b"\n"):
        return None  # a whole file: nothing more is looked at
    raw = np.frombuffer(data, dtype=np.uint8)
    ends = np.flatnonzero((raw == ord("\n")) | (raw == ord("\r")))
    if ends.size == 0 or not bytes(raw[ends[-1] + 1:]).strip():
        return None  # the header alone, or trailing blanks
    lines = int(np.count_nonzero(raw[:ends[-1] + 1] == ord("\n")))
    lines = lines if lines else ends.size  # old Mac files end their lines with "\r" alone
    return lines + 1, int(ends[-1]) + 1


def _data_line_numbers(path: Path) -> list[int]:
    """Line numbers of the non-blank lines after the header (what numpy counts as rows)."""
    with path.open("rb") as f:
        return [i for i, text in enumerate(f, start=1) if i > 1 and text.strip()]
