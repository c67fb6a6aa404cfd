"""Bench-config faults read from the data: does the current turn as fast as the encoder says it should?

The current's electrical frequency f_e (zero-crossing rate of i_a) must equal p·|ω|/2π with p the
stated ``pole_pairs`` and ω the speed from the encoder counts scaled by the stated ``counts_per_rev``.
A wrong constant makes the ratio r = f_e / (p·|ω|/2π) = (p_true/p)·(counts_per_rev/counts_per_rev_true)
differ from 1 — the clock alignment then fails without saying why. This module measures r (independent
of the clock offset: the lag is searched, the shapes are the same up to the scale r) and words the fault.
``acq selftest`` and the analysis's verdict use the same text.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
from scipy import signal
from scipy.ndimage import median_filter

from analysis.clocks import crossing_frequency_hz, current_crossings_s
from analysis.encoder import longest_gap_free_span, speed_from_counts
from analysis.quality import Quality
from analysis.signals import Recording

GRID_HZ = 200.0  # grid of the comparison, Hz: the speed's shape (≤ 20 Hz for a triangle) is well inside
MAX_LAG_S = 2.0  # clock offsets searched, s: the design's plausible range of DAQ vs drive start (§4)
WINDOW_S = 0.5  # windows of the ratio's scatter, s
#: A ratio off 1 by less is not named. The estimate's own spread sets the bar (``RATIO_SIGMAS``), but
#: never below 3 %: below the smallest pole-pair error of a motor with ≤ 32 pole pairs (1/33), above the
#: zero-crossing estimator's bias seen on simulated and real-shaped records (< 1 %).
MIN_RATIO_ERROR = 0.03
RATIO_SIGMAS = 5.0


@dataclass(frozen=True)
class SpeedRatio:
    """The current's electrical frequency against p·|ω|/2π from the encoder.

    Attributes
    ----------
    ratio : float
        f_e / (p·|ω|/2π): 1 on a correctly configured bench.
    spread : float
        Standard error of ``ratio`` from its scatter between windows (NaN with one window).
    lag_s : float
        Drive time minus DAQ time at which the two speed shapes match best, s.
    windows : int
        Windows with motion that entered the ratio.
    """

    ratio: float
    spread: float
    lag_s: float
    windows: int

    @property
    def mismatched(self) -> bool:
        """True when the ratio is off 1 by more than the estimate's scatter and :data:`MIN_RATIO_ERROR`."""
        bar = max(MIN_RATIO_ERROR, RATIO_SIGMAS * (self.spread if math.isfinite(self.spread) else 0.0))
        return abs(self.ratio - 1.0) > bar


