"""Durable in order against a power cut: what acq reports as committed or written is synced to the disk first.

The disk is hardware: ``os.fdatasync`` / ``os.fsync`` are wrapped to log each call with the state of the file or
folder it makes durable at that moment (a copy of the session file, the folder's files by content), or to fail as a
disk does (EIO). Everything else — the recorder, HDF5, the CLI — runs as it does for a user.
"""

from __future__ import annotations

import errno
import hashlib
import os
import shutil
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

from acq.config import load_bench, load_profile
from acq.recording.h5safe import open_read
from acq.recording.reader import load
from acq.recording.recorder import Recorder
from acq.recording.storage import write_text_atomically
from drivers.registry import open_bench
from tests.helpers import record_session_in_subprocess, run_cli, seeded_profile

RATE_HZ = 25600
#: The committed state of a session file: rows of /flushes, then the rows each counted dataset holds.
COUNTED = ("current/i_a_A", "current/blocks/count", "encoder/index", "events")


def _path_of(fd: int) -> Path:
    return Path(os.readlink(f"/proc/self/fd/{fd}"))


def _state(snapshot: Path) -> tuple[int, ...]:
    """(``/flushes`` rows, rows of each :data:`COUNTED` dataset) of a copy of a session file."""
    with open_read(snapshot) as f:
        return (f["flushes"].shape[0], *(f[name].shape[0] for name in COUNTED))


def _row_totals(row: np.void) -> tuple[int, ...]:
    return tuple(int(row[k]) for k in ("current_samples", "current_blocks", "encoder_samples", "events"))


def test_every_commit_is_synced_after_its_samples_and_before_the_next(tmp_path: Path,
                                                                     monkeypatch: pytest.MonkeyPatch) -> None:
    """A --fast recording whose each sync copies the session file as it is then (what that sync makes durable):
    the samples a /flushes row counts are synced before the row is written, the row before anything of the next
    commit is; the folder is synced once the file exists, the footer last."""
    snaps = tmp_path / "snapshots"
    snaps.mkdir()
    syncs: list[tuple[str, Path, Path | None]] = []  # (call, what it synced, copy of a session file then)
    real_fdatasync, real_fsync = os.fdatasync, os.fsync

    def logged(call: str, real: Callable[[int], None]) -> Callable[[int], None]:
        def sync(fd: int) -> None:
            real(fd)
            path, copy = _path_of(fd), None
            if path.suffix == ".h5":
                copy = snaps / f"{len(syncs)}.h5"
                shutil.copyfile(path, copy)
            syncs.append((call, path, copy))
        return sync

    monkeypatch.setattr(os, "fdatasync", logged("fdatasync", real_fdatasync))
    monkeypatch.setattr(os, "fsync", logged("fsync", real_fsync))
    bench = load_bench()
    current, drive = open_bench(bench, fast=True)
    out = tmp_path / "out"
    result = Recorder(bench, load_profile("triangle_0.2s"), current, drive, out, 20.0).run()
    monkeypatch.undo()
    assert result.status == "complete", result.stop_reason
    with open_read(result.path) as f:
        rows = [_row_totals(r) for r in f["flushes"][...]]
    assert len(rows) >= 3  # 20 s of 25.6 kS/s and a 1 kHz encoder: a commit per 2 MiB (recorder.FLUSH_BYTES), one at the end
    assert rows[-1][0] == result.current_samples >= 20 * RATE_HZ
    # the folder made (its parent synced), the file's layout, its name (the folder synced), then per commit r the
    # samples it counts without its row (r - 1 rows), then with its row; last the footer (fsync of the whole file)
    assert [(call, path) for call, path, _ in syncs] == (
        [("fsync", tmp_path), ("fdatasync", result.path), ("fsync", out)]
        + [("fdatasync", result.path)] * (2 * len(rows)) + [("fsync", result.path)])
    committed = [_state(copy) for _, _, copy in syncs if copy is not None]
    expected = [(0, 0, 0, 0, 0)]
    for r, totals in enumerate(rows, start=1):
        expected += [(r - 1, *totals), (r, *totals)]
    assert committed[:-1] == expected
    final = load(syncs[-1][2])  # type: ignore[arg-type]
    assert final.status == "complete" and final.current.sample_count == result.current_samples


