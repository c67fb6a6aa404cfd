"""Verdict on an identification: ok / poor / failed, with the reasons in words (design §5 step 6).

A number is only printed with confidence when the data back it: the joint must be excited between
its anti-resonance f_a and resonance f_r (coherence there, torque power there), the model must
match |H|, the confidence intervals must be narrow, and the clocks must have been aligned. The
paper's 0.5 s profile fails the first test (paper §5.2): the verdict then says so and how to fix
it instead of handing out a stiffness.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from analysis.averages import few_averages
from analysis.encoder import difference_response
from analysis.excitation import RESOLUTION_NAMED, against_limit, weak_coherence_cause
from analysis.fit import COHERENCE_CLIP, FitResult, band_mask
from analysis.fit_problem import rel_halfwidth
from analysis.frf import FrequencyResponse
from analysis.misfit_advice import beyond_band, estimate_explains, first_order_pull, misfit_cause, one_phase_doubt
from analysis.misfit_band import missed_band
from analysis.model import PARAM_LABELS
from analysis.recording import CommandedProfile
from analysis.sample_instants import EncoderJitter
from analysis.torque import Interference
from analysis.verdict_limits import RANK, Thresholds, Verdict, grade, phase_is_meaningful


@dataclass(frozen=True)
class Quality:
    """How far an identification can be trusted.

    Attributes
    ----------
    verdict : {"ok", "poor", "failed"}
        The worst of the checks.
    mean_coherence : float
        Mean γ² over the fit band.
    excitation_coherence : float
        Mean γ² between f_a and f_r of the fit (NaN if the fit failed).
    excitation_torque_db : float
        Mean torque PSD between f_a and f_r, dB re 1 (N·m)²/Hz (NaN if the fit failed).
    residual_rms : float
        The fit's weighted RMS misfit of ln|H|.
    misfit_ratio : float
        ``residual_rms`` over the RMS that noise alone would leave, from the coherence: ≈ 1 when
        the model explains everything but noise.
    ci_rel_halfwidth : dict of str to float
        Half-width of each fitted parameter's 95 % interval relative to its value.
    clock_residual_s : float or None
        Clock-alignment residual as given, s.
    reasons : tuple of str
        One sentence per check that is not ok, worst first; empty when ok.
    encoder_jitter_s : float or None
        The encoder's sample-instant jitter left in the speed, s (:mod:`analysis.sample_instants`);
        None when not estimated.
    encoder_time_stamps : bool
        True when the drive's own time stamps moved the samples to their nominal instants.
    misfit_band_hz : tuple of float or None
        The stretch of the band where the two-mass model misses |H| by more than noise and the encoder's
        quantisation explain (:mod:`analysis.misfit_band`); None when it fits.
    third_mode_hz : float or None
        The frequency of the third mode a reason names (:mod:`analysis.third_mode`), Hz; None when none is named
        (none found, or the misfit band is named instead).
    misfit_windows : tuple of (float, float, float, float)
        Each window the misfit test judged (:func:`analysis.adequacy.band_misfits`): its first and last bin (Hz),
        its mean ln|H_model| − ln|H| and the most that may be before the window is called missed (the bound taken
        off plus the critical t × √(noise² + systematic²)); empty when the test was not made. For the report's
        picture: the misfit and the allowance the verdict weighed.
    misfit_bins : tuple of (float, float)
        Each bin the misfit test judged: its frequency (Hz) and ln|H_model| − ln|H| there, the model as the Welch
        estimator sees it and as the test judges it (the windows' means are of these); empty when the test was not
        made. For the report's picture: the per-bin misfit that agrees with the verdict.
    faults : tuple of str
        Those of ``reasons`` that name a fault found in the data — a wrong bench constant or phase sequence, a value
        an order of magnitude off the nominal (:mod:`analysis.diagnose`), the drive holding a limit
        (:mod:`analysis.drive_limits`) — whatever the coherence: a record with one is never called not excited
        (:mod:`acq.offline.excitation_judge`); empty when none was found.
    """

    verdict: Verdict
    mean_coherence: float
    excitation_coherence: float
    excitation_torque_db: float
    residual_rms: float
    misfit_ratio: float
    ci_rel_halfwidth: dict[str, float]
    clock_residual_s: float | None
    reasons: tuple[str, ...]
    encoder_jitter_s: float | None = None
    encoder_time_stamps: bool = False
    misfit_band_hz: tuple[float, float] | None = None
    third_mode_hz: float | None = None
    misfit_windows: tuple[tuple[float, float, float, float], ...] = ()
    misfit_bins: tuple[tuple[float, float], ...] = ()
    faults: tuple[str, ...] = ()


def assess(
    frf: FrequencyResponse,
    fit: FitResult,
    *,
    clock_residual_s: float | None = None,
    inseparable_hz: tuple[float, ...] = (),
    thresholds: Thresholds = Thresholds(),
    encoder_jitter: EncoderJitter | None = None,
    clock_failure: str | None = None,
    profile: CommandedProfile | None = None,
    interference: tuple[Interference, ...] = (),
    kernel_error: np.ndarray | None = None,
    torque_from_angle: bool = False,
) -> Quality:
    """Judge an identification from its FRF, its fit and the clock alignment.

    Parameters
    ----------
    frf : FrequencyResponse
        The measured frequency response.
    fit : FitResult
        The fit of the two-mass model to ``frf``.
    clock_residual_s : float or None, optional
        RMS residual of the clock alignment, s; None when the caller did not align (not judged).
    inseparable_hz : tuple of float, optional
        Lines on the phase current that the torque estimate could not tell apart from the torque
        (:attr:`analysis.torque.Interference.inseparable_hz`), Hz; each makes the result poor.
    thresholds : Thresholds, optional
        Limits of the verdict.
    encoder_jitter : EncoderJitter or None, optional
        The encoder's sample-instant jitter estimated from the data (not judged if None).
    kernel_error : ndarray or None, optional
        ln H (complex) the Welch estimator makes of the fitted model less the fit's model of it, at the judged
        band's bins (:func:`analysis.fit.judged_fit`, :func:`analysis.estimator_check.kernel_model_error`): the
        misfit tests judge the measurement against the model so corrected; None: uncorrected.
    clock_failure : str or None, optional
        Why the clock alignment failed (:attr:`analysis.clock_model.ClockFit.failure`): the verdict is then failed
        with it as the first reason — low coherence and wide intervals follow from it, not from the motion.
    profile : CommandedProfile or None, optional
        The profile acq commanded: a weak coherence's advice names its keys only when known
        (:func:`analysis.excitation.weak_coherence_cause`).
    interference : tuple of Interference, optional
        What the torque estimate removed from the current, named when the torque carries power the speed does not
        follow.
    torque_from_angle : bool, optional
        The torque was read from one phase current through the electrical angle (the encoder method): a misfit
        band's reason then names that estimate first when the clock alignment's residual says the phase follows the
        angle only loosely (:func:`analysis.misfit_advice.one_phase_doubt`).

    Returns
    -------
    Quality
    """
    th = thresholds
    lsb_rad = encoder_jitter.lsb_rad if encoder_jitter is not None else 0.0

    def cause(check: np.ndarray, limit: float) -> str:
        return weak_coherence_cause(frf, check, limit, lsb_rad=lsb_rad, profile=profile, f_a_hz=fit.f_a,
                                    band_mask_all=in_band, interference=interference)

    findings: list[tuple[Verdict, str]] = []
    in_band = band_mask(frf.f_hz, fit.band)
    mean_coh = float(np.mean(frf.coherence[in_band])) if np.any(in_band) else float("nan")
    lo, hi = fit.band
    if fit.status == "failed":
        findings.append(("failed", f"the fit did not converge ({fit.message})"))
    elif fit.status == "max_evaluations":
        findings.append(("poor", "the fit stopped at its evaluation limit before converging"))

    exc_coh = exc_db = float("nan")
    if np.isfinite(fit.f_a) and np.isfinite(fit.f_r):
        if not (lo <= fit.f_a and fit.f_r <= hi):
            findings.append(("failed", f"fitted f_a {fit.f_a:.0f} Hz … f_r {fit.f_r:.0f} Hz lies outside the "
                                       f"fit band {lo:g}…{hi:g} Hz — widen the band or check the bench"))
        sel = band_mask(frf.f_hz, (fit.f_a, fit.f_r)) & in_band
        if np.any(sel):
            exc_coh = float(np.mean(frf.coherence[sel]))
            exc_db = float(10.0 * np.log10(np.mean(frf.torque_psd[sel])))
            level = grade(exc_coh, th.excitation_poor, th.excitation_failed)
            if level != "ok":
                findings.append((level, f"coherence {against_limit(exc_coh, th.excitation_poor)} between f_a {fit.f_a:.0f} Hz and f_r "
                                        f"{fit.f_r:.0f} Hz (torque {exc_db:.0f} dB re 1 N²m²/Hz there), "
                                        f"{cause(sel, th.excitation_poor)}"))

    level = grade(mean_coh, th.coherence_poor, th.coherence_failed)
    if level != "ok":
        findings.append((level, f"mean coherence {against_limit(mean_coh, th.coherence_poor)} in {lo:g}…{hi:g} Hz (in closed loop that biases |H|, "
                                f"not only scatters it), {cause(in_band, th.coherence_poor)}"))

    ratio = fit.residual_rms / _noise_rms(frf, in_band)
    # without the encoder's resolution the share of |H|'s misfit that its quantisation repeats with every
    # motion period is unknown (±8 % at 200–250 Hz on a healthy 2^17 counts/rev bench): no misfit test then
    known_resolution = encoder_jitter is not None and encoder_jitter.lsb_rad > 0.0
    missed, mode, judged, bins, estimate = (missed_band(frf, fit, encoder_jitter, kernel_error,
                                                         phase_is_meaningful(clock_residual_s, th), torque_from_angle)
                                            if fit.status != "failed" and known_resolution
                                            else (None, None, (), (), None))
    named_mode = mode if missed is None and mode is not None and mode.found else None
    if named_mode is not None:
        findings.append(("poor", f"the two-mass model misses a third mode near {mode.f_hz:.0f} Hz ({mode.t:.1f} σ "
                                 f"beyond what noise, the chain and the encoder's quantisation explain): a third mass "
                                 f"there moves the fitted K beyond its interval (±{100 * mode.k_halfwidth:.1f} %"
                                 f"{first_order_pull(mode)}){beyond_band(mode.f_hz, fit, True)} — a "
                                 f"compliant or loose part (the coupling, the arm, the tool or their mountings): check "
                                 f"them; until then K, J_m, J_l are the two-mass model's compromise, not the joint's"))
    if missed is not None and estimate is not None:
        low, high, worst = missed
        findings.append(("poor", f"the two-mass model does not fit |H| between {low:.0f} and {high:.0f} Hz: it misses "
                                 f"by {100 * worst.misfit:+.1f} % at {worst.low_hz:.0f}…{worst.high_hz:.0f} Hz, "
                                 f"{worst.t:.0f} σ beyond what noise, the chain and the encoder's quantisation explain "
                                 f"— {estimate_explains(estimate, worst, bins)}"))
    elif missed is not None:
        low, high, worst = missed
        findings.append(("poor", f"the two-mass model does not fit |H| between {low:.0f} and {high:.0f} Hz: it misses "
                                 f"by {100 * worst.misfit:+.1f} % at {worst.low_hz:.0f}…{worst.high_hz:.0f} Hz, "
                                 f"{worst.t:.0f} σ beyond what noise, the chain and the encoder's quantisation explain"
                                 f"{beyond_band(worst.low_hz, fit, False)} — "
                                 f"{one_phase_doubt(clock_residual_s, th) if torque_from_angle else ''}"
                                 f"{misfit_cause(worst, fit)}; until then K, J_m, J_l are the two-mass model's "
                                 f"compromise, not the joint's"))
    elif np.isfinite(fit.residual_rms):
        # the RMS misfit against the coherence's noise alone: where the window test ran (it allows for the
        # quantisation that repeats with the motion, which this ratio does not — 8 % RMS on a healthy 2^17 counts/rev
        # session whose trajectory repeats to a fraction of a count) only a gross misfit still fails here
        level = grade(-fit.residual_rms, -th.residual_poor, -th.residual_failed)
        if level != "ok" and ratio > th.misfit_ratio_poor and (not known_resolution or level == "failed"):
            few = few_averages(frf, th.coherence_poor)  # then the noise itself is unknown, not the model wrong
            findings.append((level, f"the two-mass model misses |H| by {100 * fit.residual_rms:.0f} % RMS, " + (
                f"{ratio:.1f}× what noise explains — another mode or a nonlinearity in the band; try --band"
                if few is None else f"but {few}")))

    ci_rel = {name: rel_halfwidth(fit, name) for name in fit.fitted}
    undetermined = _undetermined(fit) if fit.status != "failed" else None
    if undetermined is not None:
        findings.append(("failed", undetermined))
    for name, (poor, failed) in {"K_Nm_per_rad": (th.ci_K_poor, th.ci_K_failed),
                                 "Jm_kgm2": (th.ci_J_poor, th.ci_J_failed),
                                 "Jl_kgm2": (th.ci_J_poor, th.ci_J_failed)}.items():
        if name in ci_rel and fit.status != "failed" and np.isfinite(ci_rel[name]):  # else: undetermined, said
            level = grade(-ci_rel[name], -poor, -failed)
            if level != "ok":
                findings.append((level, f"{PARAM_LABELS[name][0]} is known only to ±{100 * ci_rel[name]:.1f} % (95 %)"))

    if clock_residual_s is not None:
        limit = th.clock_residual_complex_s if fit.options.kind == "complex" else th.clock_residual_amplitude_s
        if not clock_residual_s <= limit:
            findings.append(("poor", f"clock alignment residual {1e6 * clock_residual_s:.0f} µs exceeds "
                                     f"{1e6 * limit:.0f} µs for {'an' if fit.options.kind == 'amplitude' else 'a'} "
                                     f"{fit.options.kind} fit"))

    if encoder_jitter is not None and np.any(in_band):
        found, timing_defect = _jitter_findings(frf, fit, in_band, encoder_jitter, th)
        if any(RESOLUTION_NAMED in text for _, text in findings):
            found = [] if not timing_defect else found  # the coherence's reason already names the resolution
        if timing_defect:
            findings[:0] = found  # a timing defect is the cause: first
        else:
            findings.extend(found)  # the encoder's resolution: a property of the bench, after the motion's reasons
    if clock_failure:
        findings.insert(0, ("failed", clock_failure))  # the cause of what follows: first
    for f_hz in inseparable_hz:
        findings.append(("poor", f"a {f_hz:.1f} Hz line on the phase current cannot be told apart from the torque "
                                 f"(the motor turns at that electrical frequency for long): remove it at its source "
                                 f"(mains hum: grounding and shielding; PWM ripple: the DAQ's anti-alias filter)"))

    findings.sort(key=lambda fv: -RANK[fv[0]])
    verdict: Verdict = findings[0][0] if findings else "ok"
    return Quality(
        verdict=verdict, mean_coherence=mean_coh, excitation_coherence=exc_coh, excitation_torque_db=exc_db,
        residual_rms=float(fit.residual_rms), misfit_ratio=float(ratio), ci_rel_halfwidth=ci_rel, clock_residual_s=clock_residual_s,
        reasons=tuple(text for _, text in findings),
        encoder_jitter_s=None if encoder_jitter is None else float(encoder_jitter.sigma_s),
        encoder_time_stamps=encoder_jitter is not None and encoder_jitter.stamped,
        misfit_band_hz=None if missed is None else missed[:2],
        third_mode_hz=None if named_mode is None else float(named_mode.f_hz),
        misfit_windows=judged,
        misfit_bins=bins,
    )


def _undetermined(fit: FitResult) -> str | None:
    """Why the fitted parameters whose 95 % interval is not finite are not determined (None when every one is): the
    fit's covariance is infinite when a refit on part of the data diverged (:func:`analysis.fit.fit_two_mass`)."""
    names = [PARAM_LABELS[n][0] for n in fit.fitted if not all(np.isfinite(b) for b in fit.ci95[n])]
    if not names:
        return None
    listed = names[0] if len(names) == 1 else f"{', '.join(names[:-1])} and {names[-1]}"
    return (f"{listed} {'is' if len(names) == 1 else 'are'} not determined (95 % interval up to infinity): a refit on "
            "part of the data — the record less one block (the jackknife behind the intervals) or the resonance read "
            "from H2 — diverged, so the fit is not stable under the data")


def _jitter_findings(frf: FrequencyResponse, fit: FitResult, in_band: np.ndarray, jitter: EncoderJitter,
                     th: Thresholds) -> tuple[list[tuple[Verdict, str]], bool]:
    """The verdict on the encoder's timing jitter and resolution, from the session's own spectra.

    The speed noise they predict, N(f) (the jitter's and the position quantisation's), is taken out of the
    measured speed PSD G_yy = |H·D|²·G_xx/γ² (D the backward difference): without it the coherence would be
    γ²·G_yy/(G_yy − N) (at most 1). The encoder limits the FRF when that would lift the grade of the
    verdict's own coherence checks (whole band; f_a…f_r with the excitation limits) — no limit of its own;
    the larger of the two noises is named. Returns the findings and whether they name a timing defect.
    """
    f = frf.f_hz[in_band]
    g2 = np.clip(frf.coherence[in_band], 1e-6, 1.0)
    g_yy = np.abs(frf.H[in_band] * difference_response(f, frf.period_s)) ** 2 * frf.torque_psd[in_band] / g2
    timing = jitter.speed_noise_psd(f, frf.period_s) if np.isfinite(jitter.sigma_s) else np.zeros_like(f)
    resolution = jitter.quantisation_noise_psd(f, frf.period_s)
    noise = timing + resolution
    without = g2 * g_yy / np.maximum(g_yy - noise, g2 * g_yy)
    checks = [(np.ones(f.size, dtype=bool), th.coherence_poor, th.coherence_failed)]
    if np.isfinite(fit.f_a) and np.isfinite(fit.f_r):
        checks.append((band_mask(f, (fit.f_a, fit.f_r)), th.excitation_poor, th.excitation_failed))
    level: Verdict = "ok"
    for sel, poor, failed in checks:
        if np.any(sel):
            now = grade(float(np.mean(g2[sel])), poor, failed)
            if RANK[now] > RANK[grade(float(np.mean(without[sel])), poor, failed)]:
                level = max(level, now, key=RANK.__getitem__)
    if level == "ok":
        return [], False
    sigma_us, lo, hi = 1e6 * jitter.sigma_s, *fit.band
    cost = (f"coherence {np.mean(g2):.2f} in {lo:g}…{hi:g} Hz, ≈ {np.mean(without):.2f} without the speed noise "
            "it predicts")
    if np.sum(resolution) > np.sum(timing):
        counts = 2.0 * np.pi / jitter.lsb_rad
        advice = ("record longer or use a finer encoder; raise [encoder] counts_per_rev only if the drive really "
                  "reports finer position units (changing the key alone breaks a correct bench)")
        return [(level, f"the encoder's resolution ({counts:.0f} counts/rev) leaves speed noise that limits the FRF "
                        f"({cost}): {advice}")], False
    if jitter.stamped:
        return [(level, f"the encoder's sample instants still scatter by ≈ {sigma_us:.1f} µs after the drive's time "
                        f"stamps ({cost}): check that the drive's time stamp (0x1013 or the frame's drive time) is "
                        "taken when the position is latched")], True
    return [(level, f"the drive samples at SYNC arrival with ≈ {sigma_us:.0f} µs jitter ({cost}): use a hardware "
                    "SYNC or map the drive's time stamp (0x1013, [drive] map_timestamp = true)")], True


def _noise_rms(frf: FrequencyResponse, in_band: np.ndarray) -> float:
    """Weighted RMS of ln|H1| that noise alone leaves, from the coherence.

    var ln|H1| ≈ (1 − γ²)/(2 n γ²) per bin with n averaged segments, so with the fit's weights
    w = γ²/(1 − γ²) the expected weighted mean square is N / (2 n Σ w) over N bins.
    """
    g2 = np.clip(frf.coherence[in_band], 0.0, COHERENCE_CLIP)
    sum_w = float(np.sum(g2 / (1.0 - g2)))
    return float(np.sqrt(g2.size / (2.0 * frf.n_segments * sum_w))) if sum_w > 0 else float("nan")
