"""acq view, the report PNG and acq record --live: built from a simulated session, offscreen (one test under Xvfb)."""

from __future__ import annotations

import os
import re
import shutil
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from pyqtgraph.Qt import QtCore

from acq.config import load_bench, load_profile
from acq.offline.analyze import analyze_session
from acq.ui.report_png import draw_report
from acq.recording.recorder import Recorder
from analysis import AnalysisRequest
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
    profile = load_profile("triangle_0.2s").model_copy(update={"dither_seed": 0})  # the same motion in every run
    return Recorder(bench, profile, current, drive, out_dir, duration_s)


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

    from acq.ui.qt_app import ensure_app
    from acq.ui.report_view import ReportView
    from acq.ui.view import session_figure

    ensure_app()
    view = ReportView([session_figure(session)], title="test")
    plots = view.plots
    assert list(plots) == ["torque", "speed", "frf", "misfit", "phase", "coherence"]
    labels = {name: {side: (p.getAxis(side).labelText, p.getAxis(side).labelUnits) for side in ("bottom", "left")}
              for name, p in plots.items()}
    assert labels["misfit"] == {"bottom": ("f", "Hz"), "left": ("misfit", "%")}
    assert labels["torque"] == {"bottom": ("t (drive clock)", "s"), "left": ("T_e", "N·m")}
    assert labels["speed"] == {"bottom": ("t (drive clock)", "s"), "left": ("ω_m", "rad/s")}
    assert labels["frf"] == {"bottom": ("f", "Hz"), "left": ("|H|", "rad/(s·N·m)")}
    assert labels["coherence"]["bottom"] == ("f", "Hz") and labels["coherence"]["left"][0] == "γ²"
    assert plots["speed"].getViewBox().linkedView(pg.ViewBox.XAxis) is plots["torque"].getViewBox()
    assert plots["coherence"].getViewBox().linkedView(pg.ViewBox.XAxis) is plots["frf"].getViewBox()
    assert plots["frf"].getAxis("bottom").logMode and plots["frf"].getAxis("left").logMode
    assert plots["phase"].getViewBox().linkedView(pg.ViewBox.XAxis) is plots["frf"].getViewBox()
    # |H|, band low/high, model; the model's band about 0 (2), the misfit per bin, the test's allowance (2) and its
    # window means; phase
    assert [len(plots[n].listDataItems()) for n in plots] == [1, 1, 4, 6, 2, 1]
    items = plots["frf"].items
    assert sum(isinstance(i, pg.FillBetweenItem) for i in items) == 1
    lines = [i for i in items if isinstance(i, pg.InfiniteLine)]
    assert sorted(line.objectName() for line in lines) == ["f_a", "f_r"]
    f_a, f_r = sorted(10 ** line.value() for line in lines)
    assert 45 < f_a < 65 and 90 < f_r < 115  # the simulated plant: 55 Hz, 102 Hz
    names = [label.text for _, label in view.legend.items]
    assert names[0] == "measured |H|" and names[1].startswith("two-mass fit, 95 % band ± ")
    assert names[2:] == ["misfit (model / measured − 1), test windows", "allowed misfit (noise, quantisation)",
                         "fit band 10–400 Hz"]
    # measured and model apart: dark grey dots, the model in the session's colour (both were the same blue)
    measured, *_, model = plots["frf"].listDataItems()
    assert pg.mkBrush(measured.opts["symbolBrush"]).color().name() == "#404040"
    assert pg.mkPen(model.opts["pen"]).color().name() == "#1f77b4"
    regions = [i for i in items if isinstance(i, pg.LinearRegionItem)]  # the fit band, shaded
    assert [tuple(round(10 ** v) for v in r.getRegion()) for r in regions] == [(10, 400)]
    assert all(any(isinstance(i, pg.LinearRegionItem) for i in plots[n].items) for n in ("phase", "coherence"))
    panel = view.panel.text()
    assert all(s in panel for s in ("K", "J_m", "J_l", "N·m/rad", "kg·m²", "f_a", "f_r", "verdict"))


