"""``acq view SESSION [SESSION…] [--screenshot out.png]``: the report window of one or several sessions.

Each session is identified through :func:`acq.offline.analyze.analyze_session` (nothing written beside it);
when ``<session>.result.json`` exists, its options are used, so the window shows what ``acq analyze``
found (the JSON holds the values, not the curves, hence the re-run: ≲ 3 s for a 60 s session).
Several sessions overlay their FRFs with a legend (e.g. the same joint months apart).

Qt is imported only when a window or a screenshot is drawn, so the rest of the CLI starts fast. Closing the window
exits 0; Ctrl-C or SIGTERM close it too, with exit 130 and one line (:mod:`acq.ui.qt_signals`).
"""

from __future__ import annotations

import functools
import json
import os
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING

import click

from acq.ui.options import CatalogueLocation, PngPath, require_folder
from acq.offline.analyze import analyze_session
from acq.recording.paths import require_session_file
from acqcore.errors import EXIT_INTERRUPTED, AcqError, ConfigError
from analysis import AnalysisRequest

if TYPE_CHECKING:
    from acq.ui.report_panel import SessionFigure
    from acq.monitoring.trend import Trend
    from acq.monitoring.trend_catalogue import NoSessions

#: ``acq view`` without a display (bad input, exit 2, as ``acq record --live``): the form that draws it into a PNG.
NO_DISPLAY_MESSAGE = ("no display (DISPLAY and WAYLAND_DISPLAY are unset) — save the window as an image instead: "
                      "acq view {form} --screenshot out.png")


def has_display() -> bool:
    """True when Qt can show a window: an X11 or Wayland display, or Qt's offscreen platform chosen."""
    return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")
                or os.environ.get("QT_QPA_PLATFORM", "").startswith("offscreen"))


def stored_request(path: Path) -> AnalysisRequest:
    """The analysis request recorded in ``<session>.result.json`` (the default request if there is none)."""
    result_path = path.with_name(path.stem + ".result.json")
    if not result_path.exists():
        return AnalysisRequest()
    try:
        return AnalysisRequest.from_json_dict(json.loads(result_path.read_text())["options"])
    except (ValueError, KeyError, TypeError, AttributeError):
        raise ConfigError(f"{result_path}: not a result of acq analyze (run acq analyze {path} to redo it)") from None


def session_figure(path: Path) -> SessionFigure:
    """Identify one session (with its stored options, if any) and wrap what the figure needs."""
    from acq.ui.report_panel import SessionFigure

    done = analyze_session(path, stored_request(Path(path)), write=False)
    if done.result is None:  # the machine did not excite the joint: nothing to draw, the verdict says why
        reasons = [r for r in done.json_dict["quality"]["reasons"] if not r.startswith("note: ")]
        raise ConfigError(f"{path}: not excited: {'; '.join(reasons)}")
    return SessionFigure(Path(path).stem, done.result.figures, done.json_dict)


def refuse_unawaited_catalogue(folder: Path | None, catalogue: Path | str | None) -> None:
    """Raise the :class:`~acq.monitoring.trend_catalogue.NoSessions` of ``acq view --trend`` for a catalogue no monitor
    is to make (``…/catalogue.sqlite: no catalogue — the folder … does not exist``); nothing for one that is there
    or may still come."""
    from acq.monitoring.trend_catalogue import NoSessions, catalogue_location

    try:
        catalogue_location(folder, catalogue)
    except NoSessions as e:
        if not e.awaited:
            raise


#: Smallest side of ``--size``, px, refused before anything loads: the floor acq view has had since its first version; a
#: smaller size is a typo. The report needs more (one session 921×446 px): :func:`fitting_size` says how much once its
#: sessions are drawn.
MIN_SIDE_PX = 200
#: Largest ``--size`` in pixels (width × height): 8192 × 8192 at 4 bytes a pixel (the RGB32 image acq draws into) is
#: 256 MiB, the allocation limit of Qt's image readers (QImageReader::allocationLimit, 256 MB by default since Qt 6.0):
#: a PNG of one pixel more is refused by Qt itself ("exceeds the current allocation limit", checked with Qt 6.11). Below
#: it the offscreen drawing renders every side in full (70000×400 checked); its memory is about three such images
#: (image, window backing store, PNG encoder; peak RSS 1.0 GB at 8192², 3.3 GB at 16384², 18.9 GB at 40000²), and at
#: 99999² the image could not be allocated at all, which Qt's PNG writer reported as an I/O error.
MAX_AREA_PX = 8192 * 8192


def _parse_size(ctx: click.Context, param: click.Parameter, text: str) -> tuple[int, int]:
    """``--size WIDTHxHEIGHT`` as (width, height) px, refused in one line outside :data:`MIN_SIDE_PX` …
    :data:`MAX_AREA_PX` before anything loads."""
    try:
        width, height = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise click.BadParameter(f"{text!r}: must be WIDTHxHEIGHT in pixels, e.g. 1600x1000") from None
    if min(width, height) < MIN_SIDE_PX or width * height > MAX_AREA_PX:
        raise click.BadParameter(f"{text!r}: out of range — each side at least {MIN_SIDE_PX} px, width × height at "
                                 f"most {MAX_AREA_PX} px (8192x8192, or e.g. 16384x4096; Qt opens no larger image)")
    return width, height


