"""Electromagnetic torque T_e = k_t·i_q from the measured phase currents (design §5.1).

Motor model (i_d = 0): i_a = −i_q·sin(θ_e + θ_0) + dc, i_b and i_c shifted by ∓2π/3, where θ_e = p·θ_m
is the encoder's electrical angle at the DAQ instants (mapped through the clock fit) and θ_0 the
motor's electrical offset. All functions return torque at the DAQ samples they were given.

* :func:`torque_hilbert` — the paper's baseline: k_t·|hilbert(i_a)| with a sign per sample.
* :func:`torque_encoder` — one phase, demodulated with the encoder angle: i_q is a cubic B-spline in
  time fitted by penalised least squares to i_a. Every sample counts with weight sin²(θ_e + θ_0), so
  where the phase carries no information (|sin| small) the spline is carried by its neighbours instead
  of an explicit interpolation; the penalty only bridges those holes. No speed enters the estimate.
* :func:`torque_park` — two or three phases, Clarke + Park with the encoder angle, exact.

θ_0 is known from one phase only modulo π (the sign of i_q and θ_0 + π give the same current);
:func:`phase_offset` returns θ_0 in (−π/2, π/2] and the caller fixes the sign (one bit) from the motion.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from scipy.ndimage import median_filter, uniform_filter1d
from scipy.signal import butter, find_peaks, hilbert, sosfiltfilt

from analysis import trig, welch
from analysis.torque_spline import SlowOffset, spline_factor, spline_fit

_SQRT3 = np.sqrt(3.0)


@dataclass(frozen=True)
class WindowPhasors:
    """Least-squares fits i ≈ a·sin θ_e + b·cos θ_e + c over consecutive windows.

    Attributes
    ----------
    centre_index : ndarray of float
        Sample position of each window's centre (0 = first sample given).
    phasor_a : ndarray of complex
        a + j·b, A; for i = −i_q·sin(θ_e + θ_0) + dc this is −i_q·e^{jθ_0}.
    dc_a : ndarray of float
        c, A.
    valid : ndarray of bool
        The window's angle spans at least ``min_span_rad`` (else the fit is ill-posed; values NaN).
    """

    centre_index: np.ndarray
    phasor_a: np.ndarray
    dc_a: np.ndarray
    valid: np.ndarray


@dataclass(frozen=True)
class PhaseOffset:
    """Electrical offset and sensor DC of one phase.

    Attributes
    ----------
    theta0_rad : float
        θ_0 modulo π, in (−π/2, π/2], rad.
    dc_a : float
        Sensor DC offset, A.
    n_windows : int
        Windows that carried the estimate.
    """

    theta0_rad: float
    dc_a: float
    n_windows: int


def window_phasors(current_a: np.ndarray, theta_e_rad: np.ndarray, window_len: int,
                   min_span_rad: float = np.pi) -> WindowPhasors:
    """Fit a·sin θ_e + b·cos θ_e + c to ``current_a`` over consecutive windows of ``window_len`` samples.

    Parameters
    ----------
    current_a : ndarray
        One phase current, A.
    theta_e_rad : ndarray
        Electrical angle at the same samples, rad.
    window_len : int
        Samples per window (a trailing remainder is dropped).
    min_span_rad : float
        Smallest angle excursion in a window for its fit to count, rad.
    """
    i = np.asarray(current_a, dtype=np.float64)
    th = np.asarray(theta_e_rad, dtype=np.float64)
    if i.shape != th.shape or i.ndim != 1:
        raise ValueError("current_a and theta_e_rad must be 1-D arrays of the same length")
    if window_len < 8:
        raise ValueError(f"window_len must be at least 8 samples, got {window_len}")
    nw = i.size // window_len
    i = i[: nw * window_len].reshape(nw, window_len)
    th = th[: nw * window_len].reshape(nw, window_len)
    s, c = trig.sin_cos(th)
    M = np.empty((nw, 3, 3))
    M[:, 0, 0] = np.einsum("ij,ij->i", s, s)
    M[:, 1, 1] = np.einsum("ij,ij->i", c, c)
    M[:, 0, 1] = M[:, 1, 0] = np.einsum("ij,ij->i", s, c)
    M[:, 0, 2] = M[:, 2, 0] = s.sum(axis=1)
    M[:, 1, 2] = M[:, 2, 1] = c.sum(axis=1)
    M[:, 2, 2] = window_len
    rhs = np.stack([np.einsum("ij,ij->i", s, i), np.einsum("ij,ij->i", c, i), i.sum(axis=1)], axis=1)
    valid = (th.max(axis=1) - th.min(axis=1)) >= min_span_rad
    sol = np.full((nw, 3), np.nan)
    if valid.any():
        sol[valid] = np.linalg.solve(M[valid], rhs[valid, :, None])[..., 0]
    centre = (np.arange(nw) + 0.5) * window_len - 0.5
    return WindowPhasors(centre, sol[:, 0] + 1j * sol[:, 1], sol[:, 2], valid)


#: Window of :func:`phase_offset`, s: the motor must turn half an electrical revolution within it.
PHASE_WINDOW_S = 0.02


def min_speed_rpm(pole_pairs: int, window_s: float = PHASE_WINDOW_S) -> float:
    """Slowest motor speed, rpm, that turns half an electrical revolution (1/(2·pole_pairs) rev) within ``window_s``:
    the joint must run faster for that long at a time or :func:`phase_offset` cannot estimate θ_0."""
    return 60.0 * 0.5 / pole_pairs / window_s


def phase_offset(current_a: np.ndarray, theta_e_rad: np.ndarray, rate_hz: float,
                 window_s: float = PHASE_WINDOW_S, pole_pairs: int | None = None,
                 commanded: bool = True) -> PhaseOffset:
    """Estimate θ_0 (mod π) and the sensor DC of one phase by windowed least squares.

    θ_0 is the argument of Σ phasor² / 2 (each window weighted by i_q²); dc the median of the windows'
    constants. Windows where the motor moves less than π electrical are skipped.

    Parameters
    ----------
    current_a, theta_e_rad : ndarray
        Phase current, A, and electrical angle at the same samples, rad.
    rate_hz : float
        Sampling rate, Hz.
    window_s : float
        Window length, s.
    pole_pairs : int, optional
        The motor's pole pairs: the error then says how fast the motor must run.
    commanded : bool
        acq commanded the motion (the error's advice is the profile's); False: a machine's own program moved the
        joint (the advice is to record while it runs fast moves — there is no profile to change).
    """
    w = window_phasors(current_a, theta_e_rad, max(8, int(round(window_s * rate_hz))))
    if not w.valid.any():
        need = "" if pole_pairs is None else (
            f": the motor must run faster than {min_speed_rpm(pole_pairs, window_s):.0f} rpm for {1e3 * window_s:.0f} ms "
            f"at a time ({pole_pairs} pole pairs) — " + (
                "raise the profile's top_speed_rpm, and lengthen accel_time_s and decel_time_s if the drive cannot "
                "follow them" if commanded else "record while the machine runs fast moves of this joint"))
        raise ValueError(f"the motor never turns half an electrical revolution within {1e3 * window_s:.0f} ms, so the "
                         f"current's phase (θ_0) and DC cannot be estimated{need}")
    z = np.sum(w.phasor_a[w.valid] ** 2)
    return PhaseOffset(float(np.angle(z) / 2.0), float(np.median(w.dc_a[w.valid])), int(w.valid.sum()))


def apex_sign(speed_rad_s: np.ndarray, period_s: float, smooth_hz: float = 20.0) -> np.ndarray:
    """Sign of the torque restored at the speed apexes (paper §3.2), ±1 per speed sample.

    Between two apexes (extrema of the speed above half its peak) the sign is that of the speed change
    from one apex to the next; before the first apex it heads towards it, after the last away from it.
    The speed is only used to place the sign flips, never to shape the torque.

    Parameters
    ----------
    speed_rad_s : ndarray
        Motor speed, rad/s, on the drive's grid.
    period_s : float
        Drive cycle, s.
    smooth_hz : float
        Cut-off of the zero-phase low-pass applied before looking for apexes, Hz.
    """
    w = np.asarray(speed_rad_s, dtype=np.float64)
    if w.size < 32:
        raise ValueError("need at least 32 speed samples to find apexes")
    ws = sosfiltfilt(butter(2, smooth_hz, fs=1.0 / period_s, output="sos"), w)
    height = 0.5 * np.max(np.abs(ws))
    distance = max(1, int(0.05 / period_s))
    hi, _ = find_peaks(ws, height=height, distance=distance)
    lo, _ = find_peaks(-ws, height=height, distance=distance)
    apex = np.sort(np.concatenate((hi, lo)))
    if apex.size == 0:
        return np.full(w.size, 1.0 if ws[-1] >= ws[0] else -1.0)
    sign = np.empty(w.size)
    sign[: apex[0]] = np.sign(ws[apex[0]])
    for a, b in zip(apex[:-1], apex[1:]):
        sign[a:b] = 1.0 if ws[b] > ws[a] else -1.0
    sign[apex[-1]:] = -np.sign(ws[apex[-1]])
    sign[sign == 0] = 1.0
    return sign


def torque_hilbert(current_a: np.ndarray, k_t_Nm_per_A: float, sign: np.ndarray) -> np.ndarray:
    """The paper's torque: T_e = sign·k_t·|hilbert(i_a − mean)|, N·m.

    Parameters
    ----------
    current_a : ndarray
        One phase current, A.
    k_t_Nm_per_A : float
        Torque constant, N·m/A.
    sign : ndarray
        ±1 per sample (e.g. :func:`apex_sign` mapped onto the DAQ instants).
    """
    i = np.asarray(current_a, dtype=np.float64)
    if np.shape(sign) != i.shape:
        raise ValueError("sign must have one entry per current sample")
    return k_t_Nm_per_A * np.asarray(sign) * np.abs(hilbert(i - i.mean()))


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
    with np.errstate(divide="ignore", invalid="ignore"):  # no information: unknown (∞) even with no noise (σ = 0)
        return np.where(information > 0.0, k_t_Nm_per_A * noise_rms_a / np.sqrt(information), np.inf)


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


@dataclass(frozen=True)
class PhaseGains:
    """Relative sensor gains of three recorded phases, each divided by their mean (the common scale is k_t's).

    Attributes
    ----------
    gain : dict
        Phase name → gain / mean gain of the three phases.
    sigma : dict
        Phase name → standard error of that ratio (block jackknife).
    n_samples : int
        Samples that carried the estimate.
    """

    gain: dict[str, float]
    sigma: dict[str, float]
    n_samples: int


def phase_gains(currents_a: dict[str, np.ndarray], blocks: int = 10) -> PhaseGains | None:
    """Relative sensor gains of three phases from i_a + i_b + i_c = 0; None with fewer than three phases.

    The motor's currents sum to zero at every instant (star point not connected — the usual drive), so
    the measured m_x = g_x·i_x + dc_x satisfy Σ m_x / g_x = const. The vector (1/g_a, 1/g_b, 1/g_c) is the
    direction in which the centred currents have least variance: the smallest eigenvector of their 3×3
    covariance (total least squares — the sensors' noise enters all three alike). No angle and no model
    of the torque enter. The standard error is a jackknife over ``blocks`` contiguous pieces (a choice of
    resolution, not a tuned value: ~10 pieces leave each enough motion).

    Parameters
    ----------
    currents_a : dict
        ``"i_a"``, ``"i_b"``, ``"i_c"`` at the same samples, A.
    blocks : int
        Pieces of the jackknife.
    """
    names = ("i_a", "i_b", "i_c")
    if not all(n in currents_a for n in names):
        return None
    m = np.stack([np.asarray(currents_a[n], dtype=np.float64) for n in names])
    m = m - m.mean(axis=1, keepdims=True)
    n = m.shape[1] // blocks * blocks
    scatter = np.einsum("ibk,jbk->bij", m[:, :n].reshape(3, blocks, -1), m[:, :n].reshape(3, blocks, -1))

    def gains(s: np.ndarray) -> np.ndarray:
        inv = np.linalg.eigh(s)[1][:, 0]  # ∝ 1/g, sign arbitrary
        g = 1.0 / inv
        return g / g.mean()

    total = scatter.sum(axis=0)
    g = gains(total)
    jack = np.array([gains(total - s) for s in scatter])
    se = np.sqrt((blocks - 1) / blocks * np.sum((jack - jack.mean(axis=0)) ** 2, axis=0))
    return PhaseGains({k: float(v) for k, v in zip(names, g)}, {k: float(v) for k, v in zip(names, se)}, n)


def torque_park(currents_a: dict[str, np.ndarray], theta_e_rad: np.ndarray, k_t_Nm_per_A: float,
                theta0_rad: float, dc_a: dict[str, float], gain: dict[str, float] | None = None) -> np.ndarray:
    """Torque from two or three phases by Clarke + Park with the encoder angle, N·m.

    i_α = i_a, i_β = (i_b − i_c)/√3 (amplitude-invariant; i_c = −i_a − i_b when only a and b are
    recorded), i_q = −i_α·sin φ + i_β·cos φ with φ = θ_e + θ_0.

    Parameters
    ----------
    currents_a : dict
        ``"i_a"``, ``"i_b"`` and optionally ``"i_c"``, A.
    theta_e_rad : ndarray
        Electrical angle at the same samples, rad.
    k_t_Nm_per_A : float
        Torque constant, N·m/A.
    theta0_rad : float
        Electrical offset θ_0 (sign chosen), rad.
    dc_a : dict
        Sensor DC of each phase used, A.
    gain : dict, optional
        Relative sensor gain of each phase used (:func:`phase_gains`); the currents are divided by it.
    """
    if "i_a" not in currents_a or "i_b" not in currents_a:
        raise ValueError("park needs at least the phases i_a and i_b")
    g = gain or {}
    ia = (np.asarray(currents_a["i_a"], dtype=np.float64) - dc_a["i_a"]) / g.get("i_a", 1.0)
    ib = (np.asarray(currents_a["i_b"], dtype=np.float64) - dc_a["i_b"]) / g.get("i_b", 1.0)
    ic = ((np.asarray(currents_a["i_c"], dtype=np.float64) - dc_a["i_c"]) / g.get("i_c", 1.0)
          if "i_c" in currents_a else -ia - ib)
    i_alpha = (2.0 * ia - ib - ic) / 3.0
    i_beta = (ib - ic) / _SQRT3
    phi = np.asarray(theta_e_rad, dtype=np.float64) + theta0_rad
    return k_t_Nm_per_A * (-i_alpha * np.sin(phi) + i_beta * np.cos(phi))
