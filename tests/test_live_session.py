"""A session a running recorder still writes is never rewritten: acq check (and --repair) only read it, acq analyze
says to wait; once its recorder is killed the same file is repaired. Real recorder in a child process, real HDF5."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from acq.recording.live import SessionBeingRecorded
from acq.recording.reader import load
from acq.recording.repair import recover, repair
from acqcore.errors import ConfigError
from tests.helpers import run_cli, seeded_profile

#: The recording's length: long enough that the checks below run while it goes on (real time, not --fast).
DURATION_S = 6.0


def start_recording(folder: Path) -> tuple[subprocess.Popen[str], Path]:
    """``acq record`` in real time on the simulated bench in a child process; return it and its session file once
    the file has committed at least 1 s of current."""
    out = folder / "live"
    proc = subprocess.Popen([sys.executable, "-m", "acq", "record", "--profile", str(seeded_profile(folder)),
                             "--duration", f"{DURATION_S:g}", "--no-analyze", "--out", str(out)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 30
    while time.monotonic() < deadline:
        files = list(out.glob("*.h5"))
        if files:
            try:
                session = load(files[0])
            except ConfigError as e:  # the recorder still making the file holds HDF5's lock (CI: once in 1230 tests)
                assert "locked by a process writing it (a recording just starting?)" in str(e), e
                time.sleep(0.05)
                continue
            if session.current.sample_count >= session.current.rate_hz:
                return proc, files[0]
        time.sleep(0.2)
    proc.kill()
    raise AssertionError(f"no second committed within 30 s: {proc.communicate()}")


def test_check_and_analyze_leave_a_live_session_alone(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    proc, path = start_recording(tmp_path)
    try:
        inode = path.stat().st_ino
        for args in (("check", str(path)), ("check", str(path), "--repair")):
            run = run_cli(capsys, *args)
            assert run.code == 0, run.err
            line = run.out.strip().splitlines()[-1]
            assert line.startswith(f"{path}: being recorded by a running recorder: ")
            assert line.endswith(" s committed so far; not modified")
            assert 1.0 <= float(line.split(": ")[2].split(" s ")[0]) < DURATION_S
        run = run_cli(capsys, "analyze", str(path), "--no-report")
        assert (run.code, run.err) == (2, f"acq: error: {path}: still being recorded by a running recorder — wait "
                                          "until it finishes, or use --partial to analyse what is stored\n")
        with pytest.raises(SessionBeingRecorded, match="being recorded by a running recorder — not modified"):
            repair(path, "test")
        with pytest.raises(SessionBeingRecorded):
            recover(path)
        assert path.stat().st_ino == inode and load(path).status == "recording"
        assert not path.with_name(f"{path.stem}.recovered.h5").exists()
    finally:
        _, err = proc.communicate(timeout=60)
    assert proc.returncode == 0, err
    assert "vanished" not in err
    session = load(path)
    assert session.status == "complete" and session.meta.stop_reason == f"recorded {DURATION_S:g} s"
    assert session.current.sample_count == round(DURATION_S * session.current.rate_hz)
    run = run_cli(capsys, "check", str(path))
    assert run.code == 0 and "complete, checksums and counts verified" in run.out


def test_a_killed_recorders_session_is_repaired(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    proc, path = start_recording(tmp_path)
    os.kill(proc.pid, signal.SIGKILL)
    proc.communicate(timeout=30)
    assert load(path).status == "recording"
    run = run_cli(capsys, "check", str(path))
    assert run.code == 0, run.err
    assert "interrupted — the recorder stopped without finishing the file; repaired: status = interrupted" in " ".join(
        run.out.split())  # rich wraps the line
    session = load(path)
    assert session.status == "interrupted" and session.current.sample_count >= session.current.rate_hz


def test_a_file_locked_by_its_writer_is_said_so(tmp_path: Path) -> None:
    """A recorder holds HDF5's lock on the file it makes until its SWMR writing starts; a reader then got HDF5's
    "unable to lock file, errno = 11 … Resource temporarily unavailable" (CI: the live-session test's poll met it)."""
    path = tmp_path / "held.h5"
    writer = subprocess.Popen([sys.executable, "-c", "import h5py, sys, time; f = h5py.File(sys.argv[1], 'w'); "
                               "print('open', flush=True); time.sleep(30)", str(path)],
                              stdout=subprocess.PIPE, text=True)
    try:
        assert writer.stdout is not None and writer.stdout.readline() == "open\n"
        with pytest.raises(ConfigError) as err:
            load(path)
        assert str(err.value) == (f"{path}: not a readable HDF5 session file (locked by a process writing it (a "
                                  "recording just starting?) — try again in a moment)")
    finally:
        writer.kill()
        writer.wait()


def test_a_file_system_whose_locks_fail_is_said_so_with_the_way_round(tmp_path: Path,
                                                                      monkeypatch: pytest.MonkeyPatch) -> None:
    """An NFS mount without its lock daemon refuses flock() with ENOLCK (a mount with no locks at all answers ENOSYS,
    which open_read's best-effort locking skips): HDF5's words stand, with the setting that reads without locks. The
    file system stands in here as HDF5's own error, raised where HDF5 opens the file."""
    import h5py

    path = tmp_path / "on_share.h5"
    with h5py.File(path, "w"):
        pass

    def refuse(*_args: object, **_kwargs: object) -> None:
        raise OSError("[Errno 37] Unable to synchronously open file (unable to lock file, errno = 37, error message = "
                      "'No locks available')")

    monkeypatch.setattr(h5py.h5f, "open", refuse)
    with pytest.raises(ConfigError) as err:
        load(path)
    assert str(err.value) == (
        f"{path}: not a readable HDF5 session file ([Errno 37] Unable to synchronously open file (unable to lock file, "
        "errno = 37, error message = 'No locks available') — where the file system has no working locks, "
        "HDF5_USE_FILE_LOCKING=FALSE reads without)")
