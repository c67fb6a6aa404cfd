"""The report PNG of an identification (``<session>.report.png``), drawn once its result and catalogue row stand.

Two ways to draw it, one drawing (:func:`acq.ui.report_view.render_report_png`, written atomically):

* :func:`draw_report` in this process: ``acq analyze`` at a terminal, ``acq record``, the batch workers;
* :func:`draw_report_detached` in a background process (``python -m acq.ui.report_png JOB``) started after
  ``acq analyze --json`` has printed its result, so a script reading the numbers does not wait for Qt
  (≈ 0.3 s to import, ≈ 0.3 s to draw). The background drawers of a user take turns (one lock in the temp
  folder): a loop of 100 analyses runs one Qt process at a time, the others wait before loading anything
  heavy. A drawer draws only while ``<session>.result.json`` still holds the result it was started for (a
  newer analysis of the session draws its own picture; a removed folder is left alone). A drawing that
  fails is a note in the ``.result.json`` (as in this process) and a line in ``<session>.report.log``,
  which also catches what a crash of Qt writes; the log is removed when the picture is drawn.
"""

from __future__ import annotations

import faulthandler
import io
import json
import os
import subprocess
import sys
import tempfile
import threading
from dataclasses import dataclass, fields
from pathlib import Path
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from acq.process_signals import signals_deferred
from acq.recording.storage import atomic_path, remove_temp_files
from acqcore.errors import StorageError

if TYPE_CHECKING:
    from acq.offline.analyze import SessionResult
    from analysis import FigureData

#: A background drawer that has not finished after this long is stopped (its stack goes to the log), so a hung Qt
#: cannot hold the drawers' lock for ever. A drawing takes ≈ 0.6 s CPU whatever the session's length (the traces
#: are decimated); 120 s leaves room for a machine loaded 100× over.
DRAW_TIMEOUT_S = 120.0


def report_log_path(report_path: Path) -> Path:
    """``<session>.report.log``: where a background drawer writes why a picture was not drawn."""
    return report_path.with_suffix(".log")


def drawers_lock_path() -> Path:
    """The lock the background drawers of this user take turns on (in the temp folder: ``TMPDIR`` moves it)."""
    return Path(tempfile.gettempdir()) / f"acq-report-drawers-{os.getuid()}.lock"


def _title(done: SessionResult) -> str:
    return f"{done.session.meta.joint} · {done.session.path.name}"


def _not_drawn_line(report_path: Path, why: str, json_path: Path) -> str:
    return f"acq: {report_path}: report not drawn ({why}); the result stands in {json_path}\n"


class _Superseded(Exception):
    """A newer analysis replaced the result while its picture was drawn: the picture is not put in place."""


def _render(figures: FigureData, values: dict[str, Any], title: str, report_path: Path,
            still_current: Callable[[], bool] = lambda: True) -> str | None:
    """Draw ``report_path`` (atomically, and only if ``still_current()`` holds when the picture is ready); None when
    drawn or superseded, else why not. A write that failed raises :class:`StorageError` (disk full, I/O error: a
    failure, named by the file)."""
    try:
        with atomic_path(report_path) as tmp_png:
            # Ctrl-C / SIGTERM wait for Qt to return (then a KeyboardInterrupt here, the temp picture removed): raised
            # inside a Qt virtual (paintEvent) it unwound through C++ frames — a segfault, or a traceback and lost;
            # inside Qt's import, a fatal error of shiboken's start-up
            with signals_deferred():
                from acq.ui.report_view import render_report_png  # Qt only when a picture is drawn

                render_report_png(figures, tmp_png, values=values, title=title)
            if not still_current():  # drawing takes ≈ 0.6 s: a newer result (or --no-report) may have come meanwhile
                raise _Superseded
    except _Superseded:
        return None
    except StorageError:
        raise
    except Exception as e:  # noqa: BLE001 — whatever the plotting stack does, the identification stands
        return f"{type(e).__name__}: {e}"
    report_log_path(report_path).unlink(missing_ok=True)  # an earlier failure's log is moot once the picture is there
    return None


