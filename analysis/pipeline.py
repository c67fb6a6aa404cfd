"""A raw recording → identified joint: signals → FRF → fit → quality → result (design §5).

The :class:`analysis.request.AnalysisRequest` chooses the signal chain (:mod:`analysis.chain`):
``pipeline="acq"`` is ours (clock alignment, the chosen torque estimator, anti-alias resampling,
coherence-weighted fit), ``pipeline="paper"`` is Xu et al.'s, kept for comparison: Hilbert torque,
no alignment, linear interpolation to the encoder rate, uniform weights.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from analysis.chain import SignalChain, chain_caveat
from analysis.clock_model import ClockFit
from analysis.drive_limits import drive_limit_reason
from analysis.diagnose import inertia_fault, nominal_fault, recording_diagnosis, with_fault, with_nominal_fault
from analysis.fit import (VIBRATION_DAMPING, FitInputError, FitOptions, FitResult, PARAM_NAMES, default_band_hz,
                          fit_two_mass, judged_fit)
from analysis.encoder import longest_gap_free_span
from analysis.excess_incoherence import with_excess_floor, with_excess_reason
from analysis.estimator_check import kernel_model_error, model_estimate
from analysis.fit_problem import unbracketed_note
from analysis.frf import FrequencyResponse, estimate_frf, require_two_segments, segment_layout
from analysis.input_noise import widened_c_note
from analysis.limits import band_problem
from analysis.quality import Quality, assess
from analysis.verdict_limits import phase_is_meaningful
from analysis.recording import Recording
from analysis.report import FigureData, figure_data
from analysis.request import AnalysisRequest
from analysis.segments import MIN_SEGMENTS, Move, SegmentSelection, describe_moves, excitation_summary
from analysis.signals import prepare_signals

# blocks of the delete-one-block jackknife behind the intervals: 10 gives 9 degrees of freedom
# (t = 2.26) at a cost of ten one-start refits; fewer when the record holds fewer than 20 segments
JACKKNIFE_BLOCKS = 10


@dataclass(frozen=True)
class Result:
    """An identified joint with everything needed to judge and draw it.

    Attributes
    ----------
    fit : FitResult
        Parameters, intervals, band, f_a, f_r.
    quality : Quality
        Verdict and reasons.
    clock : ClockFit
        The DAQ → drive clock relation used.
    frf : FrequencyResponse
        The measured frequency response.
    figures : FigureData
        Data of the report figures.
    request : AnalysisRequest
        The request as given.
    chain : SignalChain
        The signal chain it chose for the recording (the torque method resolved).
    notes : tuple of str
        What the signal chain reports (gaps and spans used, clock stage, torque sign).
    moves : tuple of Move
        The joint's moves and whether the selected segments cover them (with ``select_segments`` only).
    """

    fit: FitResult
    quality: Quality
    clock: ClockFit
    frf: FrequencyResponse
    figures: FigureData
    request: AnalysisRequest
    chain: SignalChain
    notes: tuple[str, ...]
    moves: tuple[Move, ...] = ()

    def to_json_dict(self) -> dict[str, Any]:
        """The result as JSON-ready values (NaN → None), keys as documented for ``--json``.

        ``quality.reasons`` lists the verdict's reasons, then the signal chain's notes prefixed
        ``"note: "``.
        """
        v, vib = self.fit.values, self.fit.vibration_damping
        return {
            **{n: _num(getattr(v, n)) for n in PARAM_NAMES},
            **({} if vib is None else {VIBRATION_DAMPING: _num(vib[0])}),
            "ci95": {**{n: [_num(lo), _num(hi)] for n, (lo, hi) in self.fit.ci95.items()},
                     **({} if vib is None else {VIBRATION_DAMPING: [_num(vib[1]), _num(vib[2])]})},
            "antiresonance_hz": _num(self.fit.f_a),
            "resonance_hz": _num(self.fit.f_r),
            "clock": {"offset_s": _num(self.clock.offset_s), "drift_ppm": _num(self.clock.drift_ppm),
                      "residual_s": _num(self.clock.residual_s), "ambiguous_by_s": list(self.clock.ambiguous_by_s),
                      "failure": self.clock.failure or None},
            "quality": {"verdict": self.quality.verdict, "mean_coherence": _num(self.quality.mean_coherence),
                        "excitation_coherence": _num(self.quality.excitation_coherence),
                        "reasons": [*self.quality.reasons, *(f"note: {n}" for n in self.notes)],
                        "faults": list(self.quality.faults),
                        "encoder_jitter_us": None if self.quality.encoder_jitter_s is None
                        else _num(1e6 * self.quality.encoder_jitter_s),
                        "encoder_time_stamps": self.quality.encoder_time_stamps},
            "options": {**self.request.to_json_dict(self.chain), "band_hz": list(self.fit.band)},
            **({} if self.frf.selection is None else {"excitation": _excitation(self.frf.selection, self.moves,
                                                                                 self.frf.unknown_torque)}),
        }


def _excitation(sel: SegmentSelection, moves: tuple[Move, ...], unknown_torque: np.ndarray | None) -> dict[str, Any]:
    """Segment selection's figures: the excited share of the record (``segments_used``: the segments that excite),
    the segments averaged (those less the ones whose torque is not known, ``unknown_torque``), which moves
    excite, and why the selection applied or not (``segments_excited`` of ``segments`` with S/N above ``snr_limit``,
    the largest ``snr_max``; ``segments_needed`` for it to apply)."""
    averaged = sel.keep if unknown_torque is None else sel.keep & ~unknown_torque
    return {"excited_fraction": sel.excited_fraction, "segments_used": int(sel.keep.sum()),
            "segments_averaged": int(averaged.sum()), "segments": int(sel.keep.size), "selection_applied": sel.applied,
            "segments_excited": sel.excited, "segments_needed": MIN_SEGMENTS, "snr_limit": sel.snr_limit,
            "snr_max": float(sel.snr.max()) if sel.snr.size else None,
            "moves": [{"index": m.index, "start_s": round(m.start_s, 4), "duration_s": round(m.duration_s, 4),
                       "peak_rad_s": round(m.peak_rad_s, 3), "excited": m.excited} for m in moves]}


def _not_excited(quality: Quality, moves: tuple[Move, ...], excited_fraction: float,
                 band_hz: tuple[float, float]) -> Quality:
    """The verdict of a record whose segment selection found fewer than two segments that excite: failed, because
    the joint was not excited — with the clock's findings (facts), without the other reasons, whose advice
    (interference on the phase current, play in the gear) judges a fit of data that carry no excitation (a passive
    10 s record of a robot at rest read K +468 % and "PWM ripple": the trial). Not applied to a record with a fault
    found in the data (:attr:`analysis.quality.Quality.faults`), which garbles the torque whatever the motion."""
    summary = excitation_summary(sum(m.excited for m in moves), len(moves), band_hz, excited_fraction)
    clock = tuple(r for r in quality.reasons if r.startswith("clock"))
    notes = tuple(r for r in quality.reasons if r.startswith("note: "))
    return replace(quality, verdict="failed", reasons=(
        f"not excited: {summary} — record while the machine runs fast moves of this joint", *clock, *notes))


def _clock_failed(quality: Quality, failure: str) -> Quality:
    """The verdict of a record whose streams could not be aligned (:attr:`analysis.clock_model.ClockFit.failure`, the
    first reason): failed, with the clock's findings and the notes only — the other reasons judge spectra of misaligned
    streams, and their advice (interference on the phase current, the motion, the encoder) would send someone to fix
    what the clock did (a 6 s robot window without shared host stamps read "the torque estimate carries power the speed
    does not follow" at coherence 0.10)."""
    kept = tuple(r for r in quality.reasons if r.startswith(("clock", "note: ")) or r in quality.faults)
    if failure not in kept:  # a fault found in the data replaced the reasons (with_fault): the clock's failure follows it
        kept = (*(r for r in kept if not r.startswith("note: ")), failure, *(r for r in kept if r.startswith("note: ")))
    return replace(quality, verdict="failed", reasons=kept)


def analyze(rec: Recording, request: AnalysisRequest = AnalysisRequest()) -> Result:
    """Identify K, J_m, J_l, C of a joint from a raw recording.

    Parameters
    ----------
    rec : Recording
        Phase current(s), encoder positions and their indices/stamps, as recorded.
    request : AnalysisRequest, optional
        Torque method, free parameters, fit kind, band, alignment, chain.

    Returns
    -------
    Result

    Raises
    ------
    ValueError
        Bad input; in particular :class:`analysis.frf.RecordTooShortError` when the usable span
        holds fewer than two Welch segments and :class:`analysis.fit.FitInputError` for a bad band
        (:func:`analysis.limits.band_problem`: one the recording's encoder or the Welch segments cannot support, or
        one with too few bins) or ``params="K"`` without nominal values. Messages are one line.
    """
    band = request.band_hz or default_band_hz(rec.period_s)  # the prepared signals keep rec's encoder period
    band_refused = band_problem(band, rec.period_s, request.segment_s)
    if band_refused is not None:  # the default band too: its 10 Hz bin reaches 0 Hz with segments under 0.5 s
        raise FitInputError(band_refused)
    require_two_segments(longest_gap_free_span(rec.encoder_index).count, rec.period_s, request.segment_s)
    chain = request.chain(rec)
    request = replace(request, select_segments=request.selects_segments(rec))  # the result says what was done
    select = band if request.select_segments else None
    # The one-phase torque's standard error (segments whose torque is not known are left out) only where the record
    # is cut into the segments that excite (a machine's own program: its holds, at any angle, are part of the motion);
    # on acq's own continuous profiles the outlier rule found no such stretch, but left out 1 of 38 segments in 8 of 15
    # healthy runs (bench/accuracy.py scenarios 1, 22, 29), moving C's interval coverage of the family from 92 to 91 %
    sig = prepare_signals(rec, chain, torque_std=select is not None)
    frf = estimate_frf(sig.torque_Nm, sig.speed_rad_s, sig.period_s, segment_s=request.segment_s,
                       torque_noise_Nm=sig.torque_noise_Nm, torque_alias_Nm=sig.torque_alias_Nm,
                       jackknife_blocks=JACKKNIFE_BLOCKS, select_band_hz=select, torque_std_Nm=sig.torque_std_Nm)
    moves = () if frf.selection is None else tuple(
        describe_moves(sig.t_s, sig.speed_rad_s, sig.period_s, rec.counts_per_rev, math.pi / rec.pole_pairs,
                       frf.selection))
    fit = fit_two_mass(frf, FitOptions(params=request.params, kind=request.fit, band_hz=request.band_hz,
                                       weighting=chain.weighting, speed_lsb_rad=2.0 * math.pi / rec.counts_per_rev,
                                       quantisation_repeating_share=1.0 if sig.encoder_jitter is None
                                       else sig.encoder_jitter.repeating_share,
                                       vibration_damping=chain.pipeline == "acq"),
                       nominal=request.nominal)
    residual = sig.clock.residual_s if sig.aligned and math.isfinite(sig.clock.residual_s) else None
    inseparable = tuple(sorted({round(f, 1) for found in sig.interference for f in found.inseparable_hz}))
    judged = None if fit.status == "failed" else judged_fit(frf, fit)
    model_frf = None if judged is None else model_estimate(frf, judged, sig.torque_Nm, JACKKNIFE_BLOCKS)
    excess_said = None
    if model_frf is not None and chain.pipeline == "acq":  # the coherence lost beyond the known noises: H1 is then a
        fit, excess_said = with_excess_floor(fit, frf, model_frf)  # nonlinear joint's BLA (the paper's chain as it is)
    kernel_error = None if judged is None else kernel_model_error(frf, judged, model_frf)
    quality = assess(frf, fit, clock_residual_s=residual, inseparable_hz=inseparable,
                     encoder_jitter=sig.encoder_jitter, clock_failure=sig.clock.failure or None, profile=rec.profile,
                     interference=sig.interference, kernel_error=kernel_error,
                     torque_from_angle=chain.torque_method == "encoder")
    if excess_said is not None and quality.verdict != "ok":  # why the intervals are as wide as they are
        quality = replace(quality, reasons=with_excess_reason(quality.reasons, excess_said))
    caveat = chain_caveat(chain, AnalysisRequest().chain(rec))
    if caveat is not None and quality.verdict != "ok":
        quality = replace(quality, reasons=(caveat, *quality.reasons))
    # a unit or scale mistake (10× off [nominal]: its words name the current's unit), else, below that, a torque
    # scaled against a known inertia — by acq's own chain only: another's J carries that chain's errors (the paper's
    # read J_m + J_l 1.73× on a correct 10 s session, which is no k_t)
    scale_fault = (nominal_fault(fit.values, request.nominal, fit.fitted, fit.ci95)
                   or (inertia_fault(fit, request.nominal, request.inertia_tolerance) if caveat is None else None))
    quality = with_nominal_fault(quality, scale_fault)
    quality = with_fault(quality, lambda: recording_diagnosis(rec))  # a wrong bench constant (looked for when not ok)
    if sig.clock.failure:
        quality = _clock_failed(quality, sig.clock.failure)
    elif frf.selection is not None and not frf.selection.applied and not quality.faults:
        # a fault found in the data keeps its reasons (a wrong constant garbles the torque, and no segment then
        # excites: the fault, not the motion, is why — pole_pairs 8 stated 4, seed 5)
        quality = _not_excited(quality, moves, frf.selection.excited_fraction, select)  # type: ignore[arg-type]
    limited = drive_limit_reason(rec)  # the drive held a limit: at best poor, whatever else was found
    if limited is not None:
        quality = replace(quality, verdict="failed" if quality.verdict == "failed" else "poor",
                          reasons=(limited, *quality.reasons), faults=(limited, *quality.faults))
    return Result(fit=fit, quality=quality, clock=sig.clock, frf=frf,
                  figures=figure_data(sig.t_s, sig.torque_Nm, sig.speed_rad_s, frf, fit,
                                      phase_valid=phase_is_meaningful(residual), misfit_band_hz=quality.misfit_band_hz,
                                      third_mode_hz=quality.third_mode_hz, misfit_windows=quality.misfit_windows,
                                      misfit_bins=quality.misfit_bins),
                  request=request, chain=chain,
                  notes=(*sig.notes, *_unknown_torque_note(frf, sig.t_s),
                         *filter(None, [widened_c_note(fit, frf, model_frf), unbracketed_note(fit)]),
                         *([f"note: {excess_said}"] if excess_said is not None and quality.verdict == "ok" else [])),
                  moves=moves)


def _unknown_torque_note(frf: FrequencyResponse, t_s: np.ndarray) -> tuple[str, ...]:
    """A note naming the Welch segments left out because the one-phase torque is not known there (none: empty)."""
    if frf.unknown_torque is None or not frf.unknown_torque.any():
        return ()
    _, step = segment_layout(frf.segment_s, frf.period_s)  # estimate_frf's segments, at its default overlap
    starts = t_s[0] + np.flatnonzero(frf.unknown_torque) * step * frf.period_s
    where = ", ".join(f"{a:.2f}–{a + frf.segment_s:.2f} s" for a in starts)
    return (f"torque: {frf.unknown_torque.sum()} of {frf.unknown_torque.size} Welch segments left out ({where}): "
            "there the one-phase estimate's own error is an outlying share of the torque — the motor holds or changes "
            "its torque at an electrical angle where i_a shows little of it",)


def _num(x: float) -> float | None:
    """A float for JSON, None for NaN or infinity."""
    return float(x) if math.isfinite(x) else None
