"""Whether a record acq did not command excited the joint: one judgement for a monitor's window and ``acq analyze``.

A monitor's window, a passive recording or an import without a profile is the machine's own motion. After its
analysis the segment selection (fewer than two Welch segments whose torque explains their speed beyond chance:
:mod:`analysis.segments`) and the verdict's own excitation checks (coherence between f_a and f_r, and in the band,
against :class:`analysis.verdict_limits.Thresholds`) decide whether it excited the joint at all; one that did not gets the
verdict ``not excited`` and why, without K, J or C (never a number) and without the analysis' advice on the hardware
(interference, play: it judged a fit of data that carries no excitation), with its notes. A fault the analysis found
in the data (``quality.faults``: a wrong bench constant, a swapped phase, the drive at its limit) keeps the analysis'
verdict: the fault, not the motion, may be why the coherence is weak. :func:`acq.offline.analyze.analyze_session`
applies it, so the monitor (:mod:`acq.monitoring.window_judge`) and a later ``acq analyze`` of the same window file
the same verdict, reasons and (absent) K.
"""

from __future__ import annotations

from typing import Any

from analysis import UNBRACKETED_NOTE_START, Thresholds, against_limit, excitation_summary, segments_summary

#: What a document without numbers keeps of the analysis' document: what identifies the session and how it was
#: analysed, the clock's relation, and the segment selection's figures (the monitor's status and table show them).
KEPT_KEYS = ("session", "analyzed_utc", "acq_version", "analysis_fingerprint", "simulated_truth", "clock", "options",
             "excitation", "partial")


def weak_coherence(quality: dict[str, Any]) -> str | None:
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
    """True when a verdict that is not ok comes from a lack of excitation, with clocks that were aligned at all, and
    the analysis found no fault in the data (``quality.faults``: a wrong bench constant or phase sequence, the drive
    holding a limit — each garbles the torque, so the coherence is weak
    whatever the motion: the verdict stays the analysis', the fault and its advice its reason).

    Either the segment selection found fewer than two segments that excite (:func:`_unselected`: the motion itself
    says so, whatever the clock residual — a residual above the limit is then what little motion there was to align
    on), or the excitation checks fail (:func:`weak_coherence`) with the residual within the amplitude fit's limit.
    A failed alignment keeps the analysis' own verdict and reasons, the clock's first: it makes the coherence low
    too, but says nothing about the motion; so does a high residual on a window whose segments do excite."""
    quality, clock = doc["quality"], doc.get("clock", {})
    if quality.get("verdict") in ("ok", "not excited") or clock.get("failure") or quality.get("faults"):
        return False
    residual = clock.get("residual_s")
    aligned = residual is None or residual <= Thresholds().clock_residual_amplitude_s
    return _unselected(doc) or (aligned and weak_coherence(quality) is not None)


def _but(doc: dict[str, Any], excited_moves: int) -> str:
    """Why moves that excite the band still leave the record unexcited: the coherence check that failed."""
    weakness = weak_coherence(doc["quality"]) if excited_moves else None
    return f", but {weakness}" if weakness else ""


def not_excited_reasons(doc: dict[str, Any]) -> list[str]:
    """Why a record does not excite: the moves that excite and the coherence that fell short, or how many Welch
    segments the selection examined and why too few excite (the analysis' figures: :func:`segments_summary`), then
    the clock's finding (a fact, not advice). The analysis' other reasons are left out: their advice (interference on
    the phase current, play in the gear, the intervals of a K not shown) judges a fit of data without excitation."""
    clock = [r for r in doc["quality"]["reasons"] if r.startswith("clock")]
    excitation = doc.get("excitation")
    if excitation is None:  # no segment selection asked for: the coherence checks' own words
        return [f"the torque does not excite the speed: {weak_coherence(doc['quality']) or 'no coherence measured'}",
                *clock]
    moves = excitation["moves"]
    lo, hi = doc["options"]["band_hz"]
    excited = sum(m["excited"] for m in moves)
    where = "window" if "monitor_window" in doc.get("session", {}).get("tags", {}) else "record"
    segments = [] if excitation["selection_applied"] else [selection_reason(excitation)]
    return [excitation_summary(excited, len(moves), (lo, hi), excitation["excited_fraction"], where)
            + _but(doc, excited), *segments, *clock]


def selection_reason(excitation: dict[str, Any]) -> str:
    """How many Welch segments the analysis' segment selection examined and why too few excite, in its words
    (:func:`analysis.segments_summary`), from the figures of a result's ``excitation``."""
    return segments_summary(excitation["segments_excited"], excitation["segments"], excitation["segments_needed"],
                            excitation["snr_limit"], excitation["snr_max"])


def without_numbers(doc: dict[str, Any], options: dict[str, Any], verdict: str, reasons: list[str]) -> dict[str, Any]:
    """A result document with ``verdict`` and ``reasons`` and no K, J, C or intervals: of ``doc`` it keeps
    :data:`KEPT_KEYS` and the coherences (``options``: the request's, where ``doc`` names none)."""
    keep = {k: v for k, v in doc.items() if k in KEPT_KEYS}
    quality = {k: v for k, v in doc.get("quality", {}).items() if k.endswith("coherence")}
    return {"options": options, **keep, "quality": {**quality, "verdict": verdict, "reasons": reasons}}


def judged(doc: dict[str, Any]) -> dict[str, Any]:
    """``doc``, an analysis' result document of a record acq did not command, as it is filed: unchanged when the
    joint was excited; else without numbers, verdict ``not excited`` with :func:`not_excited_reasons` and then the
    analysis' notes (``note: …``: what the signal chain did — the span used, an offset removed — facts, not advice;
    not the one on the intervals it no longer gives, :data:`analysis.UNBRACKETED_NOTE_START`)."""
    if not not_excited(doc):
        return doc
    notes = [r for r in doc["quality"]["reasons"]
             if r.startswith("note: ") and not r.startswith(f"note: {UNBRACKETED_NOTE_START}")]
    return without_numbers(doc, doc["options"], "not excited", [*not_excited_reasons(doc), *notes])
