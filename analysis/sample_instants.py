"""When the drive really sampled the encoder: its own time stamps, or the jitter estimated from the data.

A drive that latches its position when SYNC arrives samples at k·T + δ_k, not at k·T: a software SYNC
jitters by 10–1000 µs. At speed ω that is a position error ω·δ_k, white in k, which the backward
difference turns into speed noise rising with frequency — it lowers the coherence and scatters J_m.

* With the drive's time stamps (serial frame drive time, CANopen 0x1013 mapped in the TPDO) each
  position is moved to its nominal instant k·T (:func:`angle_at_nominal_instants`) rather than the
  torque resampled onto the irregular instants: the rest of the chain (backward difference, its
  response divided out of the FRF, the angle spline for demodulation and clock alignment, Welch) is
  built on a regular grid and stays exact there. The shift is a small fraction of T, so reading a
  cubic spline through the irregular samples at k·T is θ(t_k) − ω·δ_k − ½α·δ_k² + O(δ³) with the local
  speed and acceleration of the data themselves. The stamps' constant offset (a latency, another
  clock origin) and their rate relative to T are removed by a straight-line fit against k, so only
  their scatter δ_k counts; their 1 µs quantisation adds 0.29 µs RMS, far below the jitter it fixes.
* Without stamps :func:`estimate_jitter` measures σ_δ from the position noise that grows with |ω|:
  the third difference of the angle removes the smooth motion up to a parabola, and its variance,
  20·(σ_q² + ω²·σ_δ²) for white errors, is regressed on the local ω² (robust per-bin variances, so
  the rare jerks at the profile's corners do not count). :meth:`EncoderJitter.speed_noise_psd` is the
  speed noise that σ_δ predicts, which the verdict compares with the measured speed spectrum.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.interpolate import CubicSpline

from analysis.encoder import quantisation_speed_psd

THIRD_DIFFERENCE = np.array([-1.0, 3.0, -3.0, 1.0])  # its weights, oldest sample first
_D3_GAIN = float(np.sum(THIRD_DIFFERENCE**2))  # 20: variance gain of the third difference on white errors
_BINS = 16
QUANTISATION_COUNTS = 2.0  # counts a cycle above which neighbouring quantisation errors count as independent
_MEDIAN_CHI2_1 = 0.454936  # median of χ²(1): median(x²) = 0.4549·σ² for Gaussian x


@dataclass(frozen=True)
class EncoderJitter:
    """The encoder's sample-instant jitter as the data show it.

    Attributes
    ----------
    sigma_s : float
        RMS scatter of the sample instants around k·T, s, that remains in the positions analysed
        (after the drive's time stamps, when they were used).
    mean_speed2 : float
        Mean squared motor speed over the samples, (rad/s)²: the jitter's speed noise scales with it.
    stamped : bool
        True when the drive's own time stamps moved the samples to k·T.
    stamp_spread_s : float
        RMS deviation of the drive's time stamps from the regular grid, s (NaN without stamps): the
        jitter the stamps corrected.
    lsb_rad : float
        One encoder count, rad (0: not known).
    locked_share : float
        Share (0…1) of the quantisation error that repeats one motion period later
        (:func:`analysis.quantisation_lock.locked_share`); NaN: not measured.
    """

    sigma_s: float
    mean_speed2: float
    stamped: bool
    stamp_spread_s: float = float("nan")
    lsb_rad: float = 0.0
    locked_share: float = float("nan")

    @property
    def repeating_share(self) -> float:
        """:attr:`locked_share`, or 1 (all of it repeats, the cautious reading) where it was not measured."""
        return self.locked_share if np.isfinite(self.locked_share) else 1.0

    def speed_noise_psd(self, f_hz: np.ndarray, period_s: float) -> np.ndarray:
        """One-sided PSD, (rad/s)²/Hz, of the backward-difference speed noise the jitter causes.

        Position errors e_k = ω·δ_k (white, variance ω²σ_δ²) through (1 − z⁻¹)/T:
        2T·ω²σ_δ²·4 sin²(πfT)/T².
        """
        s = np.sin(np.pi * np.asarray(f_hz, dtype=np.float64) * period_s)
        return 8.0 * self.mean_speed2 * self.sigma_s**2 * s * s / period_s

    def quantisation_noise_psd(self, f_hz: np.ndarray, period_s: float) -> np.ndarray:
        """One-sided PSD, (rad/s)²/Hz, of the backward-difference speed noise of the position's quantisation
        (:func:`analysis.encoder.quantisation_speed_psd`)."""
        return quantisation_speed_psd(f_hz, period_s, self.lsb_rad)


#: The largest deviation of a sample instant from its cycle grid, as a share of the cycle T, that the analysis takes
#: for a jitter around the grid: the spline move (:func:`angle_at_nominal_instants`) reads θ(t_k) − ω·δ_k − ½α·δ_k²
#: + O(δ³), which needs δ a small fraction of T, and a stamp half a cycle off could as well belong to the neighbouring
#: cycle. One deviation this large makes :func:`stamp_deviation_s` refuse all of a record's stamps.
MAX_STAMP_DEVIATION = 0.5


def cycle_deviation_s(index: np.ndarray, times_s: np.ndarray, period_s: float) -> np.ndarray | None:
    """Deviation of each cycle's time from the regular grid, s, in units of k·T.

    A straight line a + b·k fitted to the times is the grid (its offset and rate are the clock's, not the cycles'):
    δ_k = (t_k − a − b·k)·T/b. None when there is no grid to fit: fewer than 4 times, one not finite, or a rate
    that is not positive.

    Parameters
    ----------
    index : ndarray of int
        Cumulative cycle k of each time (gap-free or not).
    times_s : ndarray
        The time of each cycle, s (a drive's time stamps, or host stamps).
    period_s : float
        Cycle T, s.
    """
    t = np.asarray(times_s, dtype=np.float64)
    k = np.asarray(index, dtype=np.float64)
    if t.size < 4 or not np.all(np.isfinite(t)):
        return None
    kc, tc = k - k.mean(), t - t.mean()
    rate = float(np.dot(kc, tc) / np.dot(kc, kc))
    if not rate > 0:
        return None
    return (tc - rate * kc) * (period_s / rate)


def stamp_deviation_s(index: np.ndarray, drive_time_s: np.ndarray, period_s: float) -> np.ndarray | None:
    """Deviation of each sample's drive time stamp from the regular grid, s (:func:`cycle_deviation_s`). None when
    the stamps cannot be used: no grid to fit, or a deviation of :data:`MAX_STAMP_DEVIATION` of a period or more (not a
    jitter around the grid).

    Parameters
    ----------
    index : ndarray of int
        Cumulative drive cycle k of each sample (gap-free or not).
    drive_time_s : ndarray
        The drive's time stamp of each sample, s.
    period_s : float
        Drive cycle T, s.
    """
    dev = cycle_deviation_s(index, drive_time_s, period_s)
    if dev is None:
        return None
    return dev if np.max(np.abs(dev)) < MAX_STAMP_DEVIATION * period_s else None


def angle_at_nominal_instants(theta_rad: np.ndarray, index: np.ndarray, period_s: float,
                              deviation_s: np.ndarray) -> np.ndarray:
    """The angle at k·T from samples taken at k·T + δ_k: a cubic spline through them, read at k·T, rad.

    Parameters
    ----------
    theta_rad : ndarray
        Angle sampled at the true instants, rad (gap-free, one per cycle).
    index : ndarray of int
        Drive cycle k of each sample.
    period_s : float
        Drive cycle T, s.
    deviation_s : ndarray
        δ_k, s (:func:`stamp_deviation_s`).
    """
    t_nominal = (np.asarray(index, dtype=np.float64) - index[0]) * period_s
    return CubicSpline(t_nominal + deviation_s, theta_rad)(t_nominal)


def third_difference(x: np.ndarray) -> np.ndarray:
    """d[i] = x[i+3] − 3x[i+2] + 3x[i+1] − x[i]: removes a motion up to a parabola, keeps white errors ×20 in
    variance (length ``x.size − 3``)."""
    return np.convolve(x, THIRD_DIFFERENCE[::-1], mode="valid")


def estimate_jitter(theta_rad: np.ndarray, period_s: float, *, lsb_rad: float = 0.0, stamped: bool = False,
                    stamp_spread_s: float = float("nan")) -> EncoderJitter:
    """σ_δ from the growth of the angle's high-pass noise with speed (see the module docstring).

    Parameters
    ----------
    theta_rad : ndarray
        Angle on the regular grid k·T, rad (gap-free).
    period_s : float
        Drive cycle T, s.
    lsb_rad : float, optional
        One count of the encoder, rad. Only samples where the position moves at least
        ``QUANTISATION_COUNTS`` counts a cycle are regressed: there the quantisation errors of
        neighbouring samples are nearly independent (variance lsb²/12 whatever the speed), while slower
        they are correlated and their third difference grows with speed — which would read as jitter
        (≈ 3 µs on a 10 000-count encoder that has none). 0: every sample.
    stamped, stamp_spread_s
        Passed through to :class:`EncoderJitter`.
    """
    th = np.asarray(theta_rad, dtype=np.float64)
    speed = np.gradient(th, period_s)
    mean_speed2 = float(np.mean(speed**2)) if th.size else float("nan")
    if th.size < 8 * _BINS:
        return EncoderJitter(float("nan"), mean_speed2, stamped, stamp_spread_s, lsb_rad)
    d3 = third_difference(th)
    w2 = np.convolve(speed**2, THIRD_DIFFERENCE[::-1] ** 2, mode="valid") / _D3_GAIN  # ω² seen by each d3, weighted
    fast = np.abs(speed) * period_s >= QUANTISATION_COUNTS * lsb_rad
    n3 = THIRD_DIFFERENCE.size
    usable = np.flatnonzero(np.convolve(fast, np.ones(n3), mode="valid") == n3)
    if usable.size < 8 * _BINS:
        return EncoderJitter(float("nan"), mean_speed2, stamped, stamp_spread_s, lsb_rad)
    d3, w2 = d3[usable], w2[usable]
    order = np.argsort(w2)
    groups = np.array_split(order, _BINS)
    x = np.array([np.mean(w2[g]) for g in groups])
    var = np.array([np.median(d3[g] ** 2) / _MEDIAN_CHI2_1 for g in groups]) / _D3_GAIN
    if not (np.max(var) > 0.0 and np.ptp(x) > 0.0):  # a joint at rest (or at one speed): nothing to regress on
        return EncoderJitter(float("nan"), mean_speed2, stamped, stamp_spread_s, lsb_rad)
    # var = σ_q² + σ_δ²·ω²; each bin's variance estimate has a relative scatter ∝ its value: weights 1/var²
    weights = 1.0 / np.maximum(var, 1e-3 * np.max(var) + np.finfo(float).tiny) ** 2
    design = np.column_stack([np.ones_like(x), x])
    coef = np.linalg.lstsq(design * np.sqrt(weights)[:, None], var * np.sqrt(weights), rcond=None)[0]
    return EncoderJitter(float(np.sqrt(max(coef[1], 0.0))), mean_speed2, stamped, stamp_spread_s, lsb_rad)