def fitting_size(size: tuple[int, int], minimum: tuple[int, int], given: bool) -> tuple[int, int]:
    """The window's or screenshot's size, px: ``size`` when the report's ``minimum`` fits in it; ``--size`` left at its
    default grows to ``minimum`` (several sessions' values are taller than 1000 px); a ``size`` ``given`` smaller is
    refused in one line naming the minimum (at 1000×700 the FRF was cut off at 60 Hz)."""
    if given and (size[0] < minimum[0] or size[1] < minimum[1]):
        raise ConfigError(f"--size {size[0]}x{size[1]}: too small for this report — it needs at least "
                          f"{minimum[0]}x{minimum[1]} px (smaller, its plots and values would be cut off)")
    return max(size[0], minimum[0]), max(size[1], minimum[1])


@click.command(name="view")
@click.argument("sessions", nargs=-1, type=click.Path(path_type=Path))
@click.option("--screenshot", type=PngPath(), default=None,
              help="Draw the window offscreen into this PNG and exit (needs no display).")
@click.option("--size", default="1600x1000", show_default=True, callback=_parse_size,
              help="Window / screenshot size WIDTHxHEIGHT, px: each side 200 or more, at most 8192x8192 pixels "
                   "in all; a report refuses one smaller than it needs (one session: about 920x450), and the default "
                   "grows to it.")
@click.option("--trend", "trend_joint", default=None, metavar="JOINT",
              help="Show the stiffness trend of JOINT from the catalogue of the folder given (default sessions/).")
@click.option("--catalogue", "catalogue_path", type=CatalogueLocation(), default=None,
              help="With --trend: the catalogue, a file or postgresql:// URL (default: FOLDER/catalogue.sqlite).")
@click.option("--refresh", "refresh_s", type=click.FloatRange(0.5, 3600), default=5.0, show_default=True,
              help="With --trend: re-read the catalogue every this many s (a monitor may be writing to it).")
@click.option("--tag", "tags", multiple=True, metavar="KEY=VALUE",
              help="With --trend: only sessions with this tag (repeatable), e.g. --tag robot=r1 in a catalogue that "
                   "several monitors share.")
@click.option("--no-monitor", "no_monitor", is_flag=True,
              help="With --trend: only the sessions of no monitor (a bench's recordings, imports) where a monitor's "
                   "windows share the joint's name.")
def view_command(sessions: tuple[Path, ...], screenshot: Path | None, size: tuple[int, int],
                 trend_joint: str | None, catalogue_path: Path | str | None, refresh_s: float,
                 tags: tuple[str, ...], no_monitor: bool) -> int:
    """Show traces, FRF with the fitted model, coherence and identified values of SESSION(s);
    or, with --trend JOINT [FOLDER], the joint's stiffness over time."""
    if trend_joint is None and not sessions:
        raise click.UsageError("give one or more SESSION files, or --trend JOINT [FOLDER]")
    if trend_joint is not None and len(sessions) > 1:
        raise click.UsageError("--trend takes one FOLDER (or none for sessions/)")
    if (tags or no_monitor) and trend_joint is None:  # a session is shown whatever its tags: the filter would be lost
        raise ConfigError(f"{f'--tag {tags[0]}' if tags else '--no-monitor'}: only with --trend JOINT (it selects the "
                          "trend's sessions)")
    for path in sessions:  # a mistyped path is said first: no display is not what stops it
        if trend_joint is None:
            require_session_file(path)
        else:
            require_folder(path, catalogue_option=True)
    if screenshot is None and not has_display():
        if trend_joint is not None:  # a mistyped folder is said first
            refuse_unawaited_catalogue(sessions[0] if sessions else None, catalogue_path)
        form = "SESSION" if trend_joint is None else f"--trend {trend_joint} {sessions[0] if sessions else ''}".rstrip()
        raise ConfigError(NO_DISPLAY_MESSAGE.format(form=form))
    from acq.process_signals import signals_deferred

    with signals_deferred():  # a Ctrl-C inside Qt's import was a fatal error in shiboken's start-up (exit 134) or lost
        from acq.ui.qt_app import ensure_app, grab_png
        from acq.ui.report_view import ReportView
        from acq.ui.qt_signals import loop_ended_by_signals

    if trend_joint is not None:
        from acq.monitoring.trend_catalogue import NoSessions, load_trend

        folder = sessions[0] if sessions else None
        load = functools.partial(load_trend, folder, catalogue_path, trend_joint, tags, no_monitor)
        try:
            first: Trend | NoSessions = load()  # any other error (a bad URL, mixed monitors) is one line, no window
        except NoSessions as e:  # started before the monitor has filed its first window: the window waits for it
            # — only when the catalogue has no session yet: one with sessions, none of this joint (and tags), holds a
            # misspelt joint or tag, which was waited for for ever, as was a folder that is not there. A script's
            # picture of "waiting" with exit 0 would hide a wrong joint or folder; bad input (exit 2), as acq trend
            # says it
            if screenshot is not None or not e.awaited:
                raise
            first = e
    else:
        figures = [session_figure(p) for p in sessions]
    app = ensure_app(offscreen=screenshot is not None)
    # from here Ctrl-C / SIGTERM end the event loop (a KeyboardInterrupt raised in Qt's frames was a traceback)
    with loop_ended_by_signals(app) as caught:
        if trend_joint is not None:
            shown = " ".join([trend_joint, "tagged", *tags]) if tags else trend_joint
            live = LiveTrend(load, first, refresh_s, joint=shown)  # kept alive with the window: its timer redraws it
            if live.waiting:
                click.echo(live.waiting, err=True)
            window = live.frame
        else:
            title = (f"{figures[0].values.get('session', {}).get('joint', '')} · {sessions[0].name}"
                     if len(figures) == 1 else f"{len(figures)} sessions")
            window = ReportView(figures, title=title)
            given = click.get_current_context().get_parameter_source("size") != click.core.ParameterSource.DEFAULT
            size = fitting_size(size, window.minimum_size(), given)
        if screenshot is not None:
            grab_png(window, screenshot, size)
        else:
            window.resize(*size)
            window.show()
            click.echo(f"{window.windowTitle()}: close the window or press Ctrl-C to end")
            app.exec()
    if caught:  # also a Ctrl-C while the window was built or drawn: its handler here raises nothing (was exit 0)
        click.echo("acq: interrupted", err=True)
        return EXIT_INTERRUPTED
    if screenshot is not None:
        click.echo(f"screenshot: {screenshot} ({size[0]}×{size[1]} px)")
    return 0


