"""Offline alignment of the DAQ clock to the drive clock from the data itself (design §4).

Convention (shared with the simulator and the report): t_drive = offset_s + t_daq·(1 + drift_ppm·1e-6),
with t_daq = n / rate_hz for DAQ sample n and t_drive = k·T for drive cycle k.

Four stages, each narrowing the search of the next:

1. host: when both streams carry arrival stamps on one host clock (a recording, not two files from
   separate tools), the stamps give the relation to a few ms — if the transfer latencies are steady.
2. wide (:mod:`analysis.clock_search`): the current's electrical frequency against the encoder's over
   every plausible offset (±2 s around the host relation or, without one, around "started together"),
   one FFT correlation on a 10 ms grid. It always runs: host stamps farther from the data's alignment
   than the frequency stage reaches (a USB DAQ delivering blocks 50–150 ms late) are overruled. Offsets
   the data supports equally (whole periods of the motion apart) are resolved by the host stamps, or
   reported as ambiguous.
3. frequency: the electrical frequency carried by the current (zero-crossing rate of i_a) must equal
   p·|ω|/2π from the encoder (zero-crossing rate of sin θ_e); the lag between the two, found in
   windows along the record, gives offset and drift to a fraction of a ms. Independent of θ_0, of
   the torque's sign and of the plant.
4. angle: in short windows the phase of i_a against the encoder's electrical angle is θ_0 + p·ω·δ(t)
   where δ(t) is the remaining clock error; a coherent search then weighted least squares on
   2·phase (blind to the sign of i_q) fit offset, drift and θ_0 to µs.

No pair of crystal clocks drifts by more than :data:`MAX_DRIFT_PPM`: the frequency stage fits only the
offset where its slope would need more, and an angle fit that needs more is rejected (the next candidate
of the wide search, or the host relation, is taken; with none left the alignment fails, :attr:`ClockFit.failure`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Literal

import numpy as np
from scipy.interpolate import CubicSpline
from scipy.ndimage import median_filter

from analysis import trig
from analysis.clock_search import starting_relation, wide_search
from analysis.fit import Z95
from analysis.phase_offset import window_phasors

_CHUNK = 1 << 18  # samples per pass over the DAQ record (each pass holds ~15 float64 temporaries of this length: 30 MB)
_GRID_HZ = 1000.0  # grid of the frequency stage
_NARROW_S = 0.03  # half-range of the frequency stage's first pass around its starting relation, s
_ENVELOPE_PIECES = 8  # pieces of a record whose least-delayed host stamps give the host relation's slope
_SEARCH_STEP_S = 2.5e-5  # grid of the angle stage's coherent offset search, s
_PIECE_S = 2.0  # current the angle stage uses to tell the wide search's candidates apart, s
#: The largest drift, ppm, two free-running clocks can have against each other: the DAQ's timebase and the drive's
#: are crystal oscillators specified to ±50…100 ppm of nominal (over temperature and ageing), so two of them differ
#: by at most 200 ppm (design §4's plausible range, ±100 ppm, is the common pair of ±50 ppm parts). A fit needing
#: more has locked onto a wrong lag — on a robot's point-to-point moves the phase of i_a matches the encoder's
#: angle mod 2π at many relations, some of them stretched by percents. Drifts beyond this bound are rejected.
MAX_DRIFT_PPM = 200.0
# The angle stage demodulates block means of the current (see _block_means): at least this many blocks per
# electrical turn at the fastest speed, so the blocks lose ≤ 0.6 % of the sinusoid's amplitude and none of its
# phase; at most _MAX_BLOCK samples per block (each block's angle taken as linear in time).
_BLOCK_SAMPLES_PER_TURN = 16
_MAX_BLOCK = 8

ClockMethod = Literal["angle", "frequency", "wide", "host", "none"]


@dataclass(frozen=True)
class ClockFit:
    """The recovered relation t_drive = offset_s + t_daq·(1 + drift_ppm·1e-6).

    Attributes
    ----------
    offset_s : float
        Drive time of DAQ sample 0, s.
    drift_ppm : float
        Rate of the drive clock against the DAQ clock, ppm.
    residual_s : float
        Information-weighted RMS timing residual of the angle windows, s (NaN below the angle stage).
    offset_std_s, drift_std_ppm : float
        Standard errors of offset (at DAQ time 0), s, and drift, ppm (NaN below the angle stage).
    theta0_rad : float
        Electrical offset θ_0 modulo π from the angle stage, rad (NaN below it).
    host_offset_s, host_drift_ppm : float
        Stage 1 result from the host stamps (NaN without stamps).
    frequency_offset_s, frequency_drift_ppm : float
        Frequency stage result (NaN when the motion gave no usable window).
    n_windows : int
        Angle windows used in the final fit.
    method : {"angle", "frequency", "wide", "host", "none"}
        The last stage that succeeded ("none": streams taken as started together, no alignment).
    wide_offset_s : float
        The wide search's best offset, s (NaN when it found no motion on both sides).
    ambiguous_by_s : tuple of float
        Shifts, s, of the offset that fit the data as well (whole periods of the motion) and that no
        shared host clock resolved; empty when the offset is unique.
    notes : tuple of str
        What a person should know about the alignment (host stamps overruled, ambiguity).
    failure : str
        Why no alignment was found (every fit of the electrical angle needed a drift beyond
        :data:`MAX_DRIFT_PPM`); empty when the alignment did not fail. The relation is then the best
        guess left (frequency stage, host stamps, or "started together") and not to be trusted.
    """

    offset_s: float
    drift_ppm: float
    residual_s: float = np.nan
    offset_std_s: float = np.nan
    drift_std_ppm: float = np.nan
    theta0_rad: float = np.nan
    host_offset_s: float = np.nan
    host_drift_ppm: float = np.nan
    frequency_offset_s: float = np.nan
    frequency_drift_ppm: float = np.nan
    n_windows: int = 0
    method: ClockMethod = "none"
    wide_offset_s: float = np.nan
    ambiguous_by_s: tuple[float, ...] = ()
    notes: tuple[str, ...] = ()
    failure: str = ""

    def drive_time_s(self, t_daq_s: np.ndarray | float) -> np.ndarray:
        """Drive time, s, of DAQ time ``t_daq_s``, s."""
        return self.offset_s + np.asarray(t_daq_s) * (1.0 + self.drift_ppm * 1e-6)

    def daq_time_s(self, t_drive_s: np.ndarray | float) -> np.ndarray:
        """DAQ time, s, of drive time ``t_drive_s``, s."""
        return (np.asarray(t_drive_s) - self.offset_s) / (1.0 + self.drift_ppm * 1e-6)


def host_relation(daq_last_index: np.ndarray, daq_host_ns: np.ndarray, rate_hz: float,
                  encoder_index: np.ndarray, encoder_host_ns: np.ndarray, period_s: float) -> tuple[float, float]:
    """Stage 1: offset, s, and drift, ppm, from host arrival stamps.

    Each stream's host time is fitted as a line of its own time (DAQ: the last sample of each block;
    encoder: each sample), shifted to the 2nd percentile of the residual (the least-delayed
    arrivals), and the two lines are composed.

    Parameters
    ----------
    daq_last_index : ndarray of int
        DAQ sample index of the last sample of each block.
    daq_host_ns : ndarray of int
        Host monotonic time each block arrived, ns.
    rate_hz : float
        DAQ sample rate, Hz.
    encoder_index : ndarray of int
        Drive cycle of each encoder sample.
    encoder_host_ns : ndarray of int
        Host monotonic arrival time of each encoder sample, ns.
    period_s : float
        Drive cycle, s.
    """
    ref_ns = int(min(np.min(daq_host_ns), np.min(encoder_host_ns)))
    a_d, b_d = _lower_line(np.asarray(daq_last_index) / rate_hz, (np.asarray(daq_host_ns) - ref_ns) * 1e-9)
    a_e, b_e = _lower_line(np.asarray(encoder_index) * period_s, (np.asarray(encoder_host_ns) - ref_ns) * 1e-9)
    return (a_d - a_e) / b_e, (b_d / b_e - 1.0) * 1e6


def _lower_line(x: np.ndarray, y: np.ndarray) -> tuple[float, float]:
    """The line under the least-delayed arrivals: (intercept, slope) of host time ``y`` against stream time ``x``.

    Arrival delays are one-sided and bursty (a thread held off for 20 ms stamps a whole run late), so a
    least-squares slope through every stamp tilts by delay/duration — thousands of ppm on a 4 s record.
    As clock filters do (NTP keeps the minimum-delay sample), the slope is fitted through the least-delayed
    stamp of each of up to ``_ENVELOPE_PIECES`` equal pieces of the record; the intercept is then moved
    down to the 2nd percentile of the residual.
    """
    if x.size < 2:
        return float(np.min(y - x)), 1.0
    delay = y - x  # both in s: the nominal slope is 1
    pieces = np.array_split(np.arange(x.size), min(_ENVELOPE_PIECES, x.size))
    least = np.array([p[np.argmin(delay[p])] for p in pieces])
    b = np.polyfit(x[least], y[least], 1)[0]
    return float(np.percentile(y - b * x, 2.0)), float(b)


def current_crossings_s(current_a: np.ndarray, rate_hz: float, first_index: int = 0) -> np.ndarray:
    """DAQ times, s, at which one phase current crosses its DC level (with hysteresis).

    The hysteresis is 5× the white noise (from the second difference) or 2 % of the amplitude,
    whichever is larger, so quasi-DC stretches near reversals and standstill do not chatter.
    """
    i = np.asarray(current_a, dtype=np.float64)
    lo, hi = (percentile_without_copy(i, q) for q in (1.0, 99.0))
    noise = 1.4826 * np.median(np.abs(np.diff(i[: 1 << 18], 2))) / np.sqrt(6.0)
    return (first_index + _crossings(lambda a, b: i[a:b] - 0.5 * (lo + hi), i.size,
                                     max(5.0 * noise, 0.01 * (hi - lo)))) / rate_hz


def angle_crossings_s(angle: CubicSpline, pole_pairs: int, t_start_s: float, t_stop_s: float,
                      rate_hz: float = 10_000.0) -> np.ndarray:
    """Drive times, s, at which sin(p·θ_m) crosses zero, read from the angle spline at ``rate_hz``.

    The same estimator as :func:`current_crossings_s` (hysteresis 0.05), so biases cancel.
    """
    n = int((t_stop_s - t_start_s) * rate_hz)
    return t_start_s + _crossings(
        lambda a, b: trig.sin_cos(pole_pairs * angle(t_start_s + np.arange(a, b) / rate_hz))[0], n, 0.05) / rate_hz


def percentile_without_copy(x: np.ndarray, q: float) -> float:
    """``np.percentile(x, q)`` (linear interpolation) without copying ``x``.

    NumPy partitions a copy of the whole array (123 MB for 10 min at 25.6 kS/s); here the two order statistics
    around the q-th percentile are bracketed by a sorted subsample, the values inside the bracket gathered in
    chunks and sorted — widened until the bracket holds both (the last bracket holds every value). No library offers
    a copy-free exact percentile.
    """
    n = x.size
    if n <= 4 * _CHUNK:
        return float(np.percentile(x, q))
    pos = q / 100.0 * (n - 1)
    k = int(np.floor(pos))
    k1 = min(k + 1, n - 1)
    if any(np.isnan(x[s:s + _CHUNK]).any() for s in range(0, n, _CHUNK)):
        return float("nan")  # as NumPy
    sample = np.sort(x[:: n // 65536])
    j = int(round(q / 100.0 * (sample.size - 1)))
    for half in (64, 1024, sample.size):
        a = sample[j - half] if j - half >= 0 else -np.inf
        b = sample[j + half] if j + half < sample.size else np.inf
        below, inside = 0, []
        for s in range(0, n, _CHUNK):
            c = x[s:s + _CHUNK]
            below += int(np.count_nonzero(c < a))
            inside.append(c[(c >= a) & (c <= b)])
        vals = np.sort(np.concatenate(inside))
        if below <= k and k1 - below < vals.size:
            v0, v1 = vals[k - below], vals[k1 - below]
            return float(v0 + (pos - k) * (v1 - v0))
    raise AssertionError("unreachable: the last bracket holds every value")


def _crossings(chunk: Callable[[int, int], np.ndarray], n: int, h: float) -> np.ndarray:
    """Sample positions where a Schmitt trigger of threshold ±h on the chunked signal switches."""
    out, state = [np.empty(0, dtype=np.int64)], 0
    for a in range(0, n, _CHUNK):
        x = chunk(a, min(n, a + _CHUNK))
        s = (x > h).view(np.int8) - (x < -h).view(np.int8)  # +1 above, −1 below, 0 inside the hysteresis
        # the runs of equal values (few: the signal stays above, below or inside for many samples), then the decided
        # ones: a switch is a decided run whose value differs from the trigger's state before it (the previous one)
        first = np.concatenate(([0], np.flatnonzero(s[1:] != s[:-1]) + 1))
        vals = s[first]
        first, vals = first[vals != 0], vals[vals != 0]
        if not vals.size:
            continue
        switch = np.flatnonzero(vals[1:] != vals[:-1]) + 1
        if state != 0 and vals[0] != state:
            switch = np.concatenate(([0], switch))
        out.append(a + first[switch])
        state = int(vals[-1])
    return np.concatenate(out).astype(np.float64)


def crossing_frequency_hz(crossings_s: np.ndarray, grid_s: np.ndarray) -> np.ndarray:
    """Electrical frequency, Hz, on ``grid_s`` from half-period intervals between zero crossings.

    Each interval gives 1/(2·interval) at its midpoint; a 15-sample median filter removes the short
    spikes of an extra crossing (e.g. where i_q changes sign). Zero outside the crossings' span.
    """
    if crossings_s.size < 3:
        return np.zeros_like(grid_s)
    mid = 0.5 * (crossings_s[1:] + crossings_s[:-1])
    f = 0.5 / np.maximum(np.diff(crossings_s), 1e-6)
    return median_filter(np.interp(grid_s, mid, f, left=0.0, right=0.0), size=15, mode="nearest")


def frequency_alignment(f_current_hz: np.ndarray, t_daq_s: np.ndarray, f_encoder: Callable[[np.ndarray], np.ndarray],
                        offset_s: float, drift_ppm: float, max_lag_s: float,
                        window_s: float = 2.0) -> tuple[float, float, int]:
    """Stage 3: refine ``offset_s``/``drift_ppm`` so the encoder's electrical frequency matches the current's.

    In each window the lag τ minimising Σ (f_current(t) − f_encoder(t_drive(t) + τ))² over
    |τ| ≤ ``max_lag_s`` is found on the grid and refined by a parabola; a line through the windows'
    lags (outliers beyond 4 MAD dropped) corrects offset and drift. Windows without motion are skipped.

    Parameters
    ----------
    f_current_hz : ndarray
        Current's electrical frequency on the uniform DAQ-time grid ``t_daq_s``, Hz.
    t_daq_s : ndarray
        Uniform grid, s.
    f_encoder : callable
        Encoder's electrical frequency, Hz, as a function of drive time, s.
    offset_s, drift_ppm : float
        Starting relation.
    max_lag_s : float
        Search half-range, s.
    window_s : float
        Window length, s.

    Returns
    -------
    offset_s, drift_ppm : float
        The refined relation (the inputs if no window was usable).
    n_windows : int
        Windows used.
    """
    dt = t_daq_s[1] - t_daq_s[0]
    lags = np.arange(-int(round(max_lag_s / dt)), int(round(max_lag_s / dt)) + 1) * dt
    nw_len = max(3, int(round(window_s / dt)))
    nw = t_daq_s.size // nw_len
    if nw == 0:
        return offset_s, drift_ppm, 0
    n = nw * nw_len
    t_drive = offset_s + t_daq_s[:n] * (1.0 + drift_ppm * 1e-6)
    fc = f_current_hz[:n].reshape(nw, nw_len)
    f_enc0 = f_encoder(t_drive).reshape(nw, nw_len)
    f_top = max(float(np.max(f_enc0)), 1e-9)
    # only where the motor turns fast: there a half period is short and the estimate local; a truncated
    # square ignores the spikes of the current's frequency where i_q changes sign
    fast = f_enc0 > 0.25 * f_top
    weight = fast / np.maximum(fast.sum(axis=1, keepdims=True), 1)
    clip = (0.1 * f_top) ** 2
    cost = np.empty((lags.size, nw))
    for j, lag in enumerate(lags):
        cost[j] = np.sum(weight * np.minimum((fc - f_encoder(t_drive + lag).reshape(nw, nw_len)) ** 2, clip), axis=1)
    moving = (f_enc0.std(axis=1) > 0.05 * f_top) & (fast.mean(axis=1) > 0.1)
    best = np.argmin(cost, axis=0)
    interior = (best > 0) & (best < lags.size - 1)
    ok = moving & interior
    if not ok.any():
        return offset_s, drift_ppm, 0
    cols = np.flatnonzero(ok)
    c0, c1, c2 = cost[best[cols] - 1, cols], cost[best[cols], cols], cost[best[cols] + 1, cols]
    curv = c0 - 2 * c1 + c2
    tau = lags[best[cols]] + dt * np.where(curv > 0, 0.5 * (c0 - c2) / np.where(curv > 0, curv, 1.0), 0.0)
    t_c = t_daq_s[0] + (cols + 0.5) * nw_len * dt
    keep = np.ones(cols.size, bool)
    for _ in range(3):
        a, b = np.polyfit(t_c[keep], tau[keep], 1)[::-1] if keep.sum() >= 3 else (0.0, 0.0)
        if keep.sum() < 3 or abs(drift_ppm + b * 1e6) > MAX_DRIFT_PPM:
            # too few windows for a slope, or a slope no pair of clocks has (a few windows of motion, their lags
            # scattered by ms): the offset only, the starting drift kept — the angle stage fits the drift
            a, b = float(np.median(tau[keep])), 0.0
        r = tau - a - b * t_c
        mad = 1.4826 * np.median(np.abs(r[keep]))
        keep = np.abs(r) <= max(4.0 * mad, 2.0 * dt)
    return offset_s + a, drift_ppm + b * 1e6, int(keep.sum())


@dataclass(frozen=True)
class AngleFit:
    """Result of the angle stage: the relation, θ_0 (mod π, rad) and the fit's quality (see :class:`ClockFit`)."""

    offset_s: float
    drift_ppm: float
    theta0_rad: float
    residual_s: float
    offset_std_s: float
    drift_std_ppm: float
    n_windows: int


