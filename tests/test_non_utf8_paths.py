"""A folder whose name is not UTF-8 (a Latin-1 ``Prüfstand`` from a Windows USB stick): paths are bytes on POSIX,
and every command works there as anywhere — the new-user trial had tracebacks from analyze (the catalogue, the
process's mapped files), monitor, record and view. The real CLI in a child process, its arguments as bytes."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from acq.monitoring.catalogue import Catalogue

LATIN1 = b"Pr\xfcfstand"  # "Prüfstand" in Latin-1: not UTF-8


def _acq(cwd: Path, *args: bytes | str) -> subprocess.CompletedProcess[bytes]:
    """``acq ARGS`` in a child process in ``cwd`` (offscreen Qt), bytes in and out; its standard streams strict UTF-8,
    as Python makes them under a desktop's ``LANG=en_US.UTF-8`` (this machine's C.UTF-8 lets them pass the bytes)."""
    env = {**os.environ, "QT_QPA_PLATFORM": "offscreen", "COLUMNS": "80", "PYTHONIOENCODING": "utf-8:strict"}
    return subprocess.run([sys.executable.encode(), b"-m", b"acq", *(os.fsencode(a) for a in args)], cwd=cwd,
                          capture_output=True, env=env, timeout=300)


@pytest.fixture(scope="module")
def recorded(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """``acq record --out 'o\\xff dir'``: recorded and analysed (it said "acq: analysis failed: UnicodeEncodeError")."""
    cwd = tmp_path_factory.mktemp("latin1")
    run = _acq(cwd, "record", "--profile", "triangle_0.2s", "--fast", "--out", b"o\xff dir")
    assert run.returncode == 0, run.stderr.decode(errors="replace")
    assert b"analysis failed" not in run.stderr and b"Traceback" not in run.stderr
    (session,) = (cwd / os.fsdecode(b"o\xff dir")).glob("*.h5")
    assert b"\nresult: o\xff dir/" + os.fsencode(session.stem) + b".result.json\n" in run.stdout
    folder = cwd / os.fsdecode(LATIN1)
    folder.mkdir()
    (folder / "s.h5").write_bytes(session.read_bytes())
    return cwd


def test_analyze_of_a_session_in_a_latin1_folder_files_its_path_in_the_catalogue_as_it_is(recorded: Path) -> None:
    """It was a UnicodeEncodeError at the catalogue's write (surrogates not allowed), exit 1, no result."""
    run = _acq(recorded, "analyze", LATIN1 + b"/s.h5")
    assert (run.returncode, run.stderr) == (0, b"")
    assert run.stdout.endswith(b"result: " + LATIN1 + b"/s.result.json\nreport: " + LATIN1 + b"/s.report.png\n")
    folder = recorded / os.fsdecode(LATIN1)
    assert (folder / "s.result.json").is_file()
    with Catalogue(folder / "catalogue.sqlite", read_only=True) as catalogue:
        (entry,) = catalogue.entries()
    assert os.fsencode(entry.path) == os.fsencode(folder.resolve() / "s.h5")  # the very bytes, read back
    missing = _acq(recorded, "analyze", LATIN1 + b"/missing.h5")  # a message naming the path prints its bytes
    assert (missing.returncode, missing.stdout, missing.stderr) == (
        2, b"", b"acq: error: " + LATIN1 + b"/missing.h5: no such session file\n")
    again = _acq(recorded, "analyze", LATIN1)  # a batch of the folder: was a UnicodeDecodeError in /proc/self/maps
    assert (again.returncode, again.stderr) == (0, b"")
    assert again.stdout == (b"nothing to analyse: 1 session already analysed (same file, same options) in "
                            + LATIN1 + b"/catalogue.sqlite\n")


def test_view_screenshot_into_a_latin1_folder_is_written(recorded: Path) -> None:
    """It said "acq: error: I/O error: Pr\\udcfcfstand/v.png" (Qt's QString file name cannot carry the bytes)."""
    run = _acq(recorded, "view", LATIN1 + b"/s.h5", "--screenshot", LATIN1 + b"/v.png", "--size", "1000x700")
    assert (run.returncode, run.stderr) == (0, b"")
    assert run.stdout == b"screenshot: " + LATIN1 + "/v.png (1000×700 px)\n".encode()
    assert (recorded / os.fsdecode(LATIN1) / "v.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_monitor_into_a_latin1_folder_runs_and_files_its_windows(recorded: Path) -> None:
    """It was a traceback at the catalogue's read of the monitor's windows (its identity names its folder)."""
    run = _acq(recorded, "monitor", "--bench", "sim_robot", "--window", "4", "--every", "5", "--for", "10s",
               "--fast", "--out", LATIN1 + b"/m")
    assert run.returncode == 0, run.stderr.decode(errors="replace")
    assert b"Traceback" not in run.stderr
    with Catalogue(recorded / os.fsdecode(LATIN1) / "m" / "catalogue.sqlite", read_only=True) as catalogue:
        paths = sorted(os.fsencode(e.path) for e in catalogue.entries("joint1"))
    windows = sorted(os.fsencode(p.resolve()) for p in (recorded / os.fsdecode(LATIN1) / "m").glob("*.h5"))
    assert len(paths) == 2 and paths == windows
