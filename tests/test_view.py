"""acq view, the report PNG and acq record --live: built from a simulated session, offscreen (one test under Xvfb)."""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from acq.analyze import analyze_session, draw_report
from acq.config import load_bench, load_profile
from acq.recorder import Recorder
from drivers.registry import open_bench
from tests.helpers import run_cli

RATE_HZ = 25600


@pytest.fixture(scope="module", autouse=True)
def offscreen() -> Iterator[None]:
    """Qt's offscreen platform for every window built in this process."""
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("QT_QPA_PLATFORM", "offscreen")
        yield


def _recorder(out_dir: Path, duration_s: float) -> Recorder:
    bench = load_bench(None)
    current, drive = open_bench(bench, fast=True)
    return Recorder(bench, load_profile("triangle_0.2s"), current, drive, out_dir, duration_s)


@pytest.fixture(scope="module")
def session(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A 3 s simulated session (--fast), analysed: .result.json and .report.png beside it."""
    recorder = _recorder(tmp_path_factory.mktemp("sessions"), 3.0)
    recorder.start_devices()
    path = recorder.run().path
    draw_report(analyze_session(path))
    return path


def _pixels(path: Path) -> np.ndarray:
    from pyqtgraph.Qt import QtGui

    image = QtGui.QImage(str(path)).convertToFormat(QtGui.QImage.Format.Format_RGB32)
    rows = np.frombuffer(image.constBits(), np.uint8, count=image.sizeInBytes()).reshape(image.height(), -1)
    return rows[:, : 4 * image.width()].reshape(image.height(), image.width(), 4)[..., :3]


def _assert_real_image(path: Path, size: tuple[int, int]) -> None:
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    pixels = _pixels(path)
    assert (pixels.shape[1], pixels.shape[0]) == size
    assert pixels.std() > 20.0  # a white page with a few lines is ~5; the report is ~40
    assert len(np.unique(pixels.reshape(-1, 3), axis=0)) > 50


def test_window_holds_traces_frf_coherence_and_values(session: Path) -> None:
    import pyqtgraph as pg

    from acq.plots import ReportView, ensure_app
    from acq.view import session_figure

    ensure_app()
    view = ReportView([session_figure(session)], title="test")
    plots = view.plots
    assert list(plots) == ["torque", "speed", "frf", "coherence"]
    labels = {name: {side: (p.getAxis(side).labelText, p.getAxis(side).labelUnits) for side in ("bottom", "left")}
              for name, p in plots.items()}
    assert labels["torque"] == {"bottom": ("t (drive clock)", "s"), "left": ("T_e", "N·m")}
    assert labels["speed"] == {"bottom": ("t (drive clock)", "s"), "left": ("ω_m", "rad/s")}
    assert labels["frf"] == {"bottom": ("f", "Hz"), "left": ("|H|", "rad/(s·N·m)")}
    assert labels["coherence"]["bottom"] == ("f", "Hz") and labels["coherence"]["left"][0] == "γ²"
    assert plots["speed"].getViewBox().linkedView(pg.ViewBox.XAxis) is plots["torque"].getViewBox()
    assert plots["coherence"].getViewBox().linkedView(pg.ViewBox.XAxis) is plots["frf"].getViewBox()
    assert plots["frf"].getAxis("bottom").logMode and plots["frf"].getAxis("left").logMode
    assert [len(plots[n].listDataItems()) for n in plots] == [1, 1, 4, 1]  # |H|, band low/high, model
    items = plots["frf"].items
    assert sum(isinstance(i, pg.FillBetweenItem) for i in items) == 1
    lines = [i for i in items if isinstance(i, pg.InfiniteLine)]
    assert sorted(line.objectName() for line in lines) == ["f_a", "f_r"]
    f_a, f_r = sorted(10 ** line.value() for line in lines)
    assert 45 < f_a < 65 and 90 < f_r < 115  # the simulated plant: 55 Hz, 102 Hz
    assert [label.text for _, label in plots["frf"].legend.items] == ["measured", "two-mass fit, 95 % band"]
    panel = view.panel.text()
    assert all(s in panel for s in ("K", "J_m", "J_l", "N·m/rad", "kg·m²", "f_a", "f_r", "verdict"))


def test_several_sessions_overlay_their_frfs_with_a_legend(session: Path, tmp_path: Path) -> None:
    from acq.plots import ReportView, ensure_app
    from acq.view import session_figure

    later = tmp_path / "later_joint1.h5"
    shutil.copy(session, later)
    ensure_app()
    view = ReportView([session_figure(session), session_figure(later)])
    assert len(view.plots["frf"].listDataItems()) == 8
    names = [label.text for _, label in view.plots["frf"].legend.items]
    assert names == [f"{session.stem}: measured", f"{session.stem}: two-mass fit, 95 % band",
                     "later_joint1: measured", "later_joint1: two-mass fit, 95 % band"]


def test_screenshot_and_report_are_real_images_of_the_asked_size(session: Path, tmp_path: Path,
                                                                 capsys: pytest.CaptureFixture[str]) -> None:
    shot = tmp_path / "shot.png"
    run = run_cli(capsys, "view", str(session), "--screenshot", str(shot), "--size", "1200x800")
    assert run.code == 0 and f"screenshot: {shot} (1200×800 px)" in run.out
    _assert_real_image(shot, (1200, 800))
    _assert_real_image(session.with_name(session.stem + ".report.png"), (1600, 1000))


def test_without_a_display_view_says_so_in_one_line(session: Path, monkeypatch: pytest.MonkeyPatch,
                                                   capsys: pytest.CaptureFixture[str]) -> None:
    for name in ("DISPLAY", "WAYLAND_DISPLAY", "QT_QPA_PLATFORM"):
        monkeypatch.delenv(name, raising=False)
    run = run_cli(capsys, "view", str(session))
    assert run.code == 1
    assert run.err == ("acq view: no display (DISPLAY and WAYLAND_DISPLAY are unset) — save the window as an image "
                       "instead: acq view SESSION --screenshot out.png\n")


@pytest.fixture
def xvfb() -> Iterator[str]:
    """A private X server on a free display number; yields ``:N``."""
    if shutil.which("Xvfb") is None:
        pytest.skip("Xvfb is not installed (CI installs it: .ci/run)")
    proc = subprocess.Popen(["Xvfb", "-displayfd", "1", "-screen", "0", "1600x1200x24", "-nolisten", "tcp"],
                            stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    try:
        number = proc.stdout.readline().strip() if proc.stdout else ""
        assert number.isdigit(), "Xvfb did not report its display"
        yield f":{number}"
    finally:
        proc.terminate()
        proc.wait(timeout=10)


def test_view_screenshot_and_live_window_under_xvfb(session: Path, tmp_path: Path, xvfb: str) -> None:
    env = {k: v for k, v in os.environ.items() if k not in ("QT_QPA_PLATFORM", "WAYLAND_DISPLAY")}
    env["DISPLAY"] = xvfb
    shot = tmp_path / "xvfb.png"
    done = subprocess.run([sys.executable, "-m", "acq", "view", str(session), "--screenshot", str(shot)],
                          env=env, capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    _assert_real_image(shot, (1600, 1000))
    live = subprocess.run([sys.executable, "-m", "acq", "record", "--profile", "triangle_0.2s", "--duration", "0.5",
                           "--fast", "--live", "--no-analyze", "--out", str(tmp_path)],
                          env=env, capture_output=True, text=True, timeout=60)
    assert live.returncode == 0, live.stderr
    assert "live view: " in live.stderr and "frames drawn" in live.stderr


def test_live_view_loses_no_samples_and_draws_frames(tmp_path: Path) -> None:
    from acq.live import LiveView

    recorder = _recorder(tmp_path, 2.0)
    view = LiveView(recorder)
    recorder.start_devices()
    result, stats = view.run(recorder.run)
    assert result.status == "complete"
    assert (result.current_samples, result.encoder_samples) == (2 * RATE_HZ, 2000)
    assert (result.current_gaps, result.encoder_gaps) == (0, 0)
    assert view.feed.counts == {"current": 2 * RATE_HZ, "encoder": 2000}
    assert stats.frames > 0 and stats.frame_rate_hz > 0


def test_ctrl_c_under_the_live_view_ends_the_recording_as_interrupted(tmp_path: Path) -> None:
    from pyqtgraph.Qt import QtCore

    from acq.live import LiveView
    from acq.session import load

    recorder = _recorder(tmp_path, 30.0)
    view = LiveView(recorder)
    recorder.start_devices()
    QtCore.QTimer.singleShot(0, lambda: os.kill(os.getpid(), signal.SIGINT))
    result, _ = view.run(recorder.run)
    assert (result.status, result.stop_reason) == ("interrupted", "interrupted by user (Ctrl-C)")
    assert 0 < result.current_samples < 30 * RATE_HZ
    assert load(result.path).status == "interrupted"
