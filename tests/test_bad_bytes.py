"""A single bad byte in a session's attributes or in a catalogue: one line naming the file, the attribute or the
table/row/column and the value, exit 2 — in a batch only that session fails (the new-user trial: tracebacks)."""

from __future__ import annotations

import contextlib
import json
import shutil
import sqlite3
import subprocess
import sys
import uuid
from pathlib import Path

import h5py
import numpy as np
import pytest

from tests.helpers import record_session_in_subprocess, run_cli

SIM_ROBOT = Path(__file__).resolve().parents[1] / "configs" / "benches" / "sim_robot.toml"


@pytest.fixture(scope="module")
def recorded(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A 3 s --fast recording by the real recorder (3 s: an import needs 2 s of data)."""
    return record_session_in_subprocess(tmp_path_factory.mktemp("rec"), 3.0)


def _copy(src: Path, dst: Path, **texts: bytes | str) -> Path:
    """A copy of ``src`` with its own session id; ``texts`` rewrite root attributes as UTF-8 strings stored byte for
    byte (h5py reads a byte that is not UTF-8 back as a surrogate escape, as from a flipped bit on disk)."""
    dst.parent.mkdir(parents=True, exist_ok=True)
    shutil.copyfile(src, dst)
    with h5py.File(dst, "r+") as f:
        f.attrs["session_id"] = str(uuid.uuid4())
        for name, value in texts.items():
            raw = value if isinstance(value, bytes) else value.encode()
            f.attrs.create(name, raw, dtype=h5py.string_dtype("utf-8"))
    return dst


def _one_bad_byte(text: str) -> tuple[bytes, str]:
    """``text`` with its second character replaced by the byte 0xc6 (not UTF-8 alone), and how the error shows it."""
    return text[0].encode() + b"\xc6" + text[2:].encode(), text[0] + "\\xc6" + text[2:]


@pytest.mark.parametrize("name", ["session_id", "joint", "status", "created_utc"])
@pytest.mark.parametrize("command", ["check", "analyze", "export"])
def test_a_text_attribute_that_is_not_utf8_is_one_line_naming_it(recorded: Path, tmp_path: Path, name: str,
                                                                 command: str, capsys: pytest.CaptureFixture[str]
                                                                 ) -> None:
    """Before: check said "verified", analyze raised UnicodeEncodeError in the catalogue, export wrote the
    surrogate into session.json."""
    with h5py.File(recorded) as f:
        value = str(f.attrs[name])
    raw, shown = _one_bad_byte(value)
    path = _copy(recorded, tmp_path / "s.h5", **{name: raw})
    extra = ["--csv", str(tmp_path / "csv")] if command == "export" else []
    run = run_cli(capsys, command, str(path), *extra)
    assert (run.code, run.err) == (2, f"acq: error: {path}: damaged: attribute {name} = '{shown}': not UTF-8 text\n")
    assert not (tmp_path / "csv").exists()


@pytest.mark.parametrize(("name", "value", "what"), [
    ("tags_json", "[1,2]", "not a JSON object but a list"),
    ("tags_json", "{\"a\": 1", "not JSON"),
    ("origin_json", "7", "not a JSON object but a int"),
    ("status", "bogus", "must be 'recording', 'complete', 'interrupted' or 'failed'"),
    ("created_utc", "2026912-01T02:10:31+00:00", "not an ISO 8601 time (e.g. 2026-11-20T10:15:03+00:00)"),
    ("stopped_utc", "yesterday", "not an ISO 8601 time (e.g. 2026-11-20T10:15:03+00:00)"),
    ("host_clock_shared", "maybe", "must be a valid boolean"),
])
@pytest.mark.parametrize("command", ["check", "analyze"])
def test_an_attribute_that_decodes_to_nonsense_is_one_line_naming_it(recorded: Path, tmp_path: Path, name: str,
                                                                     value: str, what: str, command: str,
                                                                     capsys: pytest.CaptureFixture[str]) -> None:
    """Before: tags_json [1,2] → AttributeError in analyze; status 'bogus' printed as "bogus, checksums and counts
    verified"; a created_utc that is no time shown as it is; host_clock_shared 'maybe' taken as true."""
    path = _copy(recorded, tmp_path / "s.h5", **{name: value})
    run = run_cli(capsys, command, str(path))
    assert (run.code, run.err) == (2, f"acq: error: {path}: malformed session: attribute {name} = '{value}': "
                                      f"{what}\n")


def test_a_group_text_attribute_that_is_not_utf8_is_one_line_naming_it(recorded: Path, tmp_path: Path,
                                                                       capsys: pytest.CaptureFixture[str]) -> None:
    path = _copy(recorded, tmp_path / "s.h5")
    with h5py.File(path, "r+") as f:
        value = str(f["encoder"].attrs["transport"])
        raw, shown = _one_bad_byte(value)
        f["encoder"].attrs.create("transport", raw, dtype=h5py.string_dtype("utf-8"))
    run = run_cli(capsys, "check", str(path))
    assert (run.code, run.err) == (2, f"acq: error: {path}: damaged: attribute encoder/transport = '{shown}': "
                                      "not UTF-8 text\n")


@pytest.fixture(scope="module")
def batch(recorded: Path, tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, subprocess.CompletedProcess[str]]:
    """``acq analyze FOLDER --jobs 2`` of two intact sessions and one whose joint holds a byte that is not UTF-8 (the
    middle one by name); the folder (with its catalogue) and the finished process."""
    folder = tmp_path_factory.mktemp("batch")
    _copy(recorded, folder / "a.h5")
    _copy(recorded, folder / "b.h5", joint=b"j\xc6int1")
    _copy(recorded, folder / "c.h5")
    proc = subprocess.run([sys.executable, "-m", "acq", "analyze", str(folder), "--jobs", "2", "--no-report",
                           "--json"], capture_output=True, text=True, timeout=300)
    return folder, proc


def test_a_batch_goes_on_past_a_session_with_a_damaged_attribute(batch: tuple[Path, subprocess.CompletedProcess[str]]
                                                                 ) -> None:
    """Before: UnicodeEncodeError filing the damaged session stopped the whole batch, every time."""
    folder, proc = batch
    assert proc.returncode == 1, proc.stderr
    assert "Traceback" not in proc.stderr
    outcomes = {Path(o["path"]).name: (o["outcome"], o.get("verdict"), o.get("error")) for o in json.loads(proc.stdout)}
    assert outcomes == {"a.h5": ("analysed", "ok", None), "c.h5": ("analysed", "ok", None),
                        "b.h5": ("failed", None, f"{folder / 'b.h5'}: damaged: attribute joint = 'j\\xc6int1': "
                                                 "not UTF-8 text")}
    with sqlite3.connect(folder / "catalogue.sqlite") as db:
        rows = db.execute("SELECT s.path, s.joint, a.verdict, a.error IS NULL FROM sessions s JOIN analyses a "
                          "USING (session_key) ORDER BY s.path").fetchall()
    assert [(Path(p).name, j, v, ok) for p, j, v, ok in rows] == [
        ("a.h5", "joint1", "ok", 1), ("b.h5", None, None, 0), ("c.h5", "joint1", "ok", 1)]


def test_an_import_of_metadata_holding_a_byte_that_is_not_utf8_is_one_line(recorded: Path, tmp_path: Path,
                                                                           capsys: pytest.CaptureFixture[str]) -> None:
    """An export of before this change wrote the damaged attribute as JSON's \\udcc6 escape; its import failed with
    the raw codec message."""
    path = _copy(recorded, tmp_path / "s.h5")
    assert run_cli(capsys, "export", str(path), "--csv", str(tmp_path / "csv")).code == 0
    (meta,) = (tmp_path / "csv").glob("*.session.json")
    doc = json.loads(meta.read_text())
    sid = doc["session_id"]
    doc["session_id"] = sid[0] + "\udcc6" + sid[2:]
    meta.write_text(json.dumps(doc))
    assert "\\udcc6" in meta.read_text()
    (cur,) = (tmp_path / "csv").glob("*.current.csv")
    (enc,) = (tmp_path / "csv").glob("*.encoder.csv")
    run = run_cli(capsys, "import", "--current", str(cur), "--encoder", str(enc), "-o", str(tmp_path / "i.h5"))
    assert (run.code, run.err) == (2, f"acq: error: {meta}: session_id = '{sid[0]}\\xc6{sid[2:]}': not UTF-8 text\n")
    assert not (tmp_path / "i.h5").exists()


# ------------------------------------------------------------------------------------------ a damaged catalogue


def _flip_in_text(catalogue: Path, sql: str, at: int = 5) -> str:
    """Overwrite byte ``at`` of the one text value ``sql`` selects, where the file holds it, with 0xff (never UTF-8);
    the text before."""
    with sqlite3.connect(catalogue) as db:
        (text,) = db.execute(sql).fetchone()
    data = bytearray(catalogue.read_bytes())
    assert data.count(text.encode()) == 1
    data[data.find(text.encode()) + at] = 0xFF
    catalogue.write_bytes(data)
    return text


def _catalogue_copy(batch: tuple[Path, subprocess.CompletedProcess[str]], tmp_path: Path) -> Path:
    folder, _ = batch
    assert not (folder / "catalogue.sqlite-wal").exists()  # everything in the one file
    return Path(shutil.copyfile(folder / "catalogue.sqlite", tmp_path / "c.sqlite"))


@pytest.mark.parametrize("command", [["trend", "--joint", "joint1"], ["fleet"]])
def test_a_catalogue_text_that_is_not_utf8_is_one_line_naming_table_row_and_column(
        batch: tuple[Path, subprocess.CompletedProcess[str]], tmp_path: Path, command: list[str],
        capsys: pytest.CaptureFixture[str]) -> None:
    """Before: sqlite3.OperationalError: Could not decode to UTF-8 column 'sha256' with text '…' (a traceback)."""
    catalogue = _catalogue_copy(batch, tmp_path)
    with sqlite3.connect(catalogue) as db:
        (row,) = db.execute("SELECT a.id FROM analyses a JOIN sessions s USING (session_key) "
                            "WHERE s.path LIKE '%c.h5'").fetchone()
    sha = _flip_in_text(catalogue, f"SELECT sha256 FROM analyses WHERE id = {row}")
    run = run_cli(capsys, command[0], "--catalogue", str(catalogue), *command[1:])
    assert (run.code, run.err) == (2, f"acq: error: {catalogue}: damaged catalogue: analyses row {row}, column sha256 "
                                      f"= '{sha[:5]}\\xff{sha[6:35]}…': not UTF-8 text\n")


def test_a_catalogue_json_that_does_not_read_is_one_line_naming_row_and_column(
        batch: tuple[Path, subprocess.CompletedProcess[str]], tmp_path: Path,
        capsys: pytest.CaptureFixture[str]) -> None:
    """A flipped byte that leaves UTF-8 but breaks the JSON (here ']' → '}'); before: JSONDecodeError."""
    catalogue = _catalogue_copy(batch, tmp_path)
    with sqlite3.connect(catalogue) as db:
        row, reasons = db.execute("SELECT id, reasons_json FROM analyses WHERE error IS NULL ORDER BY id").fetchone()
        db.execute("UPDATE analyses SET reasons_json = ? WHERE id = ?", (reasons[:-1] + "}", row))
    run = run_cli(capsys, "trend", "--catalogue", str(catalogue), "--joint", "joint1")
    assert (run.code, run.err) == (2, f"acq: error: {catalogue}: damaged catalogue: analyses row {row}, column "
                                      f"reasons_json = '…{reasons[-31:-1]}}}': not a JSON list\n")


def test_a_catalogue_page_damaged_is_not_a_usable_catalogue(batch: tuple[Path, subprocess.CompletedProcess[str]],
                                                            tmp_path: Path,
                                                            capsys: pytest.CaptureFixture[str]) -> None:
    """The analyses table's root page with a page type SQLite does not know: the file opens (page 1 is intact) and
    the read of the table fails; before: a traceback of sqlite3.DatabaseError."""
    catalogue = _catalogue_copy(batch, tmp_path)
    with sqlite3.connect(catalogue) as db:
        page_size = db.execute("PRAGMA page_size").fetchone()[0]
        (root,) = db.execute("SELECT rootpage FROM sqlite_master WHERE name = 'analyses'").fetchone()
    assert root > 1
    data = bytearray(catalogue.read_bytes())
    data[(root - 1) * page_size] = 0xFF  # the b-tree page's type byte (2, 5, 10 or 13)
    catalogue.write_bytes(data)
    for command in (["trend", "--joint", "joint1"], ["fleet"]):
        run = run_cli(capsys, command[0], "--catalogue", str(catalogue), *command[1:])
        # found at open by PRAGMA integrity_check (before: by the read of the table, "(database disk image is
        # malformed)" alone)
        assert (run.code, run.err) == (2, f"acq: error: {catalogue}: not a usable catalogue (database disk image is "
                                          f"malformed: Page {root}: btreeInitPage() returns error code 11)\n")


@pytest.mark.parametrize("command", [["trend", "--joint", "joint1"], ["fleet"]])
def test_a_catalogue_index_damaged_is_not_a_usable_catalogue(batch: tuple[Path, subprocess.CompletedProcess[str]],
                                                             tmp_path: Path, command: list[str],
                                                             capsys: pytest.CaptureFixture[str]) -> None:
    """A byte of one session's key flipped where the sessions' unique index holds it (the table's copy intact):
    every read succeeds and ``PRAGMA quick_check`` passes, but a query through the index misses the session. Before:
    exit 0, that session's window left out of the trend (the trial: a baseline window gone, every ΔK shifted)."""
    catalogue = _catalogue_copy(batch, tmp_path)
    with sqlite3.connect(catalogue) as db:
        page_size = db.execute("PRAGMA page_size").fetchone()[0]
        (root,) = db.execute("SELECT rootpage FROM sqlite_master WHERE name = 'sqlite_autoindex_sessions_1'"
                             ).fetchone()
        row, key = db.execute("SELECT rowid, session_key FROM sessions ORDER BY rowid LIMIT 1").fetchone()
    data = bytearray(catalogue.read_bytes())
    at = data.find(key.encode(), (root - 1) * page_size, root * page_size)
    assert at > 0
    data[at + len(key) - 1] ^= 0x01  # still ASCII: every read succeeds
    catalogue.write_bytes(data)
    with sqlite3.connect(f"file:{catalogue}?mode=ro", uri=True) as db:
        assert db.execute("PRAGMA quick_check").fetchone() == ("ok",)
    run = run_cli(capsys, command[0], "--catalogue", str(catalogue), *command[1:])
    assert (run.code, run.err) == (2, f"acq: error: {catalogue}: not a usable catalogue (database disk image is "
                                      f"malformed: row {row} missing from index sqlite_autoindex_sessions_1)\n")


def _monitored_twice(out: Path) -> list[str]:
    """A --fast monitor of 2 windows run into ``out``; the command that restarts it there."""
    cmd = [sys.executable, "-m", "acq", "monitor", "--bench", str(SIM_ROBOT), "--fast", "--window", "10", "--every",
           "60", "--for", "2m", "--baseline-windows", "2", "--out", str(out)]
    first = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
    assert first.returncode == 0, first.stderr
    return cmd


def test_a_monitor_restarting_on_a_damaged_catalogue_is_one_line(tmp_path: Path) -> None:
    """A --fast monitor of 2 windows, a byte of its catalogue's second analysis flipped, the monitor started again
    on its folder; before: a traceback of sqlite3.OperationalError."""
    out = tmp_path / "monitor"
    cmd = _monitored_twice(out)
    catalogue = out / "catalogue.sqlite"
    sha = _flip_in_text(catalogue, "SELECT sha256 FROM analyses ORDER BY id LIMIT 1 OFFSET 1")
    with sqlite3.connect(f"file:{catalogue}?mode=ro", uri=True) as db:
        db.text_factory = bytes
        (row,) = db.execute("SELECT id FROM analyses ORDER BY id LIMIT 1 OFFSET 1").fetchone()
    again = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
    assert (again.returncode, again.stderr) == (2, f"acq: error: {catalogue}: damaged catalogue: analyses row {row}, "
                                                   f"column sha256 = '{sha[:5]}\\xff{sha[6:35]}…': not UTF-8 text\n")


@pytest.mark.parametrize("damage", ["index key flipped", "index page zeroed"])
def test_a_monitor_restarting_on_a_damaged_index_refuses_it_before_capturing(tmp_path: Path, damage: str) -> None:
    """The catalogue is opened for writing on a restart, where only readers (trend, fleet) ran PRAGMA integrity_check.
    A byte of a session's key flipped in the sessions' unique index: the restart filed a third window into the
    damaged file, exit 0 (the index still missing row 1). The index's page overwritten with zeros: the restart
    captured a window, then failed "acq: error: database disk image is malformed: …catalogue.sqlite (database disk
    image is malformed)", exit 1. Now one line naming the finding, exit 2, nothing captured or written."""
    out = tmp_path / "monitor"
    cmd = _monitored_twice(out)
    catalogue = out / "catalogue.sqlite"
    with contextlib.closing(sqlite3.connect(catalogue)) as db:  # closed: no -wal or -shm left beside it
        page_size = db.execute("PRAGMA page_size").fetchone()[0]
        (root,) = db.execute("SELECT rootpage FROM sqlite_master WHERE name = 'sqlite_autoindex_sessions_1'"
                             ).fetchone()
        row, key = db.execute("SELECT rowid, session_key FROM sessions ORDER BY rowid LIMIT 1").fetchone()
    data = bytearray(catalogue.read_bytes())
    if damage == "index key flipped":
        at = data.find(key.encode(), (root - 1) * page_size, root * page_size)
        assert at > 0
        data[at + len(key) - 1] ^= 0x01  # still ASCII: every read succeeds
        finding = f"row {row} missing from index sqlite_autoindex_sessions_1"
    else:
        data[(root - 1) * page_size:root * page_size] = bytes(page_size)
        finding = f"Page {root}: btreeInitPage() returns error code 11"
    catalogue.write_bytes(data)
    before = sorted(p.name for p in out.iterdir())
    again = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
    assert (again.returncode, again.stderr) == (2, f"acq: error: {catalogue}: not a usable catalogue (database disk "
                                                   f"image is malformed: {finding})\n")
    assert sorted(p.name for p in out.iterdir()) == before
    assert catalogue.read_bytes() == data, "the catalogue was written"  # (a bool: no diff of the bytes)


def test_a_flipped_bit_in_the_footers_fixed_length_status_is_one_line_and_a_batch_goes_on(
        recorded: Path, tmp_path: Path) -> None:
    """The footer's texts are fixed-length (read as bytes; acq.recording.layout): a bit flipped in ``status``
    (b'complete' → b'\\xe3omplete', the attribute's own dtype kept) raised UnicodeDecodeError in the batch's status
    read — a traceback, the other sessions not analysed (reviewer, session 14); one file said "cannot be read"."""
    folder = tmp_path / "batch"
    good, bad = _copy(recorded, folder / "a.h5"), _copy(recorded, folder / "b.h5")
    with h5py.File(bad, "r+") as f:
        dtype = f.attrs.get_id("status").dtype
        assert dtype.kind == "S"  # as the writer stores it
        f.attrs.modify("status", np.array(b"\xe3omplete", dtype=dtype))
    proc = subprocess.run([sys.executable, "-m", "acq", "analyze", str(folder), "--jobs", "1", "--no-report",
                           "--json"], capture_output=True, text=True, timeout=300)
    assert "Traceback" not in proc.stderr and proc.returncode == 1, proc.stderr
    outcomes = {Path(o["path"]).name: (o["outcome"], o.get("verdict"), o.get("error")) for o in json.loads(proc.stdout)}
    assert outcomes == {good.name: ("analysed", "ok", None),
                        bad.name: ("failed", None, f"{bad}: damaged: attribute status = '\\xe3omplete': not UTF-8 text")}