def test_several_sessions_overlay_their_frfs_with_a_legend(session: Path, tmp_path: Path) -> None:
    from acq.ui.qt_app import ensure_app
    from acq.ui.report_view import ReportView
    from acq.ui.view import session_figure

    later = tmp_path / "later_joint1.h5"
    shutil.copy(session, later)
    ensure_app()
    view = ReportView([session_figure(session), session_figure(later)])
    assert len(view.plots["frf"].listDataItems()) == 8
    names = [label.text for _, label in view.legend.items]
    assert names[0] == "measured (dots in the session's colour)" and names[-1] == "fit band 10–400 Hz"
    assert [n.split(" ± ")[0] for n in names[1:3]] == [f"{session.stem}: two-mass fit, 95 % band",
                                                       "later_joint1: two-mass fit, 95 % band"]
    assert re.fullmatch(r".*95 % band ± \d+(\.\d+)?(–\d+(\.\d+)?)? %", names[1])  # 2 significant digits


def _laid_out(view: Any, tmp_path: Path) -> None:
    """Show and render the view offscreen, so that its layout (and the f_a/f_r label rows) is final."""
    from acq.ui.qt_app import grab_png

    grab_png(view, tmp_path / "layout.png")


def _scene_box(item: Any) -> Any:
    return item.mapRectToScene(item.boundingRect())


def test_legend_and_frequency_labels_cover_no_curve_and_no_label_overlaps(session: Path, tmp_path: Path) -> None:
    from acq.ui.qt_app import ensure_app
    from acq.ui.report_view import ReportView
    from acq.ui.view import session_figure

    ensure_app()
    later = Path(shutil.copy(session, tmp_path / "later_joint1.h5"))  # same f_a and f_r: labels at the same place
    one, two = session_figure(session), session_figure(later)
    for figures in ([one], [one, two]):
        view = ReportView(figures)
        _laid_out(view, tmp_path)
        frf = view.plots["frf"]
        fd = figures[0].figures
        peak = int(np.argmax(fd.model_abs))
        peak_px = frf.vb.mapViewToScene(QtCore.QPointF(np.log10(fd.model_f_hz[peak]), np.log10(fd.model_abs[peak])))
        plot_area = frf.vb.sceneBoundingRect()
        assert plot_area.contains(peak_px)
        legend = view.legend.sceneBoundingRect()
        assert not legend.contains(peak_px) and not legend.intersects(plot_area)
        boxes = [_scene_box(t) for t in view.mark_labels]
        assert len(boxes) == 2 * len(figures)
        for i, a in enumerate(boxes):
            assert not a.intersects(plot_area) and not a.intersects(legend)
            assert not any(a.intersects(b) for b in boxes[i + 1:])
        for text, f_hz in zip(view.mark_labels, (fd.f_a_hz, fd.f_r_hz)):  # each label is centred on its line
            x_px = frf.vb.mapViewToScene(QtCore.QPointF(np.log10(f_hz), 0.0)).x()
            assert abs(_scene_box(text).center().x() - x_px) < 2.0


def test_at_1200x800_the_plots_fit_the_window_and_each_axis_label_stays_beside_its_panel(
        session: Path, tmp_path: Path) -> None:
    """The trial: at --size 1200x800 the misfit panel's label ("model / measured − 1 (%)", 167 px) ran 40 px past
    its 90 px panel into the |H| and phase labels, and a three-column legend made the plots 1085 px wide in an 840 px
    area (the FRF cut off at 80 Hz). Measured in the scene, rendered at that size."""
    from acq.ui.qt_app import ensure_app, grab_png
    from acq.ui.report_view import ReportView
    from acq.ui.view import session_figure

    ensure_app()
    view = ReportView([session_figure(session)], title="joint1 · s.h5")
    png = grab_png(view, tmp_path / "report.png", (1200, 800))
    _assert_real_image(png, (1200, 800))
    names = ("frf", "misfit", "phase", "coherence")
    labels = {n: _scene_box(view.plots[n].getAxis("left").label) for n in names}
    for name in names:
        panel = view.plots[name].vb.sceneBoundingRect()
        assert panel.right() <= view.graphics.width(), name  # the whole frequency axis is in the window
        assert labels[name].top() >= panel.top() - 5 and labels[name].bottom() <= panel.bottom() + 5, name
    assert not any(labels[a].intersects(labels[b]) for a, b in zip(names, names[1:]))


