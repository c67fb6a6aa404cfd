"""One session's analysis as the catalogue's :class:`~acq.monitoring.catalogue.Outcome`: run in a worker, where it
never raises (:func:`analyze_one`), or recorded after a one-session ``acq analyze`` (:func:`record_outcome`)."""

from __future__ import annotations

import time
import warnings
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np

from acq.monitoring.catalogue import Catalogue, Outcome
from acq.offline.analyze import SessionResult, analyze_session
from acq.recording.reader import load
from acq.recording.session import Session
from acqcore.errors import AcqError
from analysis import AnalysisRequest

CATALOGUE_NAME = "catalogue.sqlite"

#: Draws a written result's report PNG and returns the result (with a note if the picture failed), e.g.
#: :func:`acq.ui.report_png.draw_report`; a module-level function, so it reaches the workers by name.
DrawReport = Callable[[SessionResult], SessionResult]


def record_outcome(done: SessionResult, catalogue_path: Path | str | None, seconds: float) -> Path | str:
    """Put one session's analysis (done outside a batch) into its catalogue; return the catalogue's path.

    The catalogue is ``catalogue_path`` or ``catalogue.sqlite`` in the folder of the result (the session's, or
    ``--result-dir``), so a later ``acq analyze FOLDER`` finds the session current and ``acq trend`` sees it at once.
    """
    path = catalogue_path or done.json_path.parent / CATALOGUE_NAME
    with Catalogue(path) as catalogue:
        catalogue.record(succeeded(str(done.session.path), done, seconds))
    return path


def succeeded(path: str, done: SessionResult, seconds: float) -> Outcome:
    """The catalogue's record of a successful analysis of the session at ``path``, filed under the request it
    answered (an option that named the default left to it: :meth:`analysis.AnalysisRequest.as_default_where_it_is`)."""
    return Outcome(path, done.json_dict["session"]["sha256"], done.request.key(), session_meta(done.session),
                   done.json_dict, None, seconds)


def session_meta(session: Session) -> dict[str, Any]:
    """What the catalogue keeps of a session's root attributes."""
    meta = session.meta
    return {"session_id": meta.session_id, "joint": meta.joint, "created_utc": meta.created_utc,
            "start_monotonic_ns": meta.host_ns_at_start or 0, "status": meta.status, "tags": meta.tags}


@contextmanager
def quiet_numerics() -> Iterator[None]:
    """No numpy floating-point warning (divide by zero, invalid value, overflow) reaches the person: the analysis
    reports unusable data through its errors and verdict, and a warning line before them only confuses."""
    with np.errstate(all="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        yield


def analyze_one(path: str, sha256: str, request: AnalysisRequest, draw_report: DrawReport | None = None, *,
                write: bool = True, result_dir: Path | None = None) -> Outcome:
    """Analyse one session (runs in a worker process or on a Dask worker); never raises.

    Parameters
    ----------
    path : str
        Absolute path of the session file, as the worker sees it.
    sha256 : str
        The file's hash when the batch looked at it (kept when the analysis fails).
    request : AnalysisRequest
        What is asked, as filed for this session (:func:`acq.offline.analyze.filed_request`): its key files the
        outcome in the catalogue, a failure too.
    draw_report : callable, optional
        Draws ``<session>.report.png`` once the result is written (None: no report).
    write : bool, optional
        Write ``<session>.result.json`` (False: the caller writes the document it makes of the outcome).
    result_dir : Path, optional
        Where the result and report go (None: beside the session).
    """
    start = time.perf_counter()
    try:
        with quiet_numerics():
            done = analyze_session(path, request, write=write, report=draw_report is not None, result_dir=result_dir)
    except Exception as e:  # noqa: BLE001 — a batch records any session's failure and goes on
        error = str(e) if isinstance(e, AcqError) else f"{path}: {type(e).__name__}: {e}"
        return Outcome(path, sha256, request.key(), _meta_if_readable(path), None, error,
                       time.perf_counter() - start)
    if draw_report is not None:
        done = draw_report(done)  # the result is written; a picture that fails is a note on it, not a failure
    return succeeded(path, done, time.perf_counter() - start)


def _meta_if_readable(path: str) -> dict[str, Any]:
    try:
        return session_meta(load(path))
    except (AcqError, OSError, KeyError, ValueError):
        return {}