def angle_alignment(current_a: np.ndarray, rate_hz: float, first_index: int, angle: CubicSpline, pole_pairs: int,
                    offset_s: float, drift_ppm: float, search_s: float = 4e-3, window_s: float = 0.02,
                    iterations: int = 2) -> AngleFit | None:
    """Stage 4: offset, drift and θ_0 from the phase of i_a against the encoder's electrical angle.

    Parameters
    ----------
    current_a : ndarray
        One phase current, A; element 0 is DAQ sample ``first_index``.
    rate_hz : float
        DAQ rate, Hz.
    first_index : int
        DAQ sample index of ``current_a[0]``.
    angle : CubicSpline
        Mechanical angle θ_m(t_drive), rad.
    pole_pairs : int
        Pole pairs p.
    offset_s, drift_ppm : float
        Starting relation, within ``search_s`` of the truth.
    search_s : float
        Half-range of the coherent search for the offset, s.
    window_s : float
        Demodulation window, s.
    iterations : int
        Re-demodulations after the search.

    Returns
    -------
    AngleFit or None
        None when fewer than 10 windows turn half an electrical revolution.
    """
    t_ref = (first_index + 0.5 * current_a.size) / rate_hz
    t_span = angle.x[[0, -1]]
    speed = angle.derivative()
    blocks = _block_means(current_a, rate_hz, first_index, pole_pairs * float(np.max(np.abs(angle.c[2]))))
    wl = max(8, int(round(window_s * rate_hz / blocks.size)))
    theta0 = 0.0
    for it in range(iterations + 1):
        z, t_c, w_m = _phasors(blocks, angle, speed, pole_pairs, offset_s, drift_ppm, wl, t_span)
        if z.size < 10:
            return None
        k = 2.0 * pole_pairs * w_m
        if it == 0:
            grid = np.arange(-search_s, search_s + 1e-9, _SEARCH_STEP_S)
            power = np.abs(_coherent_sums(z, k, grid[0], _SEARCH_STEP_S, grid.size))
            shift = grid[int(np.argmax(power))]
            offset_s += shift
            z = z * np.exp(-1j * k * shift)
            theta0 = 0.5 * np.angle(np.sum(z))
        A = np.column_stack((2.0 * np.ones_like(k), k, k * (t_c - t_ref)))
        w = np.abs(z)
        r = np.angle(z * np.exp(-2j * theta0))
        keep = np.ones(z.size, bool)
        for _ in range(3):
            sw = np.sqrt(w[keep])
            sol = np.linalg.lstsq(A[keep] * sw[:, None], r[keep] * sw, rcond=None)[0]
            res = r - A @ sol
            mad = 1.4826 * np.median(np.abs(res[keep]))
            keep = np.abs(res) <= max(4.0 * mad, 1e-3)
        theta0 += sol[0]
        d_drift = sol[2]
        offset_s += sol[1] - d_drift * t_ref
        drift_ppm += d_drift * 1e6
    # uncertainty of the last step (the corrections are then tiny), at t_ref then moved to t = 0
    sw = np.sqrt(w[keep])
    Aw = A[keep] * sw[:, None]
    s2 = np.sum((res[keep] * sw) ** 2) / max(1, keep.sum() - 3)
    cov = s2 * np.linalg.inv(Aw.T @ Aw)
    var_off0 = cov[1, 1] - 2 * t_ref * cov[1, 2] + t_ref**2 * cov[2, 2]
    resid = np.sqrt(np.sum(w[keep] * res[keep] ** 2) / np.sum(w[keep] * k[keep] ** 2))
    theta0 = float(np.angle(np.exp(2j * theta0)) / 2.0)
    return AngleFit(offset_s, drift_ppm, theta0, float(resid), float(np.sqrt(var_off0)),
                     float(np.sqrt(cov[2, 2]) * 1e6), int(keep.sum()))


