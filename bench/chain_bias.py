"""Where the measured FRF departs from the TRUE two-mass response in the fit's band: the chain fed truth stage by stage.

For each run (bench/scenarios.py, recorded through the real recorder with the simulator's full history) the FRF is
estimated with the chain's own Welch / difference-operator / fold-over code from signals in which one stage after
the other is replaced by the simulator's truth, and each is compared with the TRUE plant (K, J_m, J_l, C, b = 0) as
the fit sees it (:class:`analysis.fit._Problem`: Welch kernel, noise gain, fold-over terms):

    chain   the analysis as is (analysis.analyze), also against its own fit (``fit``: what the misfit verdict sees)
    clock   the chain's torque estimate, with the true clock relation instead of the fitted one
    torque  the true torque k_t·i_q at the DAQ samples (true clock), through the chain's anti-alias resampling
    speed   … and the true motor angle's backward difference instead of the encoder's quantised one
    model+b … and the angle of the continuous two-mass model WITH the simulator's viscous frictions b_m, b_l
    model   … and without them (b = 0, the fitted model's form) — what is left is the Welch kernel / leakage error (d)

so chain−clock is the clock alignment, clock−torque the one-phase torque estimate (b), torque−speed the encoder's
quantisation (c), speed−model the simulator's departures from the two-mass model (a). Per band: mean of
ln|H_meas/H_model| (%) and of the phase difference (deg), mean over seeds (systematic) and their standard deviation
(scatter); the RMS of 8-bin window means; and χ² of the misfit windows after a complex / an amplitude fit of each
stage's FRF, each window judged by the SESSION's jackknife scatter and random-phase quantisation allowance q/√(2n)
(bench/misfit_structure.py --windows) without :data:`analysis.fit.CHAIN_REL_STD` — how much of the χ² a stage fed
truth removes. ``--allowance`` prints the session's window χ² under data-derived allowances (:func:`allowance_tests`).

Found (coherence weights alone, as acq was before this script; paper plant, seeds 0–2; 60 s = scenario 48):

* (a) the simulator's plant: the speed and model+b rows agree to ≤ 0.03 % / 0.08° in every band, so the ZOH, the
  integration, gravity and the current loop (it sits between i_q,ref and i_q, before the torque the chain measures)
  add nothing; the viscous frictions b_m = b_l = 0.002 N·m·s/rad, which the fit fixes at 0, lead the phase by
  +0.20° at 10–40 Hz and move |H| by −0.16 % at 100–160 Hz (+0.15°). Real joints have viscous friction too.
* (b) the one-phase torque estimate (clock − torque): ≤ 0.25 % and ≤ 0.14° per band, seed scatter 0.03–0.24 %.
* (c) clock: fitted offsets −0.8…−8.8 µs from the truth (all six runs negative; speed loop 60 Hz: +0.3…+1.5 µs) →
  phase −0.2…−0.3° at 160–400 Hz; amplitude nil. Encoder quantisation (torque − speed): −2.8 % at 160–250 Hz,
  +6.3 % at 250–400 Hz (window RMS 4 % and 13 %), −0.3 % at 40–100 Hz; no seed scatter: the simulated plant has no
  process noise, the motion repeats to well under a count, so its quantisation error is phase-locked.
* (d) Welch kernel / leakage model (model row): −0.13, +0.04, −0.09, −0.11, −0.08 % per band (60 s), window RMS
  0.07–0.30 % (largest 40–100 Hz, around f_a), phase ≤ 0.1°; on 10 s the same order (0.28 % at 40–100 Hz).
* The χ² without the chain term, 60 s: complex fit 412/48 (344–508), 383 of it in the 10–40 Hz windows: amplitude
  174 — the quantisation's pull (the true-speed row: 4): the bins above 150 Hz, biased by several % and weighted
  by a coherence the bias does not lower, tilt K, J, C and leave +0.24 % at 10–24 Hz where the 60 s jackknife
  scatter is 0.02 % — and phase 209 (viscous friction; model+b 219, model 7). Amplitude fit: 145/24, 130 at
  10–40 Hz, gone with the true speed (2). 10 s: 50/48 and 29/24 — the chain term matters only for long records.

No stage of OUR chain (clock, torque, resampling, Welch kernel) leaves a bias worth a fix: together ≤ 0.3 % per
window below 160 Hz, and fed the truth they remove none of the χ². What does is the encoder's phase-locked
quantisation, largely the simulator's own (a noise-free plant that crosses each count at the same phase of every
period; a real joint's disturbances move its trajectory by more than a count — 48 µrad at 2^17 — between periods,
which turns the error into the scatter the jackknife sees), and the viscous friction the fit fixes at 0 (real).

Tried and reverted (commit c91398d, then reverted): fit weights 1/(1/w_γ + 2·n_seg·q²), q the white quantisation
bound per bin. The pull goes (60 s: amplitude χ² without chain term 145 → 18/24; K, J errors 2–5× smaller on most
of bench/accuracy.py --seeds 3: paper plant K 0.27 → 0.09 %, J_m 0.40 → 0.07 %; 10 000 counts/rev K 4.6 → 1.6 %)
but the stiff plant (J_m is read above its 230 Hz resonance, where q is large) went to J_m 1.6 %, K 0.9 % with one
truth outside its interval, backlash 0.2 mrad from poor 3/3 to ok 3/3 (K −9.3 %), and the third mass at 150 Hz
became less visible (10 s amplitude χ² without chain term 92 → 26/24 while healthy went 29 → 14): confident wrong
results 6 → 10 of the family. Down-weighting the bins where the quantisation is large also hides what only they show.

Data-derived replacement for CHAIN_REL_STD in the misfit windows (``--allowance``; coherence weights; χ²/windows,
mean of seeds 0–2):

    allowance                          paper 10 s  third mass 10 s   paper 60 s  third mass 60 s
    amplitude fit, none (jk + q/√2n)      29/24         92/24          145/24         545/24
    amplitude fit, + CHAIN_REL_STD        13/24         33/24           14/24          38/24
    amplitude fit, q through the fit      14/24         36/24           15/24          42/24
    complex fit, none                     50/48        114/48          412/48         514/48
    complex fit, + CHAIN_REL_STD          23/48         58/48           26/48          70/48
    complex fit, q through fit, b_m = 0   26/48         62/48          234/48         155/48
    complex fit, q through fit + b_m      23/48         64/48           25/48          77/48

"q through the fit": each bin's random-phase quantisation bias (the session's encoder count and spectra, nothing
measured on this simulator) carried through the weighted fit's hat matrix, (I − M)·S·(I − M)ᵀ — its direct share
plus its pull on K, J, C; in the complex fit with b_m fitted. It reproduces what the constant does on healthy runs
(13–15/24, 23–25/48 against 13–14 and 23–26) and reads the third mass as high or a little higher (36–42/24,
64–77/48 against 33–38 and 58–70): the 0.4 % was standing in for the quantisation's pull, and the third mass is
separated no better than by the constant — about 2.5× the healthy χ² for amplitude, 2.8× complex (95 % of χ²(24) is
36, of χ²(48) 65). Repeated motion periods cannot give this term: the pull repeats in every period.

    nice -n 5 python bench/chain_bias.py --scenarios 1,48,20,40 --seeds 3
    nice -n 5 python bench/chain_bias.py --scenarios 1,14,48,14@60 --seeds 3 --allowance
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
from scipy import optimize, signal as sps

ROOT = Path(__file__).resolve().parent.parent
if str(ROOT) not in sys.path:  # this checkout's bench package
    sys.path.insert(0, str(ROOT))

from analysis import resample
from analysis.antialias import alias_terms, band_edges_hz
from analysis.clock_model import ClockFit
from analysis.fit import CHAIN_REL_STD, FitOptions, _jacobian, _Problem, fit_two_mass, quantisation_terms
from analysis.frf import FrequencyResponse, estimate_frf
from analysis.model import TwoMassParams
from analysis.signals import torque_on_instants
from analysis.stream_spans import spans_and_clock
from bench.misfit_structure import lines_in
from bench.scenarios import SCENARIOS, clock_for, scenario_bench

BANDS_HZ = ((10, 40), (40, 100), (100, 160), (160, 250), (250, 400))
FINE_PER_PERIOD = 32  # the model row's integration grid: 32 points per encoder period (32 kHz at 1 kHz)
WINDOW_BINS = 8  # bins per window of the window RMS (bench/misfit_structure.py --windows: 16 Hz at 0.5 s segments)
STAGES = ("chain", "fit", "clock", "torque", "speed", "model+b", "model")


def band_residuals(frf: FrequencyResponse, params: TwoMassParams) -> np.ndarray:
    """Per band of ``BANDS_HZ``: mean ln|H_meas/H_model| (%), mean phase difference (deg), and the RMS (%) of the
    amplitude's means over the band's windows of ``WINDOW_BINS`` bins (counted from the band's first bin, a window
    belonging to the band of its first bin: the local structure a window test sees), shape (3, bands)."""
    problem = _Problem(frf, (BANDS_HZ[0][0], BANDS_HZ[-1][1]), FitOptions(), params)
    z = -problem.log_ratio(problem.x0(params))
    amp, phase = 100.0 * z.real, np.degrees(np.angle(np.exp(1j * z.imag)))
    starts = np.arange(0, problem.f.size - WINDOW_BINS + 1, WINDOW_BINS)
    windows = np.array([np.mean(amp[j:j + WINDOW_BINS]) for j in starts])
    out = np.empty((3, len(BANDS_HZ)))
    for i, (a, b) in enumerate(BANDS_HZ):
        sel = (problem.f >= a) & (problem.f < b)
        out[0, i], out[1, i] = np.mean(amp[sel]), np.mean(phase[sel])
        in_band = (problem.f[starts] >= a) & (problem.f[starts] < b)
        out[2, i] = np.sqrt(np.mean(windows[in_band] ** 2)) if np.any(in_band) else np.nan
    return out


def window_chi2(frf: FrequencyResponse, chain: FrequencyResponse, lsb_rad: float, chain_std: float,
                kind: str = "complex") -> np.ndarray:
    """χ² per band of ``BANDS_HZ`` (by window start) of the misfit windows of ``frf`` after a fit of ``kind``
    (bench/misfit_structure.py --windows), shape (2, bands): amplitude windows, phase windows (0 for an amplitude fit).

    The allowance per window is the CHAIN's (the recorded session's): the jackknife scatter of its window means
    (``chain.replicates`` against the chain's own complex fit), its random-phase quantisation allowance q/√(2n),
    and ``chain_std`` (0 or :data:`analysis.fit.CHAIN_REL_STD`) — so a stage fed truth is judged against the same
    noise as the session it came from."""
    opts = FitOptions(kind=kind)  # type: ignore[arg-type]
    parts = []
    for source in (chain, frf):
        fit = fit_two_mass(replace(source, replicates=None), opts)
        problem = _Problem(source, fit.band, opts, fit.values)
        parts.append((problem, problem.log_ratio(problem.x0(fit.values)), fit))
    (pc, zc, fc), (ps, zs, _) = parts
    reps = np.asarray([_Problem(r, fc.band, opts, fc.values).log_ratio(pc.x0(fc.values)) for r in chain.replicates])
    f = pc.f
    white = quantisation_terms(chain, fc.band, lsb_rad)[0]
    out = np.zeros((2, len(BANDS_HZ)))
    for i in range(0, f.size - WINDOW_BINS + 1, WINDOW_BINS):
        w = slice(i, i + WINDOW_BINS)
        q = np.sqrt(np.mean(white[w] ** 2) / (2.0 * lines_in(chain, f[i], f[i + WINDOW_BINS - 1])))
        band = [j for j, (a, b) in enumerate(BANDS_HZ) if a <= f[i] < b]
        takes = (np.real, lambda z: np.angle(np.exp(1j * np.imag(z))))
        for row, take in enumerate(takes[:2 if kind == "complex" else 1]):
            means = take(reps[:, w]).mean(axis=1)
            noise2 = (means.size - 1) / means.size * np.sum((means - means.mean()) ** 2)
            if band:
                out[row, band[0]] += take(zs[w]).mean() ** 2 / (noise2 + q ** 2 + chain_std ** 2)
    return out


def allowance_tests(frf: FrequencyResponse, lsb_rad: float) -> dict[str, tuple[float, float, int]]:
    """χ², max |t| and the number of windows of the session's misfit windows (non-overlapping, ``WINDOW_BINS``
    bins) under four allowances, for the amplitude fit (``a …``) and the complex fit (``c …``, amplitude and phase
    windows):

    ``none``        the jackknife scatter and the random-phase quantisation q/√(2n) at the window (misfit_structure)
    ``chain``       … and :data:`analysis.fit.CHAIN_REL_STD` (today's verdict)
    ``through fit`` the jackknife and the random-phase quantisation bias of EVERY bin (σ² per bin chosen so that a
                    window's mean has q²/(2n)) carried through the weighted fit's hat matrix M: covariance
                    (I − M)·S·(I − M)ᵀ of the residual — the quantisation's direct share plus its pull on K, J, C
    ``… + b_m``     the same with the motor's viscous friction b_m fitted too (complex fit only: |H| does not see it)
    """
    out: dict[str, tuple[float, float, int]] = {}
    for kind in ("amplitude", "complex"):
        opts = FitOptions(kind=kind)  # type: ignore[arg-type]
        fit = fit_two_mass(replace(frf, replicates=None), opts)
        for with_b in ((False, True) if kind == "complex" else (False,)):
            problem = _Problem(frf, fit.band, opts, replace(fit.values, bm_Nms_per_rad=1e-3) if with_b else fit.values)
            if with_b:
                problem.free = (*problem.free, "bm_Nms_per_rad")
            x = problem.x0(problem.fixed)
            if with_b:
                x = optimize.least_squares(problem.residuals, x, method="lm").x
            f, n = problem.f, problem.f.size
            z = problem.log_ratio(x)
            reps = np.asarray([_with_free(_Problem(r, fit.band, opts, problem.fixed), problem.free).log_ratio(x)
                               for r in frf.replicates])
            white2 = quantisation_terms(frf, fit.band, lsb_rad)[0] ** 2
            starts = np.arange(0, n - WINDOW_BINS + 1, WINDOW_BINS)
            s2 = np.empty(n)
            q2 = np.empty(starts.size)
            for j, i in enumerate(starts):
                w = slice(i, i + WINDOW_BINS)
                lines = lines_in(frf, f[i], f[i + WINDOW_BINS - 1])
                q2[j] = np.mean(white2[w]) / (2.0 * lines)
                s2[w] = white2[w] * WINDOW_BINS / (2.0 * lines)
            s2[starts[-1] + WINDOW_BINS:] = s2[starts[-1] + WINDOW_BINS - 1]
            parts = 2 if kind == "complex" else 1
            jac = _jacobian(problem, x)
            d = np.tile(problem.sqrt_w, parts)
            hat = (jac / d[:, None]) @ np.linalg.solve(jac.T @ jac, (jac * d[:, None]).T)
            rest = np.eye(parts * n) - hat
            cov = (rest * np.tile(s2, parts)[None, :]) @ rest.T
            t = {name: [] for name in ("none", "chain", "through fit")}
            for part, take in enumerate((np.real, lambda v: np.angle(np.exp(1j * np.imag(v))))[:parts]):
                for j, i in enumerate(starts):
                    w = slice(i, i + WINDOW_BINS)
                    means = take(reps[:, w]).mean(axis=1)
                    jk2 = (means.size - 1) / means.size * np.sum((means - means.mean()) ** 2)
                    m = take(z[w]).mean()
                    k = part * n + i
                    carried = cov[k:k + WINDOW_BINS, k:k + WINDOW_BINS].mean()
                    t["none"].append(m / np.sqrt(jk2 + q2[j]))
                    t["chain"].append(m / np.sqrt(jk2 + q2[j] + CHAIN_REL_STD ** 2))
                    t["through fit"].append(m / np.sqrt(jk2 + carried))
            for name, values in t.items():
                if with_b and name != "through fit":
                    continue
                key = f"{kind[0]} {name}{' + b_m' if with_b else ''}"
                v = np.asarray(values)
                out[key] = (float(np.sum(v ** 2)), float(np.max(np.abs(v))), int(v.size))
    return out


def _with_free(problem: _Problem, free: tuple[str, ...]) -> _Problem:
    """``problem`` with the free parameters ``free``."""
    problem.free = free
    return problem


def truth_at(sim, t_s: np.ndarray, key: str) -> np.ndarray:
    """The simulator's true ``key`` at drive times ``t_s`` (s), in pieces (its interpolation holds ~300 B/point)."""
    return np.concatenate([sim.true_state_at(t_s[i:i + 100_000])[key] for i in range(0, t_s.size, 100_000)])


def model_speed(sim, params: TwoMassParams, t0_s: float, period_s: float, n: int, bm: float = 0.0,
                bl: float = 0.0) -> np.ndarray:
    """θ_m at t0 + k·T, k = 0 … n−1, of the continuous two-mass model (no b_m, b_l, no gravity) driven by the
    simulator's true torque (first-order hold on a grid of ``FINE_PER_PERIOD`` points per period), started
    from the simulator's true state at t0."""
    K, Jm, Jl, C = params.K_Nm_per_rad, params.Jm_kgm2, params.Jl_kgm2, params.C_Nms_per_rad
    A = np.array([[0, 1, 0, 0], [-K / Jm, -(C + bm) / Jm, K / Jm, C / Jm], [0, 0, 0, 1],
                  [K / Jl, C / Jl, -K / Jl, -(C + bl) / Jl]])
    B = np.array([[0.0], [1.0 / Jm], [0.0], [0.0]])
    h = period_s / FINE_PER_PERIOD
    t = t0_s + np.arange((n - 1) * FINE_PER_PERIOD + 1) * h
    st = {k: truth_at(sim, t, k) for k in ("theta_m_rad", "omega_m_rad_s", "theta_l_rad", "omega_l_rad_s", "torque_Nm")}
    Ad, Bd, Cd, Dd, _ = sps.cont2discrete((A, B, np.eye(4), np.zeros((4, 1))), h, method="foh")
    x0 = np.array([st["theta_m_rad"][0], st["omega_m_rad_s"][0], st["theta_l_rad"][0], st["omega_l_rad_s"][0]])
    # foh's state is shifted by Bd-part of the first input: x̃ = x − Γ₂·u, so start there
    _, y, _ = sps.dlsim((Ad, Bd, Cd, Dd, h), st["torque_Nm"][:, None], x0=np.linalg.solve(Cd, x0 - Dd[:, 0] * st["torque_Nm"][0]))
    return y[::FINE_PER_PERIOD, 0]


def scenario(spec: str) -> tuple[str, Any]:
    """A scenario from ``N`` (bench/scenarios.py, 1-based) or ``N@D`` (the same, recorded for D seconds)."""
    number, _, duration = spec.partition("@")
    sc = SCENARIOS[int(number) - 1]
    return spec, (replace(sc, duration_s=float(duration), name=f"{sc.name}, {duration} s") if duration else sc)


def record(spec: str, seed: int) -> tuple[Any, Any, Any, Any, TwoMassParams, Any]:
    """Record one run with the simulator's full history and analyse it as acq does: (simulator, scenario, recording,
    result, true two-mass plant — J_l + J_3 with a third mass behind the load —, bench)."""
    from acq.offline.analyze import recording_from_session, request_for
    from acq.recording.recorder import Recorder
    from acq.recording.reader import load
    from analysis import analyze
    from drivers.registry import open_bench
    from drivers.sim.bench import SimBench

    _, sc = scenario(spec)
    index = int(spec.partition("@")[0]) - 1
    offset_s, drift_ppm = sc.clock if sc.clock is not None else clock_for(seed, index)
    bench, profile = scenario_bench(sc, seed, offset_s, drift_ppm)
    sim = SimBench(bench, realtime=False, keep_history=True)
    current, drive = open_bench(bench, fast=True, sim_bench=sim)
    with tempfile.TemporaryDirectory(prefix="acq-chainbias-") as tmp:
        session = load(Recorder(bench, profile, current, drive, Path(tmp), sc.duration_s).run().path)
        rec = recording_from_session(session)
        res = analyze(rec, request_for(session))
    tr = sim.truth
    truth = TwoMassParams(tr["K_Nm_per_rad"], tr["Jm_kgm2"], tr["Jl_kgm2"], tr["C_Nms_per_rad"])
    if sc.jl_truth == "load+third":
        truth = replace(truth, Jl_kgm2=truth.Jl_kgm2 * (1.0 + bench.sim.third_mass_Jl_fraction))
    return sim, sc, rec, res, truth, bench


def run(spec: str, seed: int) -> tuple[dict[str, np.ndarray], dict[str, float], dict[str, FrequencyResponse]]:
    """Band residuals and window χ² of every stage of one run, a few figures (K error, clock error), the stages' FRFs."""
    sim, sc, rec, res, truth, bench = record(spec, seed)
    tr = sim.truth
    lsb = 2.0 * np.pi / rec.counts_per_rev
    frfs = {"chain": res.frf}
    T = rec.period_s
    f_pass, f_stop = band_edges_hz(rec)

    def frf(tq: np.ndarray, speed: np.ndarray, noise: np.ndarray | None, alias: np.ndarray) -> FrequencyResponse:
        return estimate_frf(tq, speed, T, torque_noise_Nm=noise, torque_alias_Nm=alias)

    # (clock) the chain's torque with the true clock relation
    spans = spans_and_clock(rec)
    true_clock = ClockFit(tr["daq_offset_s"], tr["daq_drift_ppm"], theta0_rad=spans.clock.theta0_rad)
    spans = replace(spans, clock=true_clock, t_daq_s=true_clock.daq_time_s(spans.t_s))
    sig = torque_on_instants(rec, spans)
    frfs["clock"] = frf(sig.torque_Nm, sig.speed_rad_s, sig.torque_noise_Nm, sig.torque_alias_Nm)
    # (torque) the true torque at the DAQ samples of the span, through the chain's resampling
    n_daq = spans.current_a["i_a"].size
    t_daq0 = spans.n0 / rec.rate_hz
    tau_daq = truth_at(sim, sim.daq_time_s(spans.n0 + np.arange(n_daq)), "torque_Nm")
    tau = resample.to_instants(tau_daq, rec.rate_hz, t_daq0, spans.t_daq_s, f_pass, f_stop)
    step_s = (1.0 + true_clock.drift_ppm * 1e-6) / rec.rate_hz
    alias = alias_terms(tau_daq, rec.rate_hz, t_daq0, float(true_clock.drive_time_s(t_daq0)), step_s, spans.t_daq_s,
                        T, f_pass, f_stop)
    frfs["torque"] = frf(tau, sig.speed_rad_s, None, alias)
    # (speed) … and the true angle's backward difference
    theta = truth_at(sim, np.concatenate(([spans.t_s[0] - T], spans.t_s)), "theta_m_rad")
    frfs["speed"] = frf(tau, np.diff(theta) / T, None, alias)
    # (model) … and the continuous two-mass model's own angle driven by the true torque
    theta_model = model_speed(sim, truth, spans.t_s[0] - T, T, spans.t_s.size + 1)
    frfs["model"] = frf(tau, np.diff(theta_model) / T, None, alias)
    theta_b = model_speed(sim, truth, spans.t_s[0] - T, T, spans.t_s.size + 1, tr["bm_Nms_per_rad"], tr["bl_Nms_per_rad"])
    frfs["model+b"] = frf(tau, np.diff(theta_b) / T, None, alias)
    out = {stage: band_residuals(h, truth) for stage, h in frfs.items()}
    out["fit"] = band_residuals(res.frf, res.fit.values)
    for stage, h in frfs.items():
        out[f"chi2 {stage}"] = window_chi2(h, res.frf, lsb, 0.0, "complex")
        out[f"chi2a {stage}"] = window_chi2(h, res.frf, lsb, 0.0, "amplitude")
    out["chi2 chain+0.4%"] = window_chi2(res.frf, res.frf, lsb, CHAIN_REL_STD, "complex")
    out["chi2a chain+0.4%"] = window_chi2(res.frf, res.frf, lsb, CHAIN_REL_STD, "amplitude")
    v = res.fit.values
    figures = {"K %": 100 * (v.K_Nm_per_rad / truth.K_Nm_per_rad - 1), "Jm %": 100 * (v.Jm_kgm2 / truth.Jm_kgm2 - 1),
               "Jl %": 100 * (v.Jl_kgm2 / truth.Jl_kgm2 - 1),
               "clock µs": 1e6 * (res.clock.offset_s - tr["daq_offset_s"]), "drift ppm": res.clock.drift_ppm - tr["daq_drift_ppm"],
               "verdict": res.quality.verdict}
    return out, figures, frfs


def print_table(title: str, rows: dict[str, list[np.ndarray]]) -> None:
    """Mean over seeds ± their standard deviation, amplitude (%) then phase (deg), per band."""
    bands = " ".join(f"{f'{a}–{b} Hz':>11s}" for a, b in BANDS_HZ)
    print(f"\n{title}")
    for what, row, unit in (("mean ln|H/H_true| %, mean (sd) over seeds", 0, ""),
                            ("mean phase difference deg, mean (sd) over seeds", 1, ""),
                            (f"RMS over {WINDOW_BINS}-bin windows of ln|H/H_true| %, mean (sd) over seeds", 2, "")):
        print(f"  {what}\n  {'stage':7s} {bands}")
        for stage in STAGES:
            r = np.asarray(rows[stage])[:, row]
            m, s = r.mean(axis=0), r.std(axis=0, ddof=1) if r.shape[0] > 1 else np.zeros(r.shape[1:])
            print(f"  {stage:7s} " + " ".join(f"{f'{m[i]:+.2f}({s[i]:.2f})':>11s}" for i in range(len(BANDS_HZ))),
                  flush=True)
    for prefix, title in (("chi2 ", "χ² of the complex fit's windows: amplitude | phase"),
                          ("chi2a ", "χ² of the amplitude fit's windows")):
        print(f"  {title} ({WINDOW_BINS} bins; allowance: the session's jackknife and random-phase quantisation, no chain "
              f"term unless named), mean (sd) over seeds\n  {'stage':15s} {bands}  total")
        for key in [k for k in rows if k.startswith(prefix)]:
            r = np.asarray(rows[key])  # (seeds, 2, bands)
            cells = []
            for i in range(len(BANDS_HZ)):
                a, p = r[:, 0, i], r[:, 1, i]
                cells.append(f"{a.mean():.0f}|{p.mean():.0f}" if prefix == "chi2 " else f"{a.mean():.0f}({a.std():.0f})")
            tot = r.sum(axis=(1, 2))
            print(f"  {key[len(prefix):]:15s} " + " ".join(f"{c:>11s}" for c in cells)
                  + f" {tot.mean():6.0f}({tot.std(ddof=1) if tot.size > 1 else 0:.0f})", flush=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--scenarios", default="1", help="comma-separated scenarios N or N@seconds (bench/scenarios.py, 1-based)")
    ap.add_argument("--seeds", type=int, default=3, help="seeds 0 … N−1")
    ap.add_argument("--allowance", action="store_true",
                    help="only the session's misfit windows under the allowances of allowance_tests (no truth stages)")
    args = ap.parse_args()
    for spec in args.scenarios.split(","):
        name = scenario(spec)[1].name
        rows: dict[str, list[Any]] = {}
        for seed in range(args.seeds):
            if args.allowance:
                _, _, rec, res, _, _ = record(spec, seed)
                out = allowance_tests(res.frf, 2.0 * np.pi / rec.counts_per_rev)
                for k, v in out.items():
                    rows.setdefault(k, []).append(v)
                print(f"{spec} s{seed} {res.quality.verdict}: " + ", ".join(
                    f"{k} χ² {c:.0f}/{n} max|t| {t:.1f}" for k, (c, t, n) in out.items()), flush=True)
                continue
            out, fig, _ = run(spec, seed)
            for s, v in out.items():
                rows.setdefault(s, []).append(v)
            print(f"{spec} s{seed}: " + ", ".join(f"{k} {v:+.3f}" if isinstance(v, float) else f"{k} {v}"
                                               for k, v in fig.items()), flush=True)
        if args.allowance:
            print(f"scenario {spec}: {name}, seeds 0–{args.seeds - 1}: χ² (max |t|) over the windows, mean over seeds")
            for k, v in rows.items():
                a = np.asarray(v)
                print(f"  {k:22s} χ² {a[:, 0].mean():6.0f} / {a[0, 2]:.0f}   max |t| {a[:, 1].mean():5.1f}"
                      f"   (per seed: {' '.join(f'{c:.0f}' for c in a[:, 0])})", flush=True)
        else:
            print_table(f"scenario {spec}: {name}, seeds 0–{args.seeds - 1}", rows)


if __name__ == "__main__":
    main()