class LiveTrend:
    """The trend window of ``acq view --trend``, redrawn when the catalogue has new sessions of the joint.

    ``load`` re-reads the catalogue (SQLite in WAL mode or PostgreSQL: reading does not block a monitor that
    writes); a failed re-read (the catalogue busy, a server away) keeps the figure shown and says why in the
    title. The figure itself is :func:`acq.ui.trend_plot.trend_widget`. Started before the catalogue has a
    session of the joint (``first`` is that :class:`acq.monitoring.trend_catalogue.NoSessions`: a monitor that has not filed
    its first window, or not yet made its catalogue), it says what it waits for until the first one arrives.
    ``shown`` is the trend drawn (None while waiting).
    """

    def __init__(self, load: Callable[[], Trend], first: Trend | NoSessions, refresh_s: float, *,
                 joint: str | None = None) -> None:
        from pyqtgraph.Qt import QtCore, QtWidgets

        from acq.monitoring.trend_catalogue import NoSessions
        from acq.ui.trend_plot import trend_widget

        self._load, self._draw = load, trend_widget
        self.frame = QtWidgets.QWidget()
        self._layout = QtWidgets.QVBoxLayout(self.frame)
        self.shown: Trend | None = None if isinstance(first, NoSessions) else first
        self.joint = joint or (first.joint if self.shown is not None else "")  # type: ignore[union-attr]
        if isinstance(first, NoSessions):
            self._figure = QtWidgets.QLabel(self._waiting_text(first))
            self._figure.setAlignment(QtCore.Qt.AlignmentFlag.AlignCenter)
        else:
            self._figure = trend_widget(first)
        self._layout.addWidget(self._figure)
        self.frame.setWindowTitle(f"acq trend — {self.joint}")
        self._timer = QtCore.QTimer(self.frame)
        self._timer.timeout.connect(self.refresh)
        self._timer.start(int(refresh_s * 1000))

    def refresh(self) -> bool:
        """Re-read the catalogue; redraw when the joint's sessions changed. True when redrawn."""
        from acq.monitoring.trend_catalogue import NoSessions

        try:
            trend = self._load()
        except AcqError as e:
            if self.shown is None and isinstance(e, NoSessions):  # still waiting (the joints so far may have changed)
                self._figure.setText(self._waiting_text(e))
                return False
            self.frame.setWindowTitle(f"acq trend — {self.joint} (not refreshed: {e})")
            return False
        if self.shown is not None and [p.entry for p in trend.points] == [p.entry for p in self.shown.points]:
            return False
        figure = self._draw(trend)
        self._layout.replaceWidget(self._figure, figure)
        self._figure.deleteLater()
        self._figure, self.shown = figure, trend
        self.frame.setWindowTitle(f"acq trend — {trend.joint}")
        return True

    @property
    def waiting(self) -> str | None:
        """The text shown while no session of the joint has arrived, else None."""
        return None if self.shown is not None else self._figure.text()

    def _waiting_text(self, missing: NoSessions) -> str:
        others = f" (joints so far: {', '.join(missing.joints)})" if missing.joints else ""
        return f"waiting for the first window of {self.joint} in {missing.location} …{others}"