@pytest.mark.parametrize("failing", [4, 5], ids=["samples-sync", "row-sync"])
def test_a_failed_sync_fails_the_recording_keeping_the_last_durable_commit(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch, failing: int) -> None:
    """EIO from the 4th fdatasync (the 2nd commit's samples: 1st the layout, 2nd and 3rd the 1st commit) or the 5th
    (its row): ``acq record`` fails in one line, exit 1, counting only the 1st commit — the file holds that, and the
    2nd commit's row if it was written before its sync failed — and ``acq check`` repairs the file durably."""
    calls = {"n": 0}
    real_fdatasync = os.fdatasync

    def failing_disk(fd: int) -> None:
        calls["n"] += 1
        if calls["n"] == failing:
            raise OSError(errno.EIO, os.strerror(errno.EIO))
        real_fdatasync(fd)

    monkeypatch.setattr(os, "fdatasync", failing_disk)
    out = tmp_path / "out"
    run = run_cli(capsys, "record", "--profile", str(seeded_profile(tmp_path)), "--fast", "--duration", "10",
                  "--no-analyze", "--out", str(out))
    monkeypatch.undo()
    (path,) = out.glob("*.h5")
    with open_read(path) as f:
        first = _row_totals(f["flushes"][0])
        rows = f["flushes"].shape[0]
        last = _row_totals(f["flushes"][-1])
    kept, encoder = first[0], first[2]
    lines = run.err.strip().splitlines()
    assert run.code == 1 and [ln for ln in lines if ln.startswith("acq:")] == lines[-1:] == [
        f"acq: failed: I/O error: {path} — {kept / RATE_HZ:.1f} s kept ({kept} current and {encoder} encoder samples "
        f"stored in {path})"], run.err
    assert calls["n"] == failing  # nothing written or synced after the failure
    s = load(path)
    assert s.status == "recording"  # abandoned at the failure: no footer, the /flushes rows say what is stored
    assert rows == failing - 3  # the row whose sync failed is in the page cache here (a real EIO may have lost it)
    assert (s.current.sample_count, s.encoder.index.size) == (last[0], last[2])
    np.testing.assert_array_equal(s.current.sample_index(), np.arange(s.current.sample_count))

    synced = _log_fsyncs(monkeypatch)
    assert run_cli(capsys, "check", str(path)).code == 0
    monkeypatch.undo()
    assert load(path).status == "interrupted"
    _assert_replaced_durably(synced, [path])


def test_a_failed_sync_of_the_footer_is_a_failed_write(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                                        monkeypatch: pytest.MonkeyPatch) -> None:
    """EIO from the fsync after the footer: every commit was synced, the footer is not known to be on the disk."""
    real_fsync = os.fsync

    def failing_disk(fd: int) -> None:
        if _path_of(fd).suffix == ".h5":
            raise OSError(errno.EIO, os.strerror(errno.EIO))
        real_fsync(fd)

    monkeypatch.setattr(os, "fsync", failing_disk)
    out = tmp_path / "out"
    run = run_cli(capsys, "record", "--profile", "triangle_0.2s", "--fast", "--duration", "2", "--no-analyze", "--out",
                  str(out))
    monkeypatch.undo()
    (path,) = out.glob("*.h5")
    lines = run.err.strip().splitlines()
    assert run.code == 1 and [ln for ln in lines if ln.startswith("acq:")] == lines[-1:] == [
        f"acq: error: I/O error: {path} (footer not written; the samples are stored, acq check repairs the file)"]


@pytest.mark.parametrize("answer", [errno.EINVAL, errno.EIO])
def test_a_folder_the_file_system_cannot_sync_records_and_a_folder_that_fails_to_sync_fails(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch, answer: int) -> None:
    """A directory fsync refused with EINVAL (SMB/CIFS, some FUSE) leaves the names as that file system keeps them: the
    recording completes; EIO from the same sync is a failed write like any other."""
    real_fsync = os.fsync

    def folder_sync(fd: int) -> None:
        if _path_of(fd).is_dir():
            raise OSError(answer, os.strerror(answer))
        real_fsync(fd)

    monkeypatch.setattr(os, "fsync", folder_sync)
    out = tmp_path / "out"
    run = run_cli(capsys, "record", "--profile", "triangle_0.2s", "--fast", "--duration", "2", "--no-analyze", "--out",
                  str(out))
    monkeypatch.undo()
    if answer == errno.EINVAL:
        (path,) = out.glob("*.h5")
        assert run.code == 0 and load(path).status == "complete", run.err
    else:
        assert run.code == 1 and run.err.strip().splitlines()[-1].startswith("acq: error: I/O error: "), run.err


# ------------------------------------------------------------------------------------------ atomic outputs


@dataclass(frozen=True)
class Synced:
    """One fsync: what it synced (a file or a folder) and the files of the folder holding it then, by content."""

    path: Path
    is_folder: bool
    folder: dict[str, str]


