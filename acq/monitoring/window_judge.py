"""One monitor window judged and analysed (runs in a worker process): excited or not, and why.

Before the analysis the joint's travel decides (less than half an electrical revolution cannot be analysed
at all); after it the analysis of :func:`acq.offline.analyze.analyze_session` judges it as it judges any record acq
did not command (:mod:`acq.offline.excitation_judge`: the segment selection and the verdict's excitation checks), so
``acq analyze`` of the window later gives the same verdict, reasons and (absent) K. A window that does not excite gets
a catalogue record with verdict ``not excited`` and why, without K, J or C: never a number.
"""

from __future__ import annotations

import multiprocessing
import signal
from dataclasses import replace
from pathlib import Path
from typing import Any

from acq.monitoring.catalogue import Outcome
from acq.monitoring.session_outcome import analyze_one, session_meta
from acq.offline.analyze import idle_reason, output_paths, sha256_of, write_json
from acq.offline.excitation_judge import without_numbers
from acq.recording.reader import load
from acqcore.errors import StorageError
from analysis import AnalysisRequest


def marked(path: str, sha256: str, request: AnalysisRequest, meta: dict[str, Any], verdict: str,
           reasons: list[str]) -> Outcome:
    """A window's catalogue record without numbers: verdict ``not excited`` / ``not analysed`` / ``interrupted``."""
    return Outcome(path, sha256, request.key(), meta, without_numbers({}, request.to_json_dict(), verdict, reasons),
                   None, 0.0)


def marked_file(path: Path, request: AnalysisRequest, verdict: str, reason: str) -> Outcome:
    """:func:`marked` for the window file ``path`` (the monitor's marks: ``interrupted``, ``not analysed``): its
    session's root attributes ({} for a window too broken to read, still marked) and its SHA-256."""
    try:
        meta = session_meta(load(path))
    except Exception:  # noqa: BLE001 - a window too broken to read is still marked
        meta = {}
    return marked(str(path.resolve()), sha256_of(path), request, meta, verdict, [reason])


def analyse_window(path: str, sha256: str, request: AnalysisRequest) -> Outcome:
    """Judge and analyse one window (runs in a worker process); never raises."""
    if multiprocessing.parent_process() is not None:  # a worker: Ctrl-C in the terminal is the monitor's to handle
        signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        session = load(path)
        idle = idle_reason(session)
        if idle is not None:
            return marked(path, sha256, request, session_meta(session), "not excited", [idle])
    except Exception:  # noqa: BLE001 - analyze_one below records why the file cannot be read
        pass
    outcome = analyze_one(path, sha256, request, write=False)  # no report PNG; the result is written once, below
    return _write_result(Path(path), request, outcome)


def _write_result(path: Path, request: AnalysisRequest, outcome: Outcome) -> Outcome:
    """Write the window's ``.result.json`` as the catalogue has it (a window judged not excited: without numbers,
    so the file beside the window does not show a K the monitor refused) and remove an earlier report PNG (the
    monitor draws none: one of an earlier result would be taken for it). A failed write is the outcome's error."""
    if outcome.doc is None:
        return outcome
    json_path, png_path = output_paths(path, request)
    try:
        write_json(outcome.doc, json_path)
    except StorageError as e:
        return replace(outcome, doc=None, error=str(e))
    png_path.unlink(missing_ok=True)
    return outcome