def _assert_nothing_cut_off(view: Any) -> None:
    """Every plot, the legend and the headings inside the plots' area, the values inside the panel (measured in the
    scene and the widget, as drawn)."""
    area = QtCore.QRectF(0, 0, view.graphics.width(), view.graphics.height())
    items = {**view.plots, "legend": view.legend,
             **{f"label {i}": item for i, item in enumerate(view.graphics.ci.items) if type(item).__name__ == "LabelItem"}}
    for name, item in items.items():
        box = item.sceneBoundingRect()
        assert area.contains(box), (name, box, area)
    assert view.graphics.ci.layout.minimumSize().width() <= area.width()
    assert view.panel.heightForWidth(view.panel.width()) <= view.panel.height()


def test_at_1000x700_nothing_is_cut_off_and_a_size_too_small_is_refused_naming_the_minimum(
        session: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The report: at --size 1000x700 the two-column legend made the plots 828 px wide in the 640 px beside the values
    (the FRF, misfit, phase and coherence cut off at 60 Hz, f_r's label with them). The legend now takes one column
    where two do not fit; a size smaller than the report's minimum is one line naming it, exit 2, no PNG."""
    from acq.ui.qt_app import ensure_app, grab_png
    from acq.ui.report_view import ReportView
    from acq.ui.view import session_figure

    shot = tmp_path / "shot.png"
    run = run_cli(capsys, "view", str(session), "--screenshot", str(shot), "--size", "1000x700")
    assert (run.code, run.out) == (0, f"screenshot: {shot} (1000×700 px)\n")
    _assert_real_image(shot, (1000, 700))
    ensure_app()
    view = ReportView([session_figure(session)], title=f"joint1 · {session.name}")
    width, height = view.minimum_size()
    assert 880 <= width <= 960 and 420 <= height <= 480  # 921×446 px with Qt 6.11's fonts here
    for size, columns in (((1000, 700), 1), ((width, height), 1), ((1600, 1000), 2)):
        grab_png(view, tmp_path / "report.png", size)
        assert view.legend.columnCount == columns, size
        _assert_nothing_cut_off(view)
    assert view.plots["torque"].vb.sceneBoundingRect().left() == view.plots["speed"].vb.sceneBoundingRect().left()
    small = tmp_path / "small.png"
    run = run_cli(capsys, "view", str(session), "--screenshot", str(small), "--size", f"{width - 1}x{height}")
    assert (run.code, run.out) == (2, "")
    assert run.err == (f"acq: error: --size {width - 1}x{height}: too small for this report — it needs at least "
                       f"{width}x{height} px (smaller, its plots and values would be cut off)\n")
    assert not small.exists()


def test_phase_panel_when_the_clocks_are_aligned_and_none_when_not(session: Path, tmp_path: Path) -> None:
    from acq.ui.qt_app import ensure_app
    from acq.ui.report_panel import SessionFigure
    from acq.ui.report_view import ReportView
    from acq.ui.view import session_figure

    ensure_app()
    aligned = session_figure(session)
    assert aligned.figures.phase_valid and aligned.values["clock"]["residual_s"] < 100e-6
    view = ReportView([aligned])
    assert list(view.plots) == ["torque", "speed", "frf", "misfit", "phase", "coherence"]
    assert view.plots["phase"].getAxis("left").labelText == "phase of H"
    fd = aligned.figures
    in_band = (fd.f_hz >= fd.band_hz[0]) & (fd.f_hz <= fd.band_hz[1]) & (fd.coherence > 0.9)
    model_phase = np.interp(fd.f_hz[in_band], fd.model_f_hz, fd.model_phase_deg)
    assert np.median(np.abs(fd.H_phase_deg[in_band] - model_phase)) < 5.0  # measured and model phase agree, degrees
    assert "phase shown: clocks aligned to" in view.panel.text()
    assert "torque encoder · params K,Jm,Jl · fit amplitude · band 10–400 Hz" in view.panel.text()
    paper = analyze_session(session, AnalysisRequest(pipeline="paper"), write=False)  # the paper's chain: clocks not aligned
    assert not paper.result.figures.phase_valid
    unaligned = ReportView([SessionFigure("paper", paper.result.figures, paper.json_dict)])
    assert "phase" not in unaligned.plots and list(unaligned.plots)[-2:] == ["misfit", "coherence"]
    assert "phase not shown: the clocks were not aligned" in unaligned.panel.text()
    assert "chain (--paper) · torque hilbert" in unaligned.panel.text()


def test_screenshot_and_report_are_real_images_of_the_asked_size(session: Path, tmp_path: Path,
                                                                 capsys: pytest.CaptureFixture[str]) -> None:
    shot = tmp_path / "shot.png"
    run = run_cli(capsys, "view", str(session), "--screenshot", str(shot), "--size", "1200x800")
    assert run.code == 0 and f"screenshot: {shot} (1200×800 px)" in run.out
    _assert_real_image(shot, (1200, 800))
    _assert_real_image(session.with_name(session.stem + ".report.png"), (1600, 1000))


def test_without_a_display_view_says_so_in_one_line(session: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                   capsys: pytest.CaptureFixture[str]) -> None:
    for name in ("DISPLAY", "WAYLAND_DISPLAY", "QT_QPA_PLATFORM"):
        monkeypatch.delenv(name, raising=False)
    run = run_cli(capsys, "view", str(session))
    # bad input (exit 2), as acq record --live without a display
    assert (run.code, run.out) == (2, "")
    assert run.err == ("acq: error: no display (DISPLAY and WAYLAND_DISPLAY are unset) — save the window as an image "
                       "instead: acq view SESSION --screenshot out.png\n")
    # a trend's own form, not a session's: of a folder a monitor may still fill (one of uncatalogued sessions is said
    # first, as a window would say it)
    run = run_cli(capsys, "view", "--trend", "joint1", str(tmp_path))
    assert (run.code, run.err) == (2, "acq: error: no display (DISPLAY and WAYLAND_DISPLAY are unset) — save the window "
                                      f"as an image instead: acq view --trend joint1 {tmp_path} --screenshot "
                                      "out.png\n")
    uncatalogued = tmp_path / "sessions"
    uncatalogued.mkdir()
    shutil.copy(session, uncatalogued)
    run = run_cli(capsys, "view", "--trend", "joint1", str(uncatalogued))
    assert (run.code, run.err) == (2, f"acq: error: {uncatalogued / 'catalogue.sqlite'}: no catalogue — fill one with "
                                      f"acq analyze {uncatalogued}/ first\n")
    run = run_cli(capsys, "record", "--profile", "triangle_0.2s", "--fast", "--live", "--out",
                  str(session.parent / "live"))
    assert (run.code, run.err) == (2, "acq: error: --live needs a display (DISPLAY or WAYLAND_DISPLAY is unset); "
                                      "record without --live\n")
    assert not (session.parent / "live").exists()


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
    from acq.ui.live import LiveView

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

    from acq.ui.live import LiveView
    from acq.recording.reader import load

    recorder = _recorder(tmp_path, 30.0)
    view = LiveView(recorder)
    recorder.start_devices()
    QtCore.QTimer.singleShot(0, lambda: os.kill(os.getpid(), signal.SIGINT))
    result, _ = view.run(recorder.run)
    assert (result.status, result.stop_reason) == ("interrupted", "interrupted by user (Ctrl-C)")
    assert 0 < result.current_samples < 30 * RATE_HZ
    assert load(result.path).status == "interrupted"


def _stop_and_wait(proc: subprocess.Popen[str], signum: int) -> str:
    """Send ``signum`` to the process group (as the terminal does on Ctrl-C); its stderr once it exited."""
    os.killpg(proc.pid, signum)
    try:
        _, err = proc.communicate(timeout=20)  # before the fix: never (the loop ran on until kill -9)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.communicate()
        pytest.fail(f"still running 20 s after signal {signum}")
    return err


@pytest.mark.parametrize("signum", [signal.SIGTERM, signal.SIGINT])
@pytest.mark.parametrize("what", ["session", "trend"])
def test_ctrl_c_or_sigterm_closes_the_view_window_with_exit_130_and_one_line(session: Path, what: str,
                                                                            signum: int) -> None:
    """The trial: acq view (a session, or --trend) could not be stopped from the terminal — SIGTERM printed a
    traceback (KeyboardInterrupt raised in Qt's frames) and both ran on until kill -9."""
    if what == "trend":
        from acq.monitoring.session_outcome import record_outcome

        record_outcome(analyze_session(session, write=False, report=False), None, 1.0)
        args = ["--trend", "joint1", str(session.parent), "--refresh", "1"]
        title = "acq trend — joint1"
    else:
        args, title = [str(session)], f"acq view — joint1 · {session.name}"
    proc = subprocess.Popen([sys.executable, "-m", "acq", "view", *args], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, start_new_session=True,
                            env={**os.environ, "QT_QPA_PLATFORM": "offscreen"})
    assert proc.stdout is not None
    line = proc.stdout.readline()  # said once the window is shown
    assert line == f"{title}: close the window or press Ctrl-C to end\n", (line, proc.communicate())
    time.sleep(0.5)  # in Qt's event loop (a signal before it was a KeyboardInterrupt in Python's frames)
    err = _stop_and_wait(proc, signum)
    assert proc.returncode == 130 and err == "acq: interrupted\n", err


def test_the_trend_window_waiting_for_a_monitors_first_window_says_so_once_and_ctrl_c_ends_it(tmp_path: Path) -> None:
    """Started before the monitor made its catalogue: a window that waits, one line on the terminal saying for what and
    where, and the Ctrl-C of a terminal ends it with exit 130 and one line."""
    proc = subprocess.Popen([sys.executable, "-m", "acq", "view", "--trend", "joint1", str(tmp_path)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True,
                            env={**os.environ, "QT_QPA_PLATFORM": "offscreen"})
    assert proc.stdout is not None
    line = proc.stdout.readline()  # said once the window is shown
    assert line == "acq trend — joint1: close the window or press Ctrl-C to end\n", (line, proc.communicate())
    err = _stop_and_wait(proc, signal.SIGINT)
    assert proc.returncode == 130
    assert err == f"waiting for the first window of joint1 in {tmp_path / 'catalogue.sqlite'} …\nacq: interrupted\n"


@pytest.mark.parametrize("what", ["missing", "uncatalogued", "file"])
def test_the_trend_window_of_a_folder_no_monitor_fills_is_one_line_not_a_wait(session: Path, tmp_path: Path,
                                                                             what: str) -> None:
    """The report: acq view --trend of a mistyped folder, with a display, waited for ever for a monitor's first window
    (without a display, or with --screenshot, it said the folder was not there); a folder of sessions never catalogued
    waited too (a monitor makes its catalogue before its first window). Now one line, exit 2, no window."""
    folder = tmp_path / ("nosuch" if what == "missing" else "sessions")
    if what == "uncatalogued":
        folder.mkdir()
        shutil.copy(session, folder)
    elif what == "file":
        folder.write_text("not a folder")
    try:
        run = subprocess.run([sys.executable, "-m", "acq", "view", "--trend", "joint1", str(folder), "--refresh", "1"],
                             capture_output=True, text=True, timeout=20,
                             env={**os.environ, "QT_QPA_PLATFORM": "offscreen"})
    except subprocess.TimeoutExpired:
        pytest.fail("acq view --trend still waiting after 20 s")
    expected = {"missing": f"{folder / 'catalogue.sqlite'}: no catalogue — the folder {folder} does not exist",
                "uncatalogued": f"{folder / 'catalogue.sqlite'}: no catalogue — fill one with acq analyze {folder}/ first",
                "file": f"{folder}: is a file, not a folder"}[what]
    assert (run.returncode, run.stdout, run.stderr) == (2, "", f"acq: error: {expected}\n")


#: ``python -c`` of acq's entry point with a Ctrl-C to itself while Qt's import runs shiboken's start-up (the signature
#: module imports PySide6.support): the moment a terminal's Ctrl-C made a fatal error (exit 134) or was lost
_CTRL_C_INSIDE_QT_IMPORT = """
import os, signal, sys

class CtrlCInsideQtImport:
    def find_spec(self, name, path=None, target=None):
        if name == "PySide6.support":
            sys.meta_path.remove(self)
            os.kill(os.getpid(), signal.SIGINT)
        return None

sys.meta_path.insert(0, CtrlCInsideQtImport())
from acq.entry import main
main()
"""


def test_a_ctrl_c_inside_qt_s_import_is_exit_130_and_one_line(tmp_path: Path) -> None:
    """Before: "Fatal Python error: libshiboken/signature: could not initialize part 2", exit 134 (9 of 30 Ctrl-Cs
    1.3…2.4 s after start), or the Ctrl-C lost and the window open (2 of 30). Now the Ctrl-C waits for the import."""
    done = subprocess.run([sys.executable, "-c", _CTRL_C_INSIDE_QT_IMPORT, "view", "--trend", "joint1", str(tmp_path)],
                          capture_output=True, text=True, timeout=60,
                          env={**os.environ, "QT_QPA_PLATFORM": "offscreen"})
    assert (done.returncode, done.stderr, done.stdout) == (130, "acq: interrupted\n", "")


def test_a_ctrl_c_while_click_makes_the_commands_context_is_one_line(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                                    capsys: pytest.CaptureFixture[str]) -> None:
    """A Ctrl-C in click's own frames (here as it makes acq's context) was click's KeyboardInterrupt handling: an empty
    line, then acq's."""
    import click

    make = click.Context.__init__

    def ctrl_c_then_make(context: click.Context, *args: Any, **kwargs: Any) -> None:
        monkeypatch.undo()  # the first context only
        os.kill(os.getpid(), signal.SIGINT)  # handled in this (the main) thread before the next line
        make(context, *args, **kwargs)

    monkeypatch.setattr(click.Context, "__init__", ctrl_c_then_make)
    run = run_cli(capsys, "view", "--trend", "joint1", str(tmp_path))
    assert (run.code, run.err, run.out) == (130, "acq: interrupted\n", "")


@pytest.mark.parametrize("signum", [signal.SIGTERM, signal.SIGINT])
def test_ctrl_c_or_sigterm_under_record_live_ends_the_recording_as_interrupted(tmp_path: Path, signum: int) -> None:
    """The live window's Ctrl-C / SIGTERM stop the recording: the file finished as interrupted, exit 130."""
    from acq.recording.reader import load

    proc = subprocess.Popen([sys.executable, "-m", "acq", "record", "--profile", "triangle_0.2s", "--duration", "600",
                             "--fast", "--live", "--no-analyze", "--out", str(tmp_path)], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, start_new_session=True,
                            env={**os.environ, "QT_QPA_PLATFORM": "offscreen"})
    deadline = time.monotonic() + 60
    while not list(tmp_path.glob("*.h5")) and proc.poll() is None and time.monotonic() < deadline:
        time.sleep(0.05)  # the window is shown before the recording (and its file) starts
    assert proc.poll() is None, proc.communicate()
    time.sleep(0.5)  # some samples recorded
    err = _stop_and_wait(proc, signum)
    reason = "interrupted by user (Ctrl-C)" if signum == signal.SIGINT else "stopped by SIGTERM"
    assert proc.returncode == 130, err
    assert "Traceback" not in err and err.splitlines()[-1].startswith(f"acq: interrupted: {reason} — "), err
    (path,) = tmp_path.glob("*.h5")
    recorded = load(path)
    assert (recorded.status, recorded.meta.stop_reason) == ("interrupted", reason)
    assert 0 < recorded.current.sample_count < 600 * RATE_HZ


def test_the_side_panel_says_the_values_are_motor_side() -> None:
    from types import SimpleNamespace

    from acq.ui.report_panel import SessionFigure, values_html

    figures = SimpleNamespace(phase_valid=True)  # the panel reads only whether the phase is shown
    doc = {"K_Nm_per_rad": 891.0, "ci95": {}, "clock": {"residual_s": 1e-5}}
    html = values_html([SessionFigure("s", figures, doc)])  # type: ignore[arg-type]
    assert html.startswith("<h3>Identified two-mass model (motor side)</h3>") and "891" in html


def test_the_side_panel_gives_the_ends_of_an_interval_that_does_not_determine_its_value() -> None:
    """The trial's report read "C 0.237 ± 3.6e+02 %" and its legend "95 % band ± 4.6–3.6e+02 %"."""
    from types import SimpleNamespace

    from acq.ui.report_panel import SessionFigure, values_html
    from acq.ui.report_view import band_width_text

    figures = SimpleNamespace(phase_valid=True)
    doc = {"K_Nm_per_rad": 923.1, "C_Nms_per_rad": 0.2370008321746361,
           "ci95": {"K_Nm_per_rad": [847.3, 1006.0], "C_Nms_per_rad": [0.03250387560890928, 1.728082987004604]},
           "clock": {"residual_s": 6.8e-5}}
    html = values_html([SessionFigure("s", figures, doc)])  # type: ignore[arg-type]
    assert "<td align='right' nowrap>not determined</td>" in html and "± 8.6 %" in html
    assert "<p>C 0.237 N·m·s/rad: its 95 % interval 0.033 – 1.7 does not determine it</p>" in html
    band = SimpleNamespace(model_abs=np.array([1.0, 1.0]), model_low=np.array([0.954, 0.0]),
                           model_high=np.array([1.046, 7.164]))  # half-widths 4.6 % and 358 %
    assert band_width_text(band) == "± 4.6–360 %"  # type: ignore[arg-type]


def test_the_frf_of_a_failed_verdict_labels_its_fit_failed_and_gives_no_f_a_f_r_number(session: Path) -> None:
    """The report of a failed verdict labelled the fit's resonances "f_a 67.2 Hz", "f_r 77.9 Hz" like a result."""
    from acq.ui.qt_app import ensure_app
    from acq.ui.report_panel import SessionFigure
    from acq.ui.report_view import ReportView
    from acq.ui.view import session_figure

    ensure_app()
    shown = session_figure(session)
    for verdict, legend, marks in (
            ("failed", "failed two-mass fit, 95 % band ± ", ["f_a of the failed fit", "f_r of the failed fit"]),
            ("poor", "two-mass fit, 95 % band ± ", [f"f_a {shown.figures.f_a_hz:.1f} Hz",
                                                    f"f_r {shown.figures.f_r_hz:.1f} Hz"])):
        values = {**shown.values, "quality": {**shown.values["quality"], "verdict": verdict}}
        view = ReportView([SessionFigure(shown.name, shown.figures, values)])
        assert [label.text for _, label in view.legend.items][1].startswith(legend)
        assert [t.toPlainText() for t in view.mark_labels] == marks


def test_the_side_panel_shows_a_failed_verdicts_fit_as_not_a_result() -> None:
    """The new user's report panel showed K 995.5 and J_l 3.061e+16 in bold under "verdict failed"."""
    from types import SimpleNamespace

    from acq.ui.report_panel import SessionFigure, values_html
    from tests.test_display import _failed_doc

    figures = SimpleNamespace(phase_valid=True)
    html = values_html([SessionFigure("s", figures, _failed_doc())])  # type: ignore[arg-type]
    for name, unit in (("K", "N·m/rad"), ("J_l", "kg·m²"), ("f_a", "Hz")):
        assert (f"<tr><td nowrap>{name}</td><td align='right'>—</td><td align='right' nowrap>not a result</td>"
                f"<td nowrap>{unit}</td></tr>") in html
    assert ("<p>verdict failed: the fit&#x27;s K, J_m, J_l, C, f_a and f_r are not a result (the .result.json keeps "
            "them)</p>") in html
    assert "995.5" not in html and "3.061e+16" not in html and "<b>40.13</b>" in html  # the clock's numbers stay
    poor = _failed_doc()
    poor["quality"]["verdict"] = "poor"
    html = values_html([SessionFigure("s", figures, poor)])  # type: ignore[arg-type]
    assert "<b>995.5</b>" in html and "not a result" not in html


@pytest.mark.parametrize(("dither", "kind"), [(0.02, "misfit"), (0.0, "third mode")], ids=["misfit", "third-mode"])
def test_the_report_marks_where_a_poor_verdict_says_the_model_misses(tmp_path: Path, dither: float, kind: str) -> None:
    """The third mass at 150 Hz: the verdict named a misfit band (shipped dithered profile) or a third mode
    (undithered) by its frequency, but the report drew nothing there."""
    import pyqtgraph as pg

    from acq.ui.qt_app import ensure_app
    from acq.ui.report_marks import VERDICT_MARK_COLOR
    from acq.ui.report_panel import SessionFigure
    from acq.ui.report_view import ReportView
    from bench.scenarios import THIRD_INSIDE, Scenario, clock_for, record

    path, _ = record(Scenario("third mass 150 Hz", sim=THIRD_INSIDE, profile={"speed_dither": dither}), 0,
                     *clock_for(0, 7), tmp_path)
    done = analyze_session(path)
    quality = done.result.quality
    assert quality.verdict == "poor"
    if kind == "misfit":
        low, high = quality.misfit_band_hz
        assert quality.third_mode_hz is None and 160 <= low < high <= 200
        named, label = f"between {low:.0f} and {high:.0f} Hz", f"misfit {low:.0f}–{high:.0f} Hz"
    else:
        low = high = quality.third_mode_hz
        assert quality.misfit_band_hz is None and 160 <= low <= 200
        named, label = f"misses a third mode near {low:.0f} Hz", f"third mode ≈ {low:.0f} Hz"
    assert any(named in r for r in quality.reasons), quality.reasons  # the mark is where the reason says

    fd = done.result.figures
    if kind == "misfit":  # the picture shows what the text says: the test's window that "misses by +x %", beyond the
        # allowance the test held it to, in the misfit panel's range (on the log |H| axis, 6 % was not to be seen)
        (said,) = [float(m.group(1)) for r in quality.reasons if (m := re.search(r"misses by ([+-][0-9.]+) %", r))]
        windows = fd.misfit_windows[(fd.misfit_windows[:, 0] >= low) & (fd.misfit_windows[:, 1] <= high)]
        (worst,) = [w for w in windows if round(100 * w[2], 1) == said]
        assert abs(worst[2]) > worst[3]
    ensure_app()
    view = ReportView([SessionFigure("s", fd, done.json_dict)])
    if kind == "misfit":
        assert view.plots["misfit"].viewRange()[1][1] > 100 * np.expm1(worst[2])
    for plot in ("frf", "misfit", "phase"):
        (mark,) = [i for i in view.plots[plot].items if getattr(i, "objectName", str)() == kind]
        if kind == "misfit":
            assert isinstance(mark, pg.LinearRegionItem)
            assert mark.getRegion() == pytest.approx((np.log10(low), np.log10(high)), abs=1e-12)
        else:
            assert isinstance(mark, pg.InfiniteLine) and mark.value() == pytest.approx(np.log10(low), abs=1e-12)
    assert [t.toPlainText() for t in view.mark_labels][2:] == [label]  # after f_a and f_r

    def marked_pixels(png: Path) -> int:  # pixels of the mark's colour (its label and edges)
        mark = np.array([int(VERDICT_MARK_COLOR[i:i + 2], 16) for i in (1, 3, 5)])
        return int(np.sum(np.abs(_pixels(png)[..., ::-1].astype(int) - mark).sum(axis=-1) < 40))

    assert draw_report(done).report_path == path.with_name(path.stem + ".report.png")
    from acq.ui.report_view import render_report_png

    unmarked = tmp_path / "unmarked.png"
    render_report_png(replace(done.result.figures, misfit_band_hz=(np.nan, np.nan), third_mode_hz=np.nan), unmarked,
                      values=done.json_dict)
    assert marked_pixels(unmarked) == 0 and marked_pixels(path.with_name(path.stem + ".report.png")) > 100