def _coherent_sums(z: np.ndarray, k: np.ndarray, tau0_s: float, step_s: float, n: int) -> np.ndarray:
    """Σ_w z_w·e^{−j·k_w·τ_i} at the offsets τ_i = ``tau0_s`` + i·``step_s``, i = 0 … n − 1 (k in rad/s).

    Each window's phase advances by k_w·step per offset, so the terms are updated by one complex product per
    window and offset instead of a complex exponential of the whole (offsets × windows) matrix (25× faster, and
    memory of one row; after a few hundred steps the sums agree with the direct ones to 1e-14 relative).
    """
    v = z * np.exp(-1j * k * tau0_s)
    advance = np.exp(-1j * k * step_s)
    out = np.empty(n, complex)
    for i in range(n):
        out[i] = v.sum()
        v *= advance
    return out


@dataclass(frozen=True)
class _BlockMeans:
    """The current averaged over blocks of ``size`` consecutive DAQ samples, A, the first block's mid-time on the
    DAQ clock, s, and the blocks' spacing, s."""

    current_a: np.ndarray
    t0_s: float
    dt_s: float
    size: int


def _block_means(current_a: np.ndarray, rate_hz: float, first_index: int, omega_e_max_rad_s: float) -> _BlockMeans:
    """Average ``current_a`` over blocks of D samples, D as large as keeps ``_BLOCK_SAMPLES_PER_TURN`` blocks per
    electrical turn at the fastest electrical speed ``omega_e_max_rad_s`` (at most ``_MAX_BLOCK``).

    The mean of a·sin θ + b·cos θ + c over a block in which θ advances at a constant rate is the same sinusoid read
    at the block's mid-time, its amplitude times sin(Dδ/2)/(D·sin(δ/2)) (δ: angle per sample; ≥ 0.994 at 16
    blocks per turn) and its phase unchanged; white noise keeps its information (variance / D on D times fewer
    values). So the angle stage, which reads only the phase, demodulates the blocks against the angle at their
    mid-times: D times fewer angle evaluations, sines and products, three passes for the cost of one average.
    """
    per_turn = 2.0 * np.pi * rate_hz / max(omega_e_max_rad_s, 1e-9)
    size = int(np.clip(per_turn // _BLOCK_SAMPLES_PER_TURN, 1, _MAX_BLOCK))
    n = current_a.size // size
    # a matrix-vector product with weights 1/D: BLAS reads the rows once, 4–20× faster than NumPy's mean over many
    # short rows (the same means to rounding)
    means = (current_a[:n * size].reshape(n, size) @ np.full(size, 1.0 / size) if size > 1
             else np.asarray(current_a, np.float64))
    return _BlockMeans(means, (first_index + 0.5 * (size - 1)) / rate_hz, size / rate_hz, size)


def _phasors(blocks: _BlockMeans, angle: CubicSpline, speed: CubicSpline, pole_pairs: int, offset_s: float,
             drift_ppm: float, wl: int, t_span: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Squared window phasors (i_q²·e^{2j(θ_0 + pωδ)}) over windows of ``wl`` blocks, window-centre DAQ times, s, and
    speeds, rad/s."""
    zs, ts, ws = [], [], []
    step = (_CHUNK // wl) * wl
    scale = 1.0 + drift_ppm * 1e-6
    current_a, dt = blocks.current_a, blocks.dt_s
    for a in range(0, current_a.size - wl + 1, step):
        seg = current_a[a:a + step]
        t_daq = blocks.t0_s + (a + np.arange(seg.size)) * dt
        t_drv = offset_s + t_daq * scale
        wp = window_phasors(seg, pole_pairs * angle(t_drv), wl)
        t_c = blocks.t0_s + (a + wp.centre_index) * dt
        t_c_drv = offset_s + t_c * scale
        inside = (t_c_drv - 0.5 * wl * dt > t_span[0]) & (t_c_drv + 0.5 * wl * dt < t_span[1])
        ok = wp.valid & inside
        zs.append(wp.phasor_a[ok] ** 2)
        ts.append(t_c[ok])
        ws.append(speed(t_c_drv[ok]))
    return np.concatenate(zs), np.concatenate(ts), np.concatenate(ws)


def fit_clock(current_a: np.ndarray, rate_hz: float, first_index: int, angle: CubicSpline, pole_pairs: int,
              host: tuple[float, float] | None, max_lag_s: float = 2.0) -> ClockFit:
    """Align the DAQ clock to the drive clock through the stages of the module docstring.

    Parameters
    ----------
    current_a : ndarray
        One phase current, A; element 0 is DAQ sample ``first_index`` (a gap-free run).
    rate_hz : float
        DAQ rate, Hz.
    first_index : int
        DAQ sample index of ``current_a[0]``.
    angle : CubicSpline
        Mechanical angle θ_m(t_drive), rad, over a gap-free encoder run (:func:`analysis.encoder.angle_spline`).
    pole_pairs : int
        Pole pairs p.
    host : (offset_s, drift_ppm) or None
        Stage 1 result (:func:`host_relation`) when the stamps are arrival times on one host clock; None
        otherwise. The wide search runs either way, ±``max_lag_s`` around the host relation or, without
        it, around "both streams started together".
    max_lag_s : float
        Half-width of the wide search, s.
    """
    t_enc = angle.x[[0, -1]]
    t0 = first_index / rate_hz
    grid = t0 + np.arange(int(current_a.size / rate_hz * _GRID_HZ)) / _GRID_HZ
    f_cur = crossing_frequency_hz(current_crossings_s(current_a, rate_hz, first_index), grid)
    enc_grid = np.arange(t_enc[0], t_enc[1], 1.0 / _GRID_HZ)
    f_enc_grid = crossing_frequency_hz(angle_crossings_s(angle, pole_pairs, t_enc[0], t_enc[1]), enc_grid)

    def f_enc(t: np.ndarray) -> np.ndarray:
        return np.interp(t, enc_grid, f_enc_grid, left=0.0, right=0.0)

    together_s = float(t_enc[0]) - t0
    wide = wide_search(f_cur, f_enc_grid, 1.0 / _GRID_HZ, float(enc_grid[0]) - t0,
                       host[0] if host is not None else together_s, max_lag_s)
    if wide is not None:
        wide = wide.screened(lambda o: _angle_residual_s(o, current_a, rate_hz, first_index, angle, pole_pairs,
                                                         grid, f_cur, f_enc))
    offset_s, drift_ppm, start, ambiguous_by, notes = starting_relation(host, wide, together_s, _NARROW_S)

    rejected: list[AngleFit] = []

    def refine(offset_s: float, drift_ppm: float, method: ClockMethod
               ) -> tuple[float, float, tuple[float, float], ClockMethod, AngleFit | None]:
        """The frequency and angle stages from a starting relation (an angle fit of implausible drift rejected)."""
        freq = (np.nan, np.nan)
        for lag in (_NARROW_S, 0.004):
            o, d, n = frequency_alignment(f_cur, grid, f_enc, offset_s, drift_ppm, lag)
            if n:
                offset_s, drift_ppm, freq, method = o, d, (o, d), "frequency"
        fit = angle_alignment(current_a, rate_hz, first_index, angle, pole_pairs, offset_s, drift_ppm)
        if fit is not None and not plausible_drift(fit.drift_ppm, fit.drift_std_ppm):
            rejected.append(fit)
            fit = None
        return offset_s, drift_ppm, freq, method, fit

    offset_s, drift_ppm, freq, method, fit = refine(offset_s, drift_ppm, start)
    if host is not None and start == "wide":
        # The data overrule the shared host stamps only where the alignment they lead to fits better: on motion
        # whose electrical frequency correlates well at a wrong lag too (a robot's repeated point-to-point
        # moves with pauses), the wide search's best lag can be wrong while the stamps are right.
        from_host = refine(host[0], host[1], "host")
        if _angle_residual(from_host[4]) <= _angle_residual(fit):
            offset_s, drift_ppm, freq, method, fit = from_host
            start = "host"
        else:
            final_s = fit.offset_s if fit is not None else offset_s
            notes.append(f"clock: the host stamps are {1e3 * (host[0] - final_s):+.0f} ms off the data's alignment "
                         "(blocks delivered late?); the wide search's offset is used")
    failure = ""
    if rejected and fit is None:
        failure = (f"clock: no alignment found — {_rejection_text(rejected)}: the motion repeats too evenly to align "
                   "the streams on (or they do not belong together), so K, J and C would be those of a wrong alignment")
    elif rejected:
        notes.append(f"clock: rejected a fit of the electrical angle: {_rejection_text(rejected)}")
    common = dict(host_offset_s=host[0] if host else np.nan, host_drift_ppm=host[1] if host else np.nan,
                  frequency_offset_s=freq[0], frequency_drift_ppm=freq[1],
                  wide_offset_s=wide.offset_s if wide else np.nan, ambiguous_by_s=ambiguous_by, notes=tuple(notes))
    if fit is None:
        return ClockFit(offset_s, drift_ppm, method=method, failure=failure, **common)
    return ClockFit(fit.offset_s, fit.drift_ppm, fit.residual_s, fit.offset_std_s, fit.drift_std_ppm,
                    fit.theta0_rad, n_windows=fit.n_windows, method="angle", **common)


def plausible_drift(drift_ppm: float, drift_std_ppm: float) -> bool:
    """False when a fitted drift, ppm, lies beyond :data:`MAX_DRIFT_PPM` by more than its own 95 % uncertainty
    (``drift_std_ppm``, its standard error, ppm; NaN counts as zero): the data then say the clocks would
    have to differ by more than any pair of crystal oscillators does."""
    return not abs(drift_ppm) - Z95 * float(np.nan_to_num(drift_std_ppm)) > MAX_DRIFT_PPM


def _rejection_text(rejected: list[AngleFit]) -> str:
    """What the rejected angle fits needed (the smallest drift of them), for a note or the failure."""
    least = min(rejected, key=lambda f: abs(f.drift_ppm))
    drift, margin = (f"{x:,.0f}".replace(",", " ") for x in (least.drift_ppm, Z95 * least.drift_std_ppm))
    more = f" (and from {len(rejected) - 1} other start(s) more)" if len(rejected) > 1 else ""
    return (f"the phase of the current against the encoder's angle fits at offset {least.offset_s:+.3f} s only with a "
            f"drift of {'+' if least.drift_ppm >= 0 else ''}{drift} ± {margin} ppm{more}, beyond the "
            f"±{MAX_DRIFT_PPM:.0f} ppm two crystal clocks can differ")


def _angle_residual(fit: AngleFit | None) -> float:
    """Timing residual, s, of an angle-stage fit (inf without one)."""
    return fit.residual_s if fit is not None else np.inf


def _angle_residual_s(offset_s: float, current_a: np.ndarray, rate_hz: float, first_index: int, angle: CubicSpline,
                      pole_pairs: int, grid: np.ndarray, f_cur: np.ndarray,
                      f_enc: Callable[[np.ndarray], np.ndarray]) -> float:
    """Timing residual, s, of the frequency and angle stages started at ``offset_s`` on ``_PIECE_S`` of current in
    the middle of the overlap there (inf when the angle stage finds too little motion or needs an implausible
    drift, :func:`plausible_drift`)."""
    t_enc = angle.x[[0, -1]]
    lo, hi = max(grid[0], t_enc[0] - offset_s), min(grid[-1], t_enc[1] - offset_s)
    a_s, b_s = max(lo, 0.5 * (lo + hi - _PIECE_S)), min(hi, 0.5 * (lo + hi + _PIECE_S))
    sel = (grid >= a_s) & (grid < b_s)
    drift_ppm = 0.0
    for lag in (_NARROW_S, 0.004):
        o, d, n = frequency_alignment(f_cur[sel], grid[sel], f_enc, offset_s, drift_ppm, lag, window_s=b_s - a_s)
        if n:
            offset_s, drift_ppm = o, d
    a, b = (int(np.clip(round(x * rate_hz) - first_index, 0, current_a.size)) for x in (a_s, b_s))
    fit = angle_alignment(current_a[a:b], rate_hz, first_index + a, angle, pole_pairs, offset_s, drift_ppm,
                          iterations=0)
    return fit.residual_s if fit is not None and plausible_drift(fit.drift_ppm, fit.drift_std_ppm) else np.inf
