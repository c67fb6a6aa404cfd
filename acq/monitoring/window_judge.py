"""One monitor window judged and analysed (runs in a worker process): excited or not, and why.

Before the analysis the joint's travel decides (less than half an electrical revolution cannot be analysed
at all); after it the analysis' segment selection (fewer than two Welch segments whose torque explains their
speed beyond chance: :mod:`analysis.segments`) and the verdict's own excitation checks (coherence between f_a
and f_r, and in the band, against :class:`analysis.verdict_limits.Thresholds`). A window that does not excite gets a
catalogue record with verdict ``not excited`` and why, without K, J or C: never a number, and without the
analysis' advice on the hardware (interference, play: it judged a fit of data that carries no excitation).
"""

from __future__ import annotations

import multiprocessing
import signal
from dataclasses import replace
from pathlib import Path
from typing import Any

from acq.monitoring.catalogue import Outcome
from acq.monitoring.session_outcome import analyze_one, session_meta
from acq.offline.analyze import idle_reason, output_paths, write_json
from acq.recording.reader import load
from acqcore.errors import StorageError
from analysis import AnalysisRequest, Thresholds, against_limit, excitation_summary, segments_summary


def _weak_coherence(quality: dict[str, Any]) -> str | None:
    """Which excitation check of the verdict's own "poor" limits (:class:`analysis.verdict_limits.Thresholds`) fails:
    coherence between f_a and f_r, else in the whole band — its words, "" when no coherence was measured at all,
    None when both hold."""
    th = Thresholds()
    exc, mean = quality.get("excitation_coherence"), quality.get("mean_coherence")
    if exc is not None and not exc >= th.excitation_poor:
        return (f"too little between f_a and f_r (coherence {against_limit(exc, th.excitation_poor)}, "
                f"below {th.excitation_poor:g})")
    if mean is None:
        return ""
    if not mean >= th.coherence_poor:
        return (f"too little over the band (mean coherence {against_limit(mean, th.coherence_poor)}, "
                f"below {th.coherence_poor:g})")
    return None


def _unselected(doc: dict[str, Any]) -> bool:
    """True when the analysis' segment selection found fewer than two segments that excite (it then used them all)."""
    excitation = doc.get("excitation")
    return excitation is not None and not excitation["selection_applied"]


def not_excited(doc: dict[str, Any]) -> bool:
    """True when a verdict that is not ok comes from a lack of excitation, with clocks that were aligned at all.

    Either the segment selection found fewer than two segments that excite (:func:`_unselected`: the motion itself
    says so, whatever the clock residual — a residual above the limit is then what little motion there was to align
    on), or the excitation checks fail (:func:`_weak_coherence`) with the residual within the amplitude fit's limit.
    A failed alignment keeps the analysis' own verdict and reasons, the clock's first: it makes the coherence low
    too, but says nothing about the motion; so does a high residual on a window whose segments do excite."""
    quality, clock = doc["quality"], doc.get("clock", {})
    if quality.get("verdict") == "ok" or clock.get("failure"):
        return False
    residual = clock.get("residual_s")
    aligned = residual is None or residual <= Thresholds().clock_residual_amplitude_s
    return _unselected(doc) or (aligned and _weak_coherence(quality) is not None)


def _but(doc: dict[str, Any], excited_moves: int) -> str:
    """Why moves that excite the band still leave the window unexcited: the coherence check that failed."""
    weakness = _weak_coherence(doc["quality"]) if excited_moves else None
    return f", but {weakness}" if weakness else ""


def marked(path: str, sha256: str, request: AnalysisRequest, meta: dict[str, Any], verdict: str, reasons: list[str],
           doc: dict[str, Any] | None = None) -> Outcome:
    """A window's catalogue record without numbers: verdict ``not excited`` / ``not analysed`` / ``interrupted``."""
    keep = {k: v for k, v in (doc or {}).items() if k in ("session", "analyzed_utc", "acq_version", "simulated_truth",
                                                          "clock", "options", "excitation")}
    quality = {k: v for k, v in (doc or {}).get("quality", {}).items() if k.endswith("coherence")}
    out = {"options": request.to_json_dict(), **keep, "quality": {**quality, "verdict": verdict, "reasons": reasons}}
    return Outcome(path, sha256, request.key(), meta, out, None, 0.0)


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
    if outcome.doc is not None and not_excited(outcome.doc):
        outcome = replace(marked(path, sha256, request, outcome.session, "not excited",
                                 not_excited_reasons(outcome.doc), outcome.doc), seconds=outcome.seconds)
    return _write_result(Path(path), request, outcome)


def not_excited_reasons(doc: dict[str, Any]) -> list[str]:
    """Why a window does not excite: the moves that excite and the coherence that fell short, or how many Welch
    segments the selection examined and why too few excite (the analysis' figures: :func:`segments_summary`), then
    the clock's finding (a fact, not advice). The analysis' other reasons are left out: their advice (interference on
    the phase current, play in the gear, the intervals of a K not shown) judges a fit of data without excitation."""
    clock = [r for r in doc["quality"]["reasons"] if r.startswith("clock")]
    excitation = doc.get("excitation")
    if excitation is None:  # no segment selection asked for: the coherence checks' own words
        return [f"the torque does not excite the speed: {_weak_coherence(doc['quality']) or 'no coherence measured'}",
                *clock]
    moves = excitation["moves"]
    lo, hi = doc["options"]["band_hz"]
    excited = sum(m["excited"] for m in moves)
    segments = [] if excitation["selection_applied"] else [selection_reason(excitation)]
    return [excitation_summary(excited, len(moves), (lo, hi), excitation["excited_fraction"], "window")
            + _but(doc, excited), *segments, *clock]


def selection_reason(excitation: dict[str, Any]) -> str:
    """How many Welch segments the analysis' segment selection examined and why too few excite, in its words
    (:func:`analysis.segments_summary`), from the figures of a result's ``excitation``."""
    return segments_summary(excitation["segments_excited"], excitation["segments"], excitation["segments_needed"],
                            excitation["snr_limit"], excitation["snr_max"])


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