def draw_report(done: SessionResult) -> SessionResult:
    """Draw ``<session>.report.png`` of an identification already written (nothing when no report was asked for).

    A picture that fails is not a failed identification: the failure becomes a note on the result
    (:func:`acq.offline.analyze.report_not_drawn`) and one line on stderr; the returned result then has no report
    path.
    """
    if done.report_path is None:
        return done
    why = _render(done.result.figures, done.json_dict, _title(done), done.report_path)
    if why is None:
        return done
    from acq.offline.analyze import report_not_drawn

    sys.stderr.write(_not_drawn_line(done.report_path, why, done.json_path))
    return report_not_drawn(done, why)


@dataclass(frozen=True)
class _Job:
    """What a background drawer draws: the figure data, the result document as written, where the files are."""

    figures: FigureData
    result_text: str
    title: str
    report_path: Path
    json_path: Path

    def is_current(self) -> bool:
        """The ``.result.json`` still holds this job's result (not a newer analysis's, not removed)."""
        try:
            return self.json_path.read_text(encoding="utf-8") == self.result_text
        except OSError:
            return False


_JOB_TEXTS = ("result_text", "title", "report_path", "json_path")


def _write_job(done: SessionResult, report_path: Path) -> Path:
    """The job file of a background drawer: a hidden ``.npz`` beside the report (no pickle: plain arrays and
    texts), removed by the drawer as it reads it — or with the folder."""
    import numpy as np

    from acq.offline.analyze import result_text

    figures = done.result.figures
    arrays = {f.name: np.asarray(getattr(figures, f.name)) for f in fields(figures)}
    texts = (result_text(done.json_dict), _title(done), str(report_path), str(done.json_path))
    arrays.update({name: np.asarray(text) for name, text in zip(_JOB_TEXTS, texts)})
    fd, name = tempfile.mkstemp(dir=report_path.parent, prefix=f".{report_path.name}.", suffix=".job.npz")
    try:
        with os.fdopen(fd, "wb") as f:
            np.savez(f, **arrays)
    except BaseException:
        Path(name).unlink(missing_ok=True)
        raise
    return Path(name)


def _read_job(data: bytes) -> _Job:
    import numpy as np

    from analysis import FigureData

    with np.load(io.BytesIO(data), allow_pickle=False) as npz:
        values = {name: npz[name] for name in npz.files}
    scalars = {f.name: values[f.name].item() for f in fields(FigureData) if values[f.name].ndim == 0}
    arrays = {f.name: values[f.name] for f in fields(FigureData) if values[f.name].ndim > 0}
    for name in ("band_hz", "misfit_band_hz"):
        arrays[name] = tuple(float(v) for v in arrays[name])
    texts = [str(values[name]) for name in _JOB_TEXTS]
    return _Job(FigureData(**scalars, **arrays), texts[0], texts[1], Path(texts[2]), Path(texts[3]))


def draw_report_detached(done: SessionResult) -> None:
    """Draw ``<session>.report.png`` in a background process and return at once (nothing when no report was asked
    for). The drawer outlives this process (its own session: a closed terminal does not stop it) and holds none of
    its streams, so a caller reading this process's output to its end does not wait for the picture either.

    When no process can be started, or its job not written, the picture is drawn here (:func:`draw_report`).
    """
    if done.report_path is None:
        return
    report_path = done.report_path
    try:
        job = _write_job(done, report_path)
    except OSError:
        draw_report(done)  # a write that fails here fails there too, named by the picture
        return
    log = report_log_path(report_path)
    try:
        with log.open("ab") as log_file:
            # -P: the caller's working folder is not searched for modules (a folder named 'analysis' there is data)
            subprocess.Popen([sys.executable, "-P", "-m", "acq.ui.report_png", str(job)], stdin=subprocess.DEVNULL,
                             stdout=subprocess.DEVNULL, stderr=log_file, start_new_session=True)
    except OSError:  # no process (fork limit, memory), or no log: draw here
        job.unlink(missing_ok=True)
        _remove_if_empty(log)
        draw_report(done)


