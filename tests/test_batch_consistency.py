"""Batch and catalogue stay consistent: Ctrl-C stops a batch with every result written catalogued; a session still
being recorded is skipped by a batch and refused by acq analyze unless --partial; a request that spells out the
defaults is looked up, filed (success and failure) and cleaned up as the default request."""

from __future__ import annotations

import json
import os
import shutil
import signal
import sqlite3
import subprocess
import sys
import time
import uuid
from collections.abc import Callable
from pathlib import Path

import h5py
import pytest

from analysis import AnalysisRequest
from tests.helpers import run_cli, seeded_profile


@pytest.fixture(scope="module")
def recorded(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("rec")
    proc = subprocess.run([sys.executable, "-m", "acq", "record", "--profile", str(seeded_profile(out.parent)),
                           "--fast", "--duration", "10", "--no-analyze", "--out", str(out)],
                          capture_output=True, text=True, timeout=180)
    assert proc.returncode == 0, proc.stderr
    (path,) = out.glob("*.h5")
    return path


def copy_session(src: Path, dst: Path, *, status: str | None = None) -> Path:
    """A copy with its own session id (and so its own hash); ``status`` rewrites the status attribute."""
    shutil.copyfile(src, dst)
    with h5py.File(dst, "r+") as f:
        f.attrs["session_id"] = str(uuid.uuid4())
        if status is not None:
            f.attrs["status"] = status  # as a killed recorder leaves it: the /flushes rows say what is stored
    return dst


def catalogue_rows(path: Path) -> list[sqlite3.Row]:
    with sqlite3.connect(path) as db:
        db.row_factory = sqlite3.Row
        return db.execute("SELECT s.path, a.verdict, a.error, a.partial, a.request_key FROM sessions s "
                          "JOIN analyses a ON a.session_key = s.session_key ORDER BY s.path").fetchall()


def test_recording_session_is_refused_unless_partial(recorded: Path, tmp_path: Path,
                                                     capsys: pytest.CaptureFixture[str]) -> None:
    path = copy_session(recorded, tmp_path / "live.h5", status="recording")
    run = run_cli(capsys, "analyze", str(path), "--no-report")
    assert (run.code, run.err) == (2, f"acq: error: {path}: status recording, but no recorder holds it (killed, or "
                                      f"stopped without finishing the file) — run acq check {path} to repair it, or "
                                      "use --partial to analyse what is stored\n")
    assert not path.with_name("live.result.json").exists()
    run = run_cli(capsys, "analyze", str(path), "--no-report", "--partial", "--json")
    assert run.code == 0, run.err
    doc = json.loads(run.out)
    assert doc["partial"] is True and doc["session"]["status"] == "recording"
    assert json.loads(path.with_name("live.result.json").read_text())["partial"] is True
    rows = catalogue_rows(tmp_path / "catalogue.sqlite")
    assert [(Path(r["path"]).name, r["partial"]) for r in rows] == [("live.h5", 1)]


def test_batch_skips_a_session_still_recording(recorded: Path, tmp_path: Path,
                                               capsys: pytest.CaptureFixture[str]) -> None:
    copy_session(recorded, tmp_path / "a_done.h5")
    copy_session(recorded, tmp_path / "b_live.h5", status="recording")
    run = run_cli(capsys, "analyze", str(tmp_path), "--no-report", "--jobs", "1", "--json")
    assert run.code == 0, run.err
    outcomes = {Path(d["path"]).name: d["outcome"] for d in json.loads(run.out)}
    assert outcomes == {"a_done.h5": "analysed", "b_live.h5": "skipped: status recording"}
    rows = catalogue_rows(tmp_path / "catalogue.sqlite")
    assert [(Path(r["path"]).name, r["partial"]) for r in rows] == [("a_done.h5", 0)]
    assert not (tmp_path / "b_live.result.json").exists()


def test_ctrl_c_stops_a_batch_and_every_result_written_is_catalogued(recorded: Path, tmp_path: Path) -> None:
    folder = tmp_path / "many"
    folder.mkdir()
    n = 24  # a warm worker analyses a 10 s session in 0.14 s: 8 left a margin of a fraction of a second
    for i in range(n):
        copy_session(recorded, folder / f"s{i}.h5")
    proc = subprocess.Popen([sys.executable, "-m", "acq", "analyze", str(folder), "--jobs", "2", "--no-report"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 120
    while not list(folder.glob("*.result.json")) and time.monotonic() < deadline:  # at least one result done
        time.sleep(0.05)
    assert proc.poll() is None, proc.communicate()
    sent = time.monotonic()
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=30)
    stopped_s = time.monotonic() - sent
    assert proc.returncode == 130, err
    assert stopped_s < 10.0  # a bound (it took 11 s for 80); bench/faults.py measures the real figure
    rows = catalogue_rows(folder / "catalogue.sqlite")
    results = sorted(p.name.replace(".result.json", ".h5") for p in folder.glob("*.result.json"))
    assert err.splitlines() == [f"acq: interrupted: {len(results)} of {n} sessions analysed ({len(results)} by this "
                                f"run), in {folder / 'catalogue.sqlite'}; run the same command again to analyse the "
                                f"other {n - len(results)}"]
    assert sorted(Path(r["path"]).name for r in rows if r["error"] is None) == results
    assert 1 <= len(results) < n  # the result seen was catalogued; stopped part-way: queued work was cancelled
    assert [p.name for p in folder.iterdir() if p.name.startswith(".")] == []  # no temp file left
    os.sync()


def test_a_ctrl_c_after_the_last_analysis_says_all_were_analysed_not_that_0_are_left() -> None:
    from acq.monitoring.batch import BatchReport
    from acq.monitoring.catalogue import Outcome
    from acq.ui.batch_cli import interrupted_line

    paths = [Path(f"s{i}.h5") for i in range(9)]
    ok = [Outcome(str(p), "h", "r", {}, {"K_Nm_per_rad": 890.0}, None, 1.0) for p in paths]
    failed = Outcome(str(paths[-1]), "h", "r", {}, None, "ValueError: bad", 1.0)
    assert interrupted_line(paths, BatchReport(ok, [], 3.0, interrupted=True), "c.sqlite") == (
        "acq: interrupted after the last analysis: all 9 sessions analysed (9 by this run), in c.sqlite")
    assert interrupted_line(paths, BatchReport(ok[:8] + [failed], [], 3.0, interrupted=True), "c.sqlite") == (
        "acq: interrupted: 8 of 9 sessions analysed (8 by this run, 1 failed), in c.sqlite; run the same command "
        "again to analyse the other 1")


def test_a_batch_works_where_the_user_stands_in_folders_named_like_our_packages(recorded: Path, tmp_path: Path) -> None:
    """Workers import acq, not the ./acq, ./analysis or ./drivers of the folder the user runs acq in: the forkserver
    runs ``python -c``, which puts that folder first on sys.path (every worker died: BrokenProcessPool)."""
    stand = tmp_path / "bench"
    for name in ("acq", "analysis", "drivers"):
        (stand / name).mkdir(parents=True)
    folder = stand / "sessions"
    folder.mkdir()
    for i in range(2):
        copy_session(recorded, folder / f"s{i}.h5")
    # as the console script starts: the folder the user stands in is not on the parent's sys.path
    console_script = "import sys; sys.path.pop(0); from acq.entry import main; main()"
    proc = subprocess.run([sys.executable, "-c", console_script, "analyze", str(folder), "--jobs", "2", "--no-report"],
                          cwd=stand, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert [(r["verdict"], r["error"]) for r in catalogue_rows(folder / "catalogue.sqlite")] == [("ok", None)] * 2


def _ok_names(catalogue: Path) -> set[str]:
    return {Path(r["path"]).name for r in catalogue_rows(catalogue) if r["error"] is None}


def _wait_for(condition: Callable[[], bool], proc: subprocess.Popen[str], timeout_s: float = 120.0) -> None:
    deadline = time.monotonic() + timeout_s
    while not condition() and proc.poll() is None and time.monotonic() < deadline:
        time.sleep(0.02)


@pytest.mark.parametrize("moment", ["catalogue opened", "forkserver started", "first result written"])
def test_ctrl_c_at_the_terminal_stops_a_batch_in_one_line(recorded: Path, tmp_path: Path, moment: str) -> None:
    """Ctrl-C at a terminal reaches the whole process group: the forkserver importing scipy, workers importing Qt
    to draw a report. Only acq's own process answers: exit 130, one line saying how far it got, nothing left
    running (before: tracebacks of the forkserver's preload, Qt's fatal error, InvalidStateError in the pool's
    thread, leaked semaphores — 16…136 lines in 3 of 4 runs)."""
    folder = tmp_path / "many"
    folder.mkdir()
    n = 12  # a warm worker analyses a 10 s session in 0.14 s: 4 left a margin of a fraction of a second
    for i in range(n):
        copy_session(recorded, folder / f"s{i}.h5")
    catalogue = folder / "catalogue.sqlite"
    proc = subprocess.Popen([sys.executable, "-m", "acq", "analyze", str(folder), "--jobs", "2"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True)

    def forkserver_running() -> bool:
        children = Path(f"/proc/{proc.pid}/task/{proc.pid}/children").read_text().split()
        return any(b"forkserver" in Path(f"/proc/{c}/cmdline").read_bytes() for c in children
                   if Path(f"/proc/{c}/cmdline").exists())

    condition = {"catalogue opened": catalogue.exists, "forkserver started": forkserver_running,
                 "first result written": lambda: bool(list(folder.glob("*.result.json")))}[moment]
    _wait_for(condition, proc)
    assert proc.poll() is None, proc.communicate()
    os.killpg(proc.pid, signal.SIGINT)  # what the terminal does on Ctrl-C
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, err
    assert "Traceback" not in err and "Fatal" not in err and "Exception" not in err and "leaked" not in err, err
    (line,) = err.splitlines()
    try:
        ok = sum(r["error"] is None for r in catalogue_rows(catalogue))
    except sqlite3.OperationalError:  # stopped while the catalogue's tables were made: the re-run makes them
        ok = 0
    assert line in ("acq: interrupted",  # during the parent's own imports (a loaded machine)
                    f"acq: interrupted before any analysis started ({n} sessions found); run the same command again "
                    "to analyse them",
                    f"acq: interrupted: {ok} of {n} sessions analysed ({ok} by this run), in {catalogue}; run the same "
                    f"command again to analyse the other {n - ok}",
                    f"acq: interrupted after the last analysis: all {n} sessions analysed ({n} by this run), in "
                    f"{catalogue}")
    results = {p.name.replace(".result.json", ".h5") for p in folder.glob("*.result.json")}
    assert results == (_ok_names(catalogue) if ok else set())  # a result whose worker was stopped is removed
    if moment == "first result written":  # its worker draws the report (Qt) meanwhile
        assert line.startswith("acq: interrupted: ")
    deadline = time.monotonic() + 10.0  # the forkserver and the resource tracker end when acq's pipes close
    while time.monotonic() < deadline:
        try:
            os.killpg(proc.pid, 0)
        except ProcessLookupError:
            break
        time.sleep(0.05)
    else:
        pytest.fail("processes of the batch still running 10 s after it exited")
    again = subprocess.run([sys.executable, "-m", "acq", "analyze", str(folder), "--jobs", "2", "--no-report",
                            "--json"], capture_output=True, text=True, timeout=300)
    assert again.returncode == 0, again.stderr
    outcomes = [d["outcome"] for d in json.loads(again.stdout)]
    assert sorted(outcomes) == sorted(["skipped"] * ok + ["analysed"] * (n - ok))  # the re-run goes on


def _flip_a_bit_in_the_current(path: Path) -> None:
    """Damage ``path`` in place: one bit flipped in the second chunk of the phase current (its checksum fails; the
    reader keeps the rest, the batch refuses the session without --partial)."""
    with h5py.File(path, "r") as f:
        dataset = f["current/i_a_A"]
        offset = dataset.id.get_chunk_info_by_coord((dataset.chunks[0],)).byte_offset + 100
    with path.open("r+b") as fh:
        fh.seek(offset)
        byte = fh.read(1)
        fh.seek(offset)
        fh.write(bytes([byte[0] ^ 0x40]))


def _batch(capsys: pytest.CaptureFixture[str], folder: Path, *options: str) -> dict[str, str]:
    """``acq analyze FOLDER OPTIONS --no-report --jobs 1 --json``: each session's outcome by file name."""
    run = run_cli(capsys, "analyze", str(folder), *options, "--no-report", "--jobs", "1", "--json")
    assert run.code in (0, 1), run.err
    return {Path(d["path"]).name: d["outcome"] for d in json.loads(run.out)}


@pytest.mark.parametrize(("band", "label"), [("10,400", ""),  # the default band of the 1 kHz simulated encoder
                                             ("20,300", ".band-20-300")])
def test_a_second_batch_analyses_nothing_also_when_the_request_spells_out_the_default(
        recorded: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str], band: str, label: str) -> None:
    """--band 10,400 is the default band here: filed as the default request (the session's own result), it must be
    looked up there too (it was looked up under its own key, found nothing, and every run analysed every session
    again). --band 20,300 is a variant: its own result file and key, skipped the second time as well."""
    names = ["s0", "s1"]
    for name in names:
        copy_session(recorded, tmp_path / f"{name}.h5")
    assert _batch(capsys, tmp_path, "--band", band) == {f"{n}.h5": "analysed" for n in names}
    results = sorted(tmp_path.glob("*.result.json"))
    assert [p.name for p in results] == [f"{n}{label}.result.json" for n in names]
    written = [p.stat().st_mtime_ns for p in results]
    filed = AnalysisRequest(band_hz=None if label == "" else (20.0, 300.0)).key()
    rows = catalogue_rows(tmp_path / "catalogue.sqlite")
    assert [(Path(r["path"]).name, r["verdict"], r["request_key"]) for r in rows] == [(f"{n}.h5", "ok", filed)
                                                                                      for n in names]
    assert _batch(capsys, tmp_path, "--band", band) == {f"{n}.h5": "skipped" for n in names}  # 0 analysed
    assert [p.stat().st_mtime_ns for p in results] == written
    assert len(catalogue_rows(tmp_path / "catalogue.sqlite")) == len(names)
    if label == "":  # the same analysis as the default request's: current for it too
        assert _batch(capsys, tmp_path) == {f"{n}.h5": "skipped" for n in names}


def test_a_failure_of_a_request_spelling_out_the_default_is_filed_as_the_default(
        recorded: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A session damaged in place after its default analysis: --band 10,400 (the default band) fails on it, and the
    failure replaces the session's default row (it was filed under the asked key beside it, so the catalogue and the
    trend went on showing the analysis of the intact file as the session's current one). The run after it tries the
    session again, and files the failure in the same row."""
    copy_session(recorded, tmp_path / "a.h5")
    copy_session(recorded, tmp_path / "b.h5")
    assert _batch(capsys, tmp_path) == {"a.h5": "analysed", "b.h5": "analysed"}
    _flip_a_bit_in_the_current(tmp_path / "b.h5")
    default = AnalysisRequest().key()
    damaged = (f"{tmp_path / 'b.h5'}: damaged (current: samples 2 560–5 119 unreadable) — run acq check, or use "
               "--partial to analyse the intact part")
    for _ in range(2):
        outcomes = _batch(capsys, tmp_path, "--band", "10,400")
        rows = [(Path(r["path"]).name, r["verdict"], r["error"], r["request_key"])
                for r in catalogue_rows(tmp_path / "catalogue.sqlite")]
        assert rows == [("a.h5", "ok", None, default), ("b.h5", None, damaged, default)]
        assert outcomes == {"a.h5": "skipped", "b.h5": "failed"}


def test_ctrl_c_leaves_no_result_of_a_request_spelling_out_the_default_without_its_row(recorded: Path,
                                                                                        tmp_path: Path) -> None:
    """Ctrl-C while a worker draws the report of a result it wrote: --band 10,400 (the default band) writes the
    session's own s<i>.result.json, and a worker stopped after writing it must not leave it without its catalogue row
    (the cleanup removed s<i>.band-10-400.result.json, which no worker writes)."""
    folder = tmp_path / "many"
    folder.mkdir()
    n = 12
    for i in range(n):
        copy_session(recorded, folder / f"s{i}.h5")
    catalogue = folder / "catalogue.sqlite"
    proc = subprocess.Popen([sys.executable, "-m", "acq", "analyze", str(folder), "--band", "10,400", "--jobs", "2"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True)
    _wait_for(lambda: bool(list(folder.glob("*.result.json"))), proc)  # its worker now draws the report (Qt)
    assert proc.poll() is None, proc.communicate()
    os.killpg(proc.pid, signal.SIGINT)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, err
    assert err.startswith("acq: interrupted: "), err
    ok = _ok_names(catalogue)
    assert {p.name.replace(".result.json", ".h5") for p in folder.glob("*.result.json")} == ok
    assert {p.name.replace(".report.png", ".h5") for p in folder.glob("*.report.png")} <= ok
    assert [p.name for p in folder.iterdir() if ".band-" in p.name or p.name.startswith(".")] == []
    assert {r["request_key"] for r in catalogue_rows(catalogue)} <= {AnalysisRequest().key()}
