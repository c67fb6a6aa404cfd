"""Electromagnetic torque T_e = k_t·i_q from one phase current demodulated with the encoder angle (design §5.1),
acq's default estimator (``--torque encoder``).

Motor model (i_d = 0): i_a = −i_q·sin(θ_e + θ_0) + dc, i_b and i_c shifted by ∓2π/3, where θ_e = p·θ_m
is the encoder's electrical angle at the DAQ instants (mapped through the clock fit) and θ_0 the
motor's electrical offset (:mod:`analysis.phase_offset`). The functions return torque at the DAQ samples they
were given.

* :func:`torque_encoder` — one phase, demodulated with the encoder angle: i_q is a cubic B-spline in
  time fitted by penalised least squares to i_a. Every sample counts with weight sin²(θ_e + θ_0), so
  where the phase carries no information (|sin| small) the spline is carried by its neighbours instead
  of an explicit interpolation; the penalty only bridges those holes. No speed enters the estimate.
  Interference the angle does not modulate (sensor offset drift, mains hum, aliased PWM ripple) is
  removed in the same least squares (:class:`Interference`).
* :func:`angle_information_std` — the estimate's standard error where the phase carries little about i_q.

The other estimators: two or three phases by Clarke + Park (:mod:`analysis.torque_park`) and the paper's
Hilbert envelope (:mod:`analysis.torque_hilbert`).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from scipy.ndimage import median_filter, uniform_filter1d
from scipy.signal import find_peaks

from analysis import trig, welch
from analysis.phase_offset import PhaseOffset
from analysis.torque_spline import SlowOffset, spline_factor, spline_fit


def torque_encoder(current_a: np.ndarray, theta_e_rad: np.ndarray, rate_hz: float, k_t_Nm_per_A: float,
                   offset: PhaseOffset, knot_spacing_s: float = 2.5e-4, smoothing: float = 1e-2,
                   noise_seed: int | None = None, found: list[Interference] | None = None) -> np.ndarray:
    """Torque from one phase demodulated with the encoder angle, N·m, at the given samples.

    Solves min Σ_n (i_a[n] − dc + i_q(t_n)·sin(θ_e[n] + θ_0))² + λ·Σ (Δ² c)² for the coefficients c of
    a uniform cubic B-spline i_q(t) (a banded system, cost linear in the record length), jointly with
    what is left of the sensor DC after subtracting ``offset.dc_a``. A second pass adds the first
    pass's −i_q·cos(θ_e + θ_0) as a column, i.e. re-estimates θ_0 linearised, so an error of a few
    mrad in ``offset.theta0_rad`` (which matters where |sin| is small) does not leak into the torque;
    and the same column times the electrical speed dθ_e/dt (and times t), i.e. re-estimates the clock
    offset and drift linearised: an offset error δ of tens of µs turns the angle by p·ω·δ, which the
    constant θ_0 cannot absorb (on a stiff plant a 39 µs residual cost K +2.7 %, J_m +4.5 %). The
    angle's rate only corrects the angle, it never scales the torque.

    Interference that the electrical angle does not modulate is estimated in the same least squares
    and removed (the torque enters only through sin(θ_e + θ_0), so a term fixed in the lab frame is
    told apart from it wherever the electrical frequency is away from the term's own): the sensor
    offset is a slow cubic B-spline in time (knots :data:`OFFSET_KNOT_S` apart) instead of a
    constant, and every narrow line of the first pass's residual spectrum (mains hum and its
    harmonics, aliased PWM ripple, …; :func:`_interference_lines`) gets a sine and a cosine at its
    frequency, each also times t (a slowly changing amplitude or a slightly wrong frequency). Left
    in the current, a line leaks into i_q as line/sin(θ_e + θ_0): 20 mA of 50 Hz hum with 40 mA of
    offset drift biased K by +3 %.

    The knots are 0.25 ms apart (bandwidth ≈ 2 kHz): at 0.5 ms the spline cannot follow the current
    loop's fast content, and the part it misses, weighted by sin², folds into the band (soft plant:
    K +4 % from a noise-free current; 0.25 ms: +0.1 %).

    Parameters
    ----------
    current_a, theta_e_rad : ndarray
        Phase current, A, and electrical angle at the same samples (clock-aligned), rad.
    rate_hz : float
        Sampling rate, Hz.
    k_t_Nm_per_A : float
        Torque constant, N·m/A.
    offset : PhaseOffset
        θ_0 (sign chosen) and a first estimate of the sensor DC (refined jointly).
    knot_spacing_s : float
        Knot spacing of the spline, s; its bandwidth is about 1/(2·spacing).
    smoothing : float
        λ relative to the mean data weight per coefficient; only matters where |sin| is small.
    noise_seed : int or None
        If given, also return what the estimator makes of white noise of the fit's residual floor
        (drawn from this seed), N·m: shape (2, n), row 0 the torque, row 1 the noise realisation.
        Its spectrum is the estimate's noise spectrum (the estimator is linear in the current), which
        the FRF needs because noise on the torque biases H1 = G_xy/G_xx low where the torque is weak.
        The noise goes through the first pass (the spline and the sensor DC), not the refits' few
        dozen global columns, which barely change its spectrum.
    found : list or None
        If given, an :class:`Interference` describing what was removed is appended to it.
    """
    i = np.asarray(current_a, dtype=np.float64)
    th = np.asarray(theta_e_rad, dtype=np.float64)
    if i.shape != th.shape or i.ndim != 1:
        raise ValueError("current_a and theta_e_rad must be 1-D arrays of the same length")
    m = max(1, int(round(knot_spacing_s * rate_hz)))
    if i.size < 4 * m:
        raise ValueError("record shorter than four spline knots")
    # the current less its DC, with unit white noise beside it when the estimator's noise is asked for (scaled to
    # the floor at the end): both right-hand sides of the fits, as the columns of Y (each contiguous)
    Yt = np.empty((1 if noise_seed is None else 2, i.size))
    y = np.subtract(i, offset.dc_a, out=Yt[0])
    if noise_seed is not None:
        np.random.default_rng(noise_seed).standard_normal(out=Yt[1])
    Y = y if noise_seed is None else Yt.T
    phi = th + offset.theta0_rad
    g, cos_phi = trig.sin_cos(phi)
    np.negative(g, out=g)
    tn = np.linspace(-1.0, 1.0, y.size)
    offset = SlowOffset(y.size, OFFSET_KNOT_S * rate_hz)  # the slow offset's columns, then the angle columns and lines
    nd = offset.count
    cols = np.empty((3, y.size))
    r_band = spline_factor(g, m, smoothing)  # the spline's normal matrix depends on g alone: factored once
    iq1, _ = spline_fit(Y, g, m, r_band, np.ones((1, y.size)))
    # the noise through the first pass only: the later passes' global columns (slow offset, angle, lines: a few dozen
    # degrees of freedom among ~10⁵ spline coefficients) change its spectrum far less than its own scatter between
    # Welch segments, and would cost a second right-hand side in every refit
    iq1, noise_iq = (iq1, None) if Y.ndim == 1 else (iq1[:, 0], iq1[:, 1])
    w_e = np.gradient(th) * rate_hz

    def angle_columns(iq_a: np.ndarray) -> None:
        np.multiply(iq_a, cos_phi, out=cols[0])
        np.negative(cols[0], out=cols[0])
        np.multiply(cols[0], w_e, out=cols[1])
        np.multiply(cols[1], tn, out=cols[2])

    angle_columns(iq1)
    lines_hz: list[float] = []
    for round_ in range(LINE_ROUNDS + 1):  # a strong line's leak into the first fit can hide weaker ones
        iq, beta = spline_fit(y, g, m, r_band, cols, offset)
        offset_a = offset.curve(beta[:nd])
        resid = g * iq  # y − g·i_q − offset − Σ β·x, in place (the same operations in the same order)
        np.subtract(y, resid, out=resid)
        resid -= offset_a
        resid -= beta[nd:] @ cols
        if round_ == LINE_ROUNDS:
            break
        new = [f for f in _interference_lines(resid, rate_hz) if all(abs(f - h) > 1.0 for h in lines_hz)]
        new = new[:MAX_LINES - len(lines_hz)]
        if not new:
            break
        lines_hz += new
        cols = np.concatenate((cols, *(_tone_columns(f, rate_hz, tn) for f in new)))
        angle_columns(iq)  # the lines leaked into the first i_q, and so into the angle columns
    # the noise floor of the final residual: with the lines removed (left in, a line's leak raised the
    # floor and the noise model biased K by −2 % with 25 mA tones on a 10 kS/s current)
    sigma = _broadband_noise_rms(resid, rate_hz, m) if noise_iq is not None else float("nan")
    if found is not None:
        found.append(replace(_interference_found(lines_hz, beta[nd + 3:], offset_a, w_e), noise_rms_a=sigma))
    if noise_iq is None:
        return k_t_Nm_per_A * iq
    out = np.empty((2, y.size))
    np.multiply(iq, k_t_Nm_per_A, out=out[0])
    np.multiply(noise_iq, sigma, out=out[1])
    out[1] *= k_t_Nm_per_A
    return out


def angle_information_std(theta_e_rad: np.ndarray, theta0_rad: float, rate_hz: float, k_t_Nm_per_A: float,
                          noise_rms_a: float, resolution_s: float) -> np.ndarray:
    """Standard error, N·m, of the one-phase torque (:func:`torque_encoder`) at each sample, from what the phase
    carries about i_q near it: k_t·σ / √(Σ sin²(θ_e + θ_0)) over the ``resolution_s`` centred on the sample.

    i_a = −i_q·sin(θ_e + θ_0) + noise, so a least-squares i_q over the samples of one resolution cell has the
    variance σ²/Σ sin²: wherever the motor holds or slowly changes its torque at an electrical angle where
    sin(θ_e + θ_0) ≈ 0 this grows without bound, and the spline's penalty, not the current, decides the torque
    there. The noise realisation of :func:`torque_encoder` cannot show it: the penalty that bridges such a hole
    keeps the noise small there and turns the missing information into a bias instead.

    Parameters
    ----------
    theta_e_rad : ndarray
        Electrical angle at the samples, rad.
    theta0_rad : float
        Electrical offset θ_0 (mod π suffices), rad.
    rate_hz : float
        Sampling rate, Hz.
    k_t_Nm_per_A : float
        Torque constant, N·m/A.
    noise_rms_a : float
        The phase's noise per sample besides the torque (:attr:`Interference.noise_rms_a`), A.
    resolution_s : float
        The time resolution asked of the torque, s (half the period of the highest frequency used).
    """
    cell = max(1, int(round(resolution_s * rate_hz)))
    information = uniform_filter1d(np.sin(np.asarray(theta_e_rad, dtype=np.float64) + theta0_rad) ** 2, cell,
                                   mode="nearest") * cell
    with np.errstate(divide="ignore"):
        return k_t_Nm_per_A * noise_rms_a / np.sqrt(information)


# Knot spacing of the sensor-offset spline, s: a thermal drift of a Hall sensor's offset is slower
# than this (seconds to minutes); faster changes are not an offset. Each knot is one more column of
# the first pass (cost ∝ columns × samples), so no finer than needed.
OFFSET_KNOT_S = 2.0
# A line stands out of the residual's Welch PSD (1 Hz bins) when it exceeds LINE_FACTOR times the
# median of its ±LINE_NEIGHBOURS bins. With ≥ 10 averaged segments a noise bin exceeds 10× its
# median with a probability far below 1e-9, so the detector does not fire on noise; a false line
# would cost only four columns. At most MAX_LINES lines, the strongest, found in LINE_ROUNDS rounds
# (each refits with the lines found so far, then looks again).
LINE_FACTOR = 10.0
LINE_NEIGHBOURS = 25
MAX_LINES = 8
LINE_ROUNDS = 2
LINE_MIN_HZ = 2.0
# A line is inseparable when the spline i_q·sin(θ_e + θ_0) can mimic more than this share of its
# power: the joint fit then leaves the line's amplitude, and so the torque, undetermined.
INSEPARABLE_SHARE = 0.9


@dataclass(frozen=True)
class Interference:
    """What :func:`torque_encoder` removed from one phase current besides the torque.

    Attributes
    ----------
    lines_hz : tuple of float
        Frequencies of the lines removed, Hz.
    amplitude_a : tuple of float
        Their amplitudes, A (at the record's middle).
    inseparable_hz : tuple of float
        The lines the torque model can mimic (the electrical frequency dwells near them): their
        amplitude, and the torque where they are, cannot be told apart.
    offset_drift_a : float
        Peak-to-peak excursion of the sensor offset over the record, A.
    noise_rms_a : float
        RMS of white noise with the final residual's broadband floor (:func:`_broadband_noise_rms`), A: what the
        phase carries besides the torque and the removed interference, per sample; NaN when the torque's noise
        realisation was not asked for (:func:`torque_encoder`'s ``noise_seed``).
    """

    lines_hz: tuple[float, ...]
    amplitude_a: tuple[float, ...]
    inseparable_hz: tuple[float, ...]
    offset_drift_a: float
    noise_rms_a: float = float("nan")


def _interference_lines(resid_a: np.ndarray, rate_hz: float) -> list[float]:
    """Frequencies, Hz, of narrow lines standing out of the residual's spectrum (strongest first).

    Found in a Welch PSD with 1 Hz bins, then located to a small fraction of the record's
    resolution on the zero-padded periodogram of the whole residual (parabolic interpolation of
    the peak), since a sine fitted over a record of T seconds must be within ≪ 1/T of the line.
    """
    nper = min(resid_a.size, int(rate_hz))
    if resid_a.size < 4 * nper:
        return []
    f, psd = welch.psd(resid_a, rate_hz, nper)
    ref = median_filter(psd, size=2 * LINE_NEIGHBOURS + 1, mode="nearest")
    peaks, _ = find_peaks(psd, height=LINE_FACTOR * ref, distance=3)
    peaks = peaks[(f[peaks] >= LINE_MIN_HZ) & (f[peaks] <= 0.49 * rate_hz)]
    peaks = peaks[np.argsort(psd[peaks] / ref[peaks])[::-1][:MAX_LINES]]
    if peaks.size == 0:
        return []
    nfft = 4 * resid_a.size
    spec = np.abs(np.fft.rfft(resid_a * np.hanning(resid_a.size), nfft))
    out = []
    for fp in f[peaks]:
        c = int(round(fp * nfft / rate_hz))
        lo, hi = max(1, c - 8 * nfft // nper), min(spec.size - 2, c + 8 * nfft // nper)
        j = lo + int(np.argmax(spec[lo:hi + 1]))
        a, b, d = np.log(spec[j - 1:j + 2] + 1e-300)
        delta = 0.5 * (a - d) / (a - 2 * b + d) if a - 2 * b + d < 0 else 0.0
        out.append(float((j + delta) * rate_hz / nfft))
    return out


def _tone_columns(f_hz: float, rate_hz: float, tn: np.ndarray) -> np.ndarray:
    """sin, cos of a line at ``f_hz`` and the same times the normalised time ``tn`` (−1…1), one row each."""
    arg = 2.0 * np.pi * f_hz / rate_hz * np.arange(tn.size)
    s, c = np.sin(arg), np.cos(arg)
    return np.stack((s, c, s * tn, c * tn))


def _interference_found(lines_hz: list[float], beta_tones: np.ndarray, offset_a: np.ndarray,
                        w_e_rad_s: np.ndarray) -> Interference:
    """Amplitudes of the removed lines, the offset's excursion, and which lines are inseparable.

    A line at f is inseparable from the torque term when the electrical frequency |ω_e|/2π dwells
    near f: there i_q·sin(θ_e + θ_0) with a slowly varying i_q is the line itself, and the fit can
    put the line into either. It counts as inseparable when |ω_e|/2π is within 1 Hz of f (about
    the torque's own spectral detail over a Welch segment) for more than 1 − INSEPARABLE_SHARE of
    the record; a ramp sweeping through f passes in milliseconds.
    """
    amps = tuple(float(np.hypot(*beta_tones[4 * k:4 * k + 2])) for k in range(len(lines_hz)))
    inseparable: tuple[float, ...] = ()
    if lines_hz:  # the electrical frequency at every sample only when there is a line to test
        f_e = np.abs(w_e_rad_s) / (2.0 * np.pi)
        inseparable = tuple(f for f in lines_hz if np.mean(np.abs(f_e - f) < 1.0) > 1.0 - INSEPARABLE_SHARE)
    return Interference(tuple(lines_hz), amps, inseparable, float(np.ptp(offset_a)))


def _broadband_noise_rms(resid_a: np.ndarray, rate_hz: float, m: int) -> float:
    """RMS of white noise with the first-pass residual's broadband floor, A.

    The floor is the median of the residual's Welch PSD above twice the spline's bandwidth (≈ rate/(2m)),
    where the spline absorbs none of the noise, and where narrow lines — PWM ripple at the switching
    frequency, which the spline filters out of the torque anyway — are outliers the median ignores. The
    residual's RMS instead counts such ripple as broadband noise (a 3 % ripple biased K by −2…−5 %) and,
    below the bandwidth, misses what the spline absorbed.
    """
    # no detrending: a segment's mean leaks into bins 0 and 1 of the (periodic) Hann window only, far below the floor's
    f, psd = welch.psd(resid_a, rate_hz, min(resid_a.size, 4096), detrend=None)
    floor = psd[(f >= rate_hz / m) & (f <= 0.45 * rate_hz)]
    if floor.size < 8:
        return 1.4826 * float(np.median(np.abs(resid_a - np.median(resid_a))))
    return float(np.sqrt(np.median(floor) * rate_hz / 2.0))