def _digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _log_fsyncs(monkeypatch: pytest.MonkeyPatch) -> list[Synced]:
    log: list[Synced] = []
    real_fsync = os.fsync

    def sync(fd: int) -> None:
        real_fsync(fd)
        path = _path_of(fd)
        folder = path if path.is_dir() else path.parent
        log.append(Synced(path, path.is_dir(), {p.name: _digest(p) for p in folder.iterdir() if p.is_file()}))

    monkeypatch.setattr(os, "fsync", sync)
    return log


def _assert_replaced_durably(log: list[Synced], outputs: list[Path]) -> None:
    """Each output's content was synced in a temp file beside it before it had that content under its name, and its
    folder was synced after it had."""
    for out in outputs:
        final = _digest(out)
        temp = [i for i, s in enumerate(log) if not s.is_folder and s.path.parent == out.parent
                and s.path.name != out.name and s.folder[s.path.name] == final and s.folder.get(out.name) != final]
        assert temp, f"{out}: its data was not synced before the rename"
        folder = [i for i, s in enumerate(log) if s.is_folder and s.path == out.parent
                  and s.folder.get(out.name) == final]
        assert folder and folder[0] > temp[0], f"{out}: its folder was not synced after the rename"


def test_a_text_output_is_synced_before_its_rename_and_its_folder_after(tmp_path: Path,
                                                                       monkeypatch: pytest.MonkeyPatch) -> None:
    """The result JSON, the monitor's identity (write_text_atomically), written twice: the second replaces the first."""
    target = tmp_path / "x.result.json"
    log = _log_fsyncs(monkeypatch)
    write_text_atomically(target, "{}\n")
    write_text_atomically(target, '{"k": 1}\n')
    monkeypatch.undo()
    _assert_replaced_durably(log, [target])
    assert [(s.is_folder, s.path == tmp_path) for s in log] == [(False, False), (True, True)] * 2
    assert target.read_text() == '{"k": 1}\n' and [p.name for p in tmp_path.iterdir()] == [target.name]


def test_export_and_import_sync_each_file_before_its_rename_and_its_folder_after(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch) -> None:
    session = record_session_in_subprocess(tmp_path / "s", 3.0)
    pair = tmp_path / "new" / "pair"  # folders made: each one's parent synced
    log = _log_fsyncs(monkeypatch)
    assert run_cli(capsys, "export", str(session), "--csv", str(pair)).code == 0
    monkeypatch.undo()
    exported = [pair / f"{session.stem}.{kind}" for kind in ("current.csv", "encoder.csv", "session.json")]
    _assert_replaced_durably(log, exported)
    assert [s.path for s in log if s.is_folder][:2] == [tmp_path, tmp_path / "new"]

    imported = tmp_path / "imported" / "i.h5"
    log = _log_fsyncs(monkeypatch)
    run = run_cli(capsys, "import", "--current", str(exported[0]), "--encoder", str(exported[1]), "--profile",
                  "triangle_0.2s", "-o", str(imported))
    monkeypatch.undo()
    assert run.code == 0, run.err
    _assert_replaced_durably(log, [imported])
    assert load(imported).current.sample_count == load(session).current.sample_count


def test_a_folder_that_fails_to_sync_after_the_rename_says_the_file_is_written_but_its_name_may_not_survive(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch) -> None:
    """The output is complete under its name when its folder's sync fails: the error says so and exits 1 (what acq
    reports as written survives a power cut, this name may not). Before: 'acq: error: I/O error: <file>', as if the
    file had not been written."""
    session = record_session_in_subprocess(tmp_path / "s", 3.0)
    expected = tmp_path / "expected"
    assert run_cli(capsys, "export", str(session), "--csv", str(expected)).code == 0
    pair = tmp_path / "pair"
    pair.mkdir()
    real_fsync = os.fsync

    def folder_sync(fd: int) -> None:
        if _path_of(fd) == pair:
            raise OSError(errno.EIO, os.strerror(errno.EIO))
        real_fsync(fd)

    monkeypatch.setattr(os, "fsync", folder_sync)
    run = run_cli(capsys, "export", str(session), "--csv", str(pair))
    monkeypatch.undo()
    first = pair / f"{session.stem}.current.csv"
    assert run.code == 1 and run.err == (f"acq: error: {first}: written, but its name may not survive a power cut "
                                         "(I/O error when syncing its folder)\n")
    assert [p.name for p in pair.iterdir()] == [first.name]  # no temp file; the export stopped at its first file
    assert first.read_bytes() == (expected / first.name).read_bytes()