def electrical_speed_ratio(current_a: np.ndarray, rate_hz: float, encoder_index: np.ndarray,
                           position_counts: np.ndarray, period_s: float, counts_per_rev: int,
                           pole_pairs: int) -> SpeedRatio | None:
    """Measure f_e / (p·|ω|/2π) over a record; None when it holds too little motion to tell.

    Parameters
    ----------
    current_a : ndarray
        One phase current, A, gap-free, DAQ sample 0 at t_daq = 0.
    rate_hz : float
        DAQ rate, Hz.
    encoder_index, position_counts : ndarray of int
        Drive cycle and unwrapped position, counts, of each encoder sample.
    period_s : float
        Drive cycle, s.
    counts_per_rev, pole_pairs : int
        The bench's stated encoder resolution and pole pairs.
    """
    span = longest_gap_free_span(np.asarray(encoder_index))
    if span.count < 3 or current_a.size < 3:
        return None
    cycles = np.asarray(encoder_index)[span.start:span.stop]
    omega = speed_from_counts(np.asarray(position_counts)[span.start:span.stop], counts_per_rev, period_s)
    t_enc = cycles[1:] * period_s
    grid_enc = np.arange(t_enc[0], t_enc[-1], 1.0 / GRID_HZ)
    f_enc = _smooth(np.interp(grid_enc, t_enc, pole_pairs * np.abs(omega) / (2 * np.pi)))
    grid_daq = np.arange(0.0, current_a.size / rate_hz, 1.0 / GRID_HZ)
    f_cur = crossing_frequency_hz(current_crossings_s(current_a, rate_hz), grid_daq)
    if not (np.any(f_cur > 0) and np.any(f_enc > 0)):
        return None
    # f_cur[i] at DAQ time i/G must match r·f_enc at drive time i/G + lag: the lag where the shapes correlate
    xc = signal.correlate(f_enc, f_cur, mode="full", method="fft")
    shifts = np.arange(-f_cur.size + 1, f_enc.size)  # f_enc index − f_cur index
    t_lag = grid_enc[0] + shifts / GRID_HZ
    allowed = np.abs(t_lag) <= MAX_LAG_S
    if not np.any(allowed & (xc > 0)):
        return None
    best = int(np.flatnonzero(allowed)[np.argmax(xc[allowed])])
    shift, lag_s = int(shifts[best]), float(t_lag[best])
    i = np.arange(max(0, -shift), min(f_cur.size, f_enc.size - shift))
    a, b = f_cur[i], f_enc[i + shift]
    per = max(1, int(WINDOW_S * GRID_HZ))
    ratios = []
    top = float(np.max(b))
    for k in range(0, a.size - per + 1, per):
        bw = b[k:k + per]
        if np.mean(bw) > 0.2 * top:  # windows that move (quasi-standstill crossings chatter or vanish)
            ratios.append(float(np.dot(a[k:k + per], bw) / np.dot(bw, bw)))
    if not ratios:
        return None
    moving = b > 0.2 * top
    ratio = float(np.dot(a[moving], b[moving]) / np.dot(b[moving], b[moving]))
    spread = float(np.std(ratios, ddof=1) / math.sqrt(len(ratios))) if len(ratios) > 1 else float("nan")
    return SpeedRatio(ratio, spread, lag_s, len(ratios))


def _smooth(x: np.ndarray) -> np.ndarray:
    """The same 15-sample median the current's crossing frequency gets, so both shapes match."""
    return median_filter(x, size=15, mode="nearest")


def ratio_fault(r: SpeedRatio, pole_pairs: int, counts_per_rev: int) -> str | None:
    """The words for a mismatched ratio (None when it matches): what turns faster, and the values to check.

    The suggested ``pole_pairs`` is given only when p·r is near a whole number; ``counts_per_rev`` is
    counts_per_rev/r (snapped to a power of two within 2 %, as most encoders are).
    """
    if not r.mismatched:
        return None
    word = f"{r.ratio:.2f}× faster" if r.ratio > 1 else f"{1 / r.ratio:.2f}× slower"
    candidates = []
    p = pole_pairs * r.ratio
    if round(p) >= 1 and abs(p - round(p)) < 0.1:
        candidates.append(f"[motor] pole_pairs = {round(p)}")
    cpr = counts_per_rev / r.ratio
    power = 2 ** round(math.log2(cpr))
    candidates.append(f"[encoder] counts_per_rev = {power if abs(cpr / power - 1) < 0.02 else round(cpr)}")
    return (f"the current turns {word} than pole_pairs·ω (pole_pairs = {pole_pairs}, counts_per_rev = "
            f"{counts_per_rev}): check {' or '.join(candidates)}")


def recording_fault(rec: Recording) -> str | None:
    """:func:`ratio_fault` of a raw recording's phase i_a and encoder (None if it matches or cannot tell)."""
    r = electrical_speed_ratio(rec.current_a["i_a"], rec.rate_hz, rec.encoder_index, rec.position_counts,
                               rec.period_s, rec.counts_per_rev, rec.pole_pairs)
    return None if r is None else ratio_fault(r, rec.pole_pairs, rec.counts_per_rev)


def with_fault(quality: Quality, fault: str | None) -> Quality:
    """``quality`` failed with ``fault`` as its first reason (unchanged when there is no fault): a wrong
    bench constant makes every number wrong, whatever the fit's own checks say."""
    if fault is None:
        return quality
    return replace(quality, verdict="failed", reasons=(fault, *quality.reasons))