def _remove_if_empty(path: Path) -> None:
    try:
        if path.stat().st_size == 0:
            path.unlink()
    except OSError:
        pass  # gone already


class _DrawersLock:
    """Exclusive ``flock`` on :func:`drawers_lock_path`, waited for (released by the kernel if a drawer dies). The
    file is not followed if it is a link (the temp folder is shared with other users)."""

    def __enter__(self) -> _DrawersLock:
        import fcntl

        path = drawers_lock_path()
        try:
            self._fd: int | None = os.open(path, os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW, 0o600)
        except OSError as e:  # e.g. another user made a file of that name: the turns are a courtesy, not a need
            sys.stderr.write(f"acq: {path}: not usable ({e.strerror}); drawing without waiting for other drawers\n")
            self._fd = None
            return self
        fcntl.flock(self._fd, fcntl.LOCK_EX)
        return self

    def __exit__(self, *exc: object) -> None:
        if self._fd is not None:
            os.close(self._fd)


def run_job(job_path: Path) -> None:
    """The background drawer: read and remove the job, wait for its turn, draw if the result is still this job's.

    A failure is a note in the ``.result.json`` and a line on stderr (``<session>.report.log``); this process has
    no caller to raise to.
    """
    faulthandler.enable()  # a crash of Qt leaves its traceback in the log
    try:
        data = job_path.read_bytes()
    except FileNotFoundError:
        return  # the folder was removed: nothing to draw for
    job_path.unlink(missing_ok=True)
    with _DrawersLock():
        job = _read_job(data)
        remove_temp_files(job.report_path)  # a drawer stopped by its timeout leaves its temp picture
        timer = threading.Timer(DRAW_TIMEOUT_S, _give_up, (job,))
        timer.daemon = True
        timer.start()
        # the last resort if Qt hangs holding the interpreter's lock (the timer then cannot run): no Python needed
        faulthandler.dump_traceback_later(DRAW_TIMEOUT_S + 10.0, exit=True)
        try:
            _draw_job(job)
        finally:
            timer.cancel()
            faulthandler.cancel_dump_traceback_later()


def _give_up(job: _Job) -> None:
    """Stop a drawer that hangs: its stack, the line and the note of a picture not drawn, no temp file."""
    faulthandler.dump_traceback(all_threads=True)
    _not_drawn(job, f"stopped after {DRAW_TIMEOUT_S:g} s without a picture")
    remove_temp_files(job.report_path)
    os._exit(1)  # the main thread is stuck in the plotting stack: no orderly exit reaches it


def _draw_job(job: _Job) -> None:
    """Draw ``job``'s picture if its result is still the session's; a failure: a line on stderr, a note in the result."""
    if not job.is_current():  # a newer analysis draws its own picture
        _remove_if_empty(report_log_path(job.report_path))
        return
    try:
        why = _render(job.figures, json.loads(job.result_text), job.title, job.report_path, job.is_current)
    except StorageError as e:
        why = str(e)
    if why is None:
        _remove_if_empty(report_log_path(job.report_path))  # drawn (its log is gone) or superseded meanwhile
        return
    _not_drawn(job, why)


def _not_drawn(job: _Job, why: str) -> None:
    """The line on stderr (the log) and the note in the result of a picture not drawn (never over a newer result)."""
    sys.stderr.write(_not_drawn_line(job.report_path, why, job.json_path))
    sys.stderr.flush()
    if job.is_current():  # never over a newer analysis's result
        from acq.offline.analyze import write_report_note

        try:
            write_report_note(json.loads(job.result_text), job.json_path, why)
        except StorageError as e:
            sys.stderr.write(f"acq: {e}\n")


if __name__ == "__main__":
    run_job(Path(sys.argv[1]))
