"""`acq analyze --json` leaves the report PNG to a background drawer: the caller's process exits with the numbers
before the picture is drawn; the picture then appears, the same as one drawn in the process; a failure is a note and
a log line; a drawer whose result was replaced or removed draws nothing. Real processes, real files read back."""

from __future__ import annotations

import fcntl
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import pytest

from acq.ui.report_png import drawers_lock_path
from analysis import AnalysisRequest, TwoMassParams
from tests.helpers import record_session_in_subprocess

#: How long a test waits for a background drawer (≈ 1 s alone) before it fails; only a bound, not a measurement.
DRAWER_BOUND_S = 120.0
#: Another analysis of the same file that writes its result (the default file name: a fit start other than the bench's
#: [nominal] is no variant), with other content than the first.
OTHER_START = AnalysisRequest(nominal=TwoMassParams(K_Nm_per_rad=900.0, Jm_kgm2=0.003027, Jl_kgm2=0.00748,
                                                    C_Nms_per_rad=0.0))


@pytest.fixture(scope="module")
def recorded(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A 3 s simulated session (--fast), not analysed."""
    return record_session_in_subprocess(tmp_path_factory.mktemp("recorded"), 3.0)


@pytest.fixture
def session(recorded: Path, tmp_path: Path) -> Path:
    """A copy of the recorded session in a folder of its own."""
    folder = tmp_path / "sessions"
    folder.mkdir()
    return Path(shutil.copy2(recorded, folder / recorded.name))


@pytest.fixture
def env(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> dict[str, str]:
    """The environment of the acq processes: a temp folder of this test's own (so the drawers' lock is this
    test's), offscreen Qt; the same temp folder for this process's :func:`drawers_lock_path`."""
    tmpdir = tmp_path / "tmp"
    tmpdir.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(tmpdir))
    return {**os.environ, "TMPDIR": str(tmpdir), "QT_QPA_PLATFORM": "offscreen"}


@contextmanager
def _drawers_held() -> Iterator[None]:
    """This test holds the background drawers' lock: no drawer can draw until the block ends."""
    with drawers_lock_path().open("a") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        yield


def _assert_real_image(path: Path, size: tuple[int, int]) -> None:
    """``path`` is a PNG of ``size`` (width, height) px with a drawing on it (read back by Qt)."""
    from pyqtgraph.Qt import QtGui

    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    image = QtGui.QImage(str(path)).convertToFormat(QtGui.QImage.Format.Format_RGB32)
    assert (image.width(), image.height()) == size
    rows = np.frombuffer(image.constBits(), np.uint8, count=image.sizeInBytes()).reshape(image.height(), -1).copy()
    pixels = rows[:, : 4 * image.width()].reshape(image.height(), image.width(), 4)[..., :3]
    assert pixels.std() > 20.0  # a white page with a few lines is ~5; the report is ~40
    assert len(np.unique(pixels.reshape(-1, 3), axis=0)) > 50


def _analyze(session: Path, env: dict[str, str], *options: str) -> dict:
    """``acq analyze SESSION --json OPTIONS`` as a script runs it (stdout and stderr read to their end); its JSON."""
    proc = subprocess.run([sys.executable, "-m", "acq", "analyze", str(session), "--json", *options],
                          capture_output=True, text=True, env=env, timeout=DRAWER_BOUND_S)
    assert proc.returncode == 0, proc.stderr
    assert proc.stderr == ""
    return json.loads(proc.stdout)


def _wait_for(what: str, done: Callable[[], bool]) -> None:
    start = time.monotonic()
    while not done():
        assert time.monotonic() - start < DRAWER_BOUND_S, f"{what}: not within {DRAWER_BOUND_S:g} s"
        time.sleep(0.02)


def _paths(session: Path) -> tuple[Path, Path, Path]:
    stem = session.with_name(session.stem)
    return (Path(f"{stem}.report.png"), Path(f"{stem}.result.json"), Path(f"{stem}.report.log"))


def test_the_json_caller_exits_before_the_picture_which_then_appears_as_drawn_in_process(
        session: Path, env: dict[str, str]) -> None:
    png, result, log = _paths(session)
    with _drawers_held():  # the drawer cannot draw while this test holds its lock
        doc = _analyze(session, env)
        # the caller has its numbers and its process has exited; the picture is not there yet (its drawer waits)
        assert doc["quality"]["verdict"] == "ok" and doc["K_Nm_per_rad"] > 0
        assert json.loads(result.read_text()) == doc
        assert not png.exists()
        assert log.exists() and log.stat().st_size == 0  # the drawer's stderr, empty while nothing went wrong
    _wait_for(f"{png} drawn", png.exists)
    _assert_real_image(png, (1600, 1000))
    _wait_for(f"{log} removed", lambda: not log.exists())  # drawn: nothing to report
    assert json.loads(result.read_text()) == doc  # no note: the picture was drawn
    assert sorted(p.name for p in session.parent.iterdir()) == sorted(
        [session.name, png.name, result.name, "catalogue.sqlite"])  # no job file, no temp file left
    background = png.read_bytes()
    png.unlink()
    again = _analyze(session, env, "--wait-report")
    assert {**again, "analyzed_utc": None} == {**doc, "analyzed_utc": None}
    assert png.read_bytes() == background  # the same picture as the one drawn in the process


def test_a_drawer_that_fails_leaves_a_note_in_the_result_and_a_line_in_the_log(
        session: Path, env: dict[str, str], tmp_path: Path) -> None:
    png, result, log = _paths(session)
    no_qt = tmp_path / "no_qt" / "pyqtgraph"
    no_qt.mkdir(parents=True)
    (no_qt / "__init__.py").write_text("raise ImportError('libEGL.so.1: cannot open shared object file')\n")
    env = {**env, "PYTHONPATH": os.pathsep.join([str(no_qt.parent), env.get("PYTHONPATH", "")])}
    doc = _analyze(session, env)  # a host without the Qt libraries: the numbers come all the same
    why = "ImportError: libEGL.so.1: cannot open shared object file"
    _wait_for("the note", lambda: json.loads(result.read_text())["quality"]["reasons"] != doc["quality"]["reasons"])
    noted = json.loads(result.read_text())
    assert noted["quality"]["reasons"] == [*doc["quality"]["reasons"], f"note: report not drawn: {why}"]
    assert {k: v for k, v in noted.items() if k != "quality"} == {k: v for k, v in doc.items() if k != "quality"}
    assert log.read_text() == f"acq: {png}: report not drawn ({why}); the result stands in {result}\n"
    assert not png.exists()
    # the next analysis that draws its picture removes the old failure's log
    _analyze(session, {**env, "PYTHONPATH": os.environ.get("PYTHONPATH", "")}, "--wait-report")
    assert png.exists() and not log.exists()


def _drawers_of(folder: Path) -> list[int]:
    """The background drawers (``python -m acq.ui.report_png JOB``) of the sessions in ``folder``: their PIDs."""
    pids = []
    for cmdline in Path("/proc").glob("[0-9]*/cmdline"):
        try:
            args = cmdline.read_bytes().split(b"\0")
        except OSError:
            continue  # ended meanwhile
        if b"acq.ui.report_png" in args and any(a.startswith(bytes(folder) + b"/") for a in args):
            pids.append(int(cmdline.parent.name))
    return pids


def test_a_drawer_whose_folder_was_removed_ends_quietly(session: Path, env: dict[str, str]) -> None:
    with _drawers_held():
        _analyze(session, env)
        assert len(_drawers_of(session.parent)) == 1  # waiting for its turn
        shutil.rmtree(session.parent)  # the caller removes the folder (a CI step's scratch folder)
    _wait_for("the drawer to end", lambda: not _drawers_of(session.parent))
    assert not session.parent.exists()  # nothing written, no folder made again


def test_a_drawer_draws_nothing_over_a_newer_result(session: Path, env: dict[str, str]) -> None:
    from acq.offline.analyze import analyze_session
    from acq.ui.report_png import _draw_job, _read_job, _write_job  # the drawer's own steps, in this process

    done = analyze_session(session)
    png, result, log = _paths(session)
    job = _write_job(done, png)
    older = _read_job(job.read_bytes())
    analyze_session(session, OTHER_START)  # a newer result of the same file
    newer = result.read_text()
    log.write_text("")  # as the drawer's process has it
    _draw_job(older)
    assert not png.exists() and result.read_text() == newer and not log.exists()


def test_a_picture_finished_after_a_newer_result_is_not_put_in_place(session: Path, env: dict[str, str],
                                                                       monkeypatch: pytest.MonkeyPatch) -> None:
    """The result is checked again when the picture is ready (drawing takes ≈ 0.6 s): an analysis that came
    meanwhile (here `--no-report`, which also removes an earlier picture) keeps its result without a stale PNG."""
    import acq.ui.report_view as report_view
    from acq.offline.analyze import analyze_session
    from acq.ui.report_png import _draw_job, _read_job, _write_job

    monkeypatch.setenv("QT_QPA_PLATFORM", "offscreen")
    done = analyze_session(session)
    png, result, _ = _paths(session)
    job_file = _write_job(done, png)
    job = _read_job(job_file.read_bytes())
    job_file.unlink()  # as the drawer does when it has read it
    draw = report_view.render_report_png

    def draw_while_a_newer_analysis_comes(*args: object, **kwargs: object) -> None:
        draw(*args, **kwargs)
        analyze_session(session, OTHER_START, report=False)

    monkeypatch.setattr(report_view, "render_report_png", draw_while_a_newer_analysis_comes)
    _draw_job(job)
    assert not png.exists()
    assert json.loads(result.read_text())["options"]["nominal"]["K_Nm_per_rad"] == 900.0
    assert not [p.name for p in session.parent.iterdir() if p.name.startswith(".")]  # no temp picture left


def test_a_drawer_stopped_by_its_timeout_leaves_the_note_and_no_temp_file(
        session: Path, env: dict[str, str], monkeypatch: pytest.MonkeyPatch, capfd: pytest.CaptureFixture[str]) -> None:
    import acq.ui.report_png as report_png
    from acq.offline.analyze import analyze_session

    done = analyze_session(session)
    png, result, _ = _paths(session)
    job_file = report_png._write_job(done, png)
    job = report_png._read_job(job_file.read_bytes())
    job_file.unlink()
    left = png.with_name(f".{png.name}.abc123.tmp.png")  # what atomic_path had begun when Qt hung
    left.write_bytes(b"half a picture")
    monkeypatch.setattr(report_png.os, "_exit", lambda code: (_ for _ in ()).throw(SystemExit(code)))
    with pytest.raises(SystemExit):
        report_png._give_up(job)
    why = f"stopped after {report_png.DRAW_TIMEOUT_S:g} s without a picture"
    assert json.loads(result.read_text())["quality"]["reasons"][-1] == f"note: report not drawn: {why}"
    assert f"acq: {png}: report not drawn ({why}); the result stands in {result}" in capfd.readouterr().err
    assert not left.exists() and not png.exists()
