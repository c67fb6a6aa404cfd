"""The wide search of the clock alignment: every plausible offset at once, from the data alone (design §4).

The current's electrical frequency (zero-crossing rate of i_a) and the encoder's, p·|ω|/2π, are the
same function of time seen through two clocks. Their Pearson correlation over the overlap, for every
lag, is one FFT cross-correlation plus running sums on a coarse grid (10 ms), so the whole range —
±2 s, or as far as the records still overlap by half the shorter one — costs about a millisecond for a
minute of data. The best lag is good to a few ms; :func:`analysis.clock_frequency.frequency_alignment` and the
angle stage refine it.

|ω| of a periodic motion repeats every half motion period (for the triangle 0 → +top → 0 → −top → 0
the speed's magnitude repeats every 0.4 s), so the correlation has as many peaks. A whole cycle
later the electrical angle repeats too: such shifts only what does not repeat can tell apart (the
motion's start or stop, a change of profile). A half cycle maps θ_m onto its mirror 2c − θ_m (c the
middle of the swing), which one phase current −i_q·sin(p·θ_m + θ_0) would fit with another θ_0 — were
the motion symmetric to the last detail; gravity and friction make it not, and the angle stage's
residual on a piece of the record (:meth:`WideSearch.screened`) tells those apart. The candidates
left are returned: the caller resolves them with host stamps or reports the offset as ambiguous.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Literal

import numpy as np
from scipy import signal

from analysis.clock_host import HostRelation

COARSE_STEP_S = 0.01  # grid of the wide search; the frequency stage's first pass searches ±30 ms around it
#: A lag is as good as the best when (1) its misfit 1 − ρ is at most this many times the best one's — the
#: misfit of an equally good lag scatters by ~√(2/N) relative, N the independent samples of the overlap
#: (≥ ~40 for 2 s of a signal correlated over ~50 ms), so 1.5 is several of those — and (2) its residual
#: has no stretch of mismatch (see :data:`MISMATCH_FRACTION`) longer than the best one's by more than a
#: spike's length (the frequency track's time resolution, :data:`SPIKE_SAMPLES`).
#: (1) alone is diluted on long records: a minute of periodic motion hides a mismatched start of 0.2 s.
EQUALLY_GOOD = 1.5
#: The frequencies disagree where they differ by more than this fraction of the top electrical frequency
#: (the frequency stage's own limit for "the motor turns fast").
MISMATCH_FRACTION = 0.25
#: A spike of the frequency track — an extra zero crossing where i_q changes sign — lasts at most the
#: 15 ms median filter of :func:`analysis.zero_crossings.crossing_frequency_hz` plus one 10 ms block: three
#: samples of the coarse grid. A longer stretch of mismatch is the motion itself not matching.
SPIKE_SAMPLES = 3
MIN_OVERLAP_FRACTION = 0.5  # of the shorter record: lags leaving less overlap are not plausible
#: Candidates the angle stage (on a piece of the record) fits with a timing residual within this factor of
#: the best one's stay equally good. A whole cycle of the motion shifts nothing, and the residual then
#: scatters with the noise; a half cycle maps the angle onto its mirror, exact only for a motion
#: symmetric to the last detail — gravity and friction leave an asymmetry (on the simulated bench a
#: residual of 244 µs against 11–16 µs for the whole cycles). Where it is exact, it changes nothing either.
ANGLE_EQUALLY_GOOD = 3.0

Start = Literal["host", "wide", "none"]


@dataclass(frozen=True)
class WideSearch:
    """Result of the wide search.

    Attributes
    ----------
    offset_s : float
        Best offset (drive time of DAQ time 0), s, refined by a parabola on the coarse grid.
    candidates_s : tuple of float
        Offsets, s, that fit as well as the best (the best included, best first).
    misfit : float
        1 − ρ at the best offset (Pearson correlation of the two frequency tracks over the overlap).
    range_s : (float, float)
        The offsets searched, s: within the plausible range and overlapping enough to be checked.
    """

    offset_s: float
    candidates_s: tuple[float, ...]
    misfit: float
    range_s: tuple[float, float]

    def nearest(self, offset_s: float) -> float:
        """The candidate nearest ``offset_s``, s."""
        c = np.asarray(self.candidates_s)
        return float(c[np.argmin(np.abs(c - offset_s))])

    def screened(self, residual_s: Callable[[float], float]) -> WideSearch:
        """The candidates the electrical angle cannot tell apart, best first.

        ``residual_s(offset_s)`` is the angle stage's timing residual, s, starting from a candidate (inf
        when it cannot tell); candidates within :data:`ANGLE_EQUALLY_GOOD` of the smallest stay.
        """
        if len(self.candidates_s) < 2:
            return self
        residual = np.array([residual_s(c) for c in self.candidates_s])
        if not np.isfinite(residual).any():
            return self
        order = np.argsort(residual)
        keep = tuple(self.candidates_s[i] for i in order if residual[i] <= ANGLE_EQUALLY_GOOD * residual[order[0]])
        return replace(self, offset_s=keep[0], candidates_s=keep)


def _decimated(x: np.ndarray, factor: int) -> np.ndarray:
    """Means of consecutive blocks of ``factor`` samples (the tail that does not fill a block dropped)."""
    n = x.size // factor * factor
    return x[:n].reshape(-1, factor).mean(axis=1)


def overlap_correlation(x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Pearson correlation of ``x[n]`` with ``y[n + L]`` over their overlap, for every lag L.

    The cross products come from one FFT correlation, the overlap's sums and sums of squares from
    running sums, so each lag's correlation uses only the samples both signals have there.

    Returns
    -------
    lags : ndarray of int
        L, from −(len(x) − 1) to len(y) − 1.
    rho : ndarray
        Correlation at each lag (NaN where either side is constant over the overlap).
    overlap : ndarray of int
        Samples in the overlap at each lag.
    """
    c = signal.correlate(y, x, mode="full", method="fft")
    lags = signal.correlation_lags(y.size, x.size, mode="full")
    lo, hi = np.maximum(0, -lags), np.minimum(x.size, y.size - lags)
    n = (hi - lo).astype(np.float64)

    def running(v: np.ndarray) -> np.ndarray:
        return np.concatenate(([0.0], np.cumsum(v)))

    cx, cxx, cy, cyy = running(x), running(x * x), running(y), running(y * y)
    sx, sxx = cx[hi] - cx[lo], cxx[hi] - cxx[lo]
    sy, syy = cy[hi + lags] - cy[lo + lags], cyy[hi + lags] - cyy[lo + lags]
    var = (sxx - sx**2 / n) * (syy - sy**2 / n)
    with np.errstate(invalid="ignore", divide="ignore"):
        rho = np.where(var > 0, (c - sx * sy / n) / np.sqrt(np.maximum(var, 0.0)), np.nan)
    return lags, rho, (hi - lo)


def wide_search(f_current_hz: np.ndarray, f_encoder_hz: np.ndarray, grid_step_s: float, start_gap_s: float,
                centre_s: float, max_lag_s: float) -> WideSearch | None:
    """Offsets, s, at which the current's electrical frequency matches the encoder's, over the whole range.

    Parameters
    ----------
    f_current_hz : ndarray
        Current's electrical frequency on a uniform DAQ-time grid of step ``grid_step_s``, Hz.
    f_encoder_hz : ndarray
        Encoder's electrical frequency on a uniform drive-time grid of the same step, Hz.
    grid_step_s : float
        Step of both grids, s (a divisor of :data:`COARSE_STEP_S`).
    start_gap_s : float
        Drive time of the encoder grid's first point minus DAQ time of the current grid's first, s.
    centre_s : float
        Middle of the plausible offset range, s.
    max_lag_s : float
        Half-width of the plausible range, s.

    Returns
    -------
    WideSearch or None
        None when no plausible lag has motion on both sides.
    """
    factor = max(1, int(round(COARSE_STEP_S / grid_step_s)))
    step = factor * grid_step_s
    x, y = _decimated(f_current_hz, factor), _decimated(f_encoder_hz, factor)
    if min(x.size, y.size) < 3:
        return None
    lags, rho, overlap = overlap_correlation(x, y)
    offsets = start_gap_s + lags * step  # block centres are shifted alike on both grids
    enough = overlap >= MIN_OVERLAP_FRACTION * min(x.size, y.size)
    # scored a little beyond the range, so that a best lag on its edge is still a local maximum
    score = np.where(enough & (np.abs(offsets - centre_s) <= max_lag_s + 2 * step) & np.isfinite(rho), rho, -2.0)
    inside = enough & (np.abs(offsets - centre_s) <= max_lag_s + 0.5 * step)
    peaks = signal.argrelmax(score)[0]
    peaks = peaks[inside[peaks] & (score[peaks] > -2.0)]
    if peaks.size == 0:
        return None
    peaks = peaks[np.argsort(-score[peaks])]
    misfit = 1.0 - score[peaks]
    runs = {int(i): _longest_mismatch(x, y, int(lags[i]), MISMATCH_FRACTION * float(np.percentile(y, 99)))
            for i in peaks[misfit <= EQUALLY_GOOD * max(misfit[0], 0.0)]}
    # a stretch "longer than the best one's" by more than the frequency track's resolution: a mismatch that
    # every lag shares (the motor at rest, where the current's crossings are noise) measures a sample or two
    # longer or shorter from lag to lag, as its edges fall on the coarse grid and through the median filter
    limit = max(runs[int(peaks[0])], 0) + SPIKE_SAMPLES
    refined = tuple(_parabola_peak(score, i, offsets, step) for i, run in runs.items() if run <= limit)
    searched = offsets[inside]
    return WideSearch(refined[0], refined, float(misfit[0]), (float(searched.min()), float(searched.max())))


def _longest_mismatch(x: np.ndarray, y: np.ndarray, lag: int, tolerance: float) -> int:
    """Longest run of samples where ``x[n]`` and ``y[n + lag]`` differ by more than ``tolerance``."""
    lo, hi = max(0, -lag), min(x.size, y.size - lag)
    bad = np.abs(x[lo:hi] - y[lo + lag:hi + lag]) > tolerance
    if not bad.any():
        return 0
    edges = np.diff(np.concatenate(([0], bad.astype(np.int8), [0])))
    return int(np.max(np.flatnonzero(edges == -1) - np.flatnonzero(edges == 1)))


def _parabola_peak(score: np.ndarray, i: int, offsets: np.ndarray, step: float) -> float:
    """Offset, s, of the vertex of the parabola through the score at the local maximum ``i`` and its neighbours."""
    c0, c1, c2 = score[i - 1:i + 2]
    curv = c0 - 2 * c1 + c2
    return float(offsets[i] + (0.5 * step * (c0 - c2) / curv if curv < 0 else 0.0))


def starting_relation(host: HostRelation | None, wide: WideSearch | None, together_s: float, narrow_s: float
                      ) -> tuple[float, float, Start, tuple[float, ...], list[str]]:
    """Where the frequency stage starts: (offset_s, drift_ppm, what it rests on, ambiguous_by_s, notes).

    Host stamps within ``narrow_s`` (the frequency stage's reach, s) of an offset the data supports are
    kept, with their drift; farther off, the data wins. Among offsets the data supports equally (whole
    periods of the motion apart) the host stamps choose (nothing is noted: the offset is then unique); without
    them the best fit is taken and the other shifts, s, are returned and noted. ``together_s`` is the offset of "both streams started
    together", s, used when the wide search found nothing.
    """
    if wide is not None and host is not None and not wide.range_s[0] <= host[0] <= wide.range_s[1]:
        wide = None  # the streams hardly overlap where the stamps put them: the data cannot check the stamps
    if wide is None:
        if host is not None:
            return host[0], host[1], "host", (), []
        return together_s, 0.0, "none", (), ["clock: no motion to align the streams on; taken as started together"]
    chosen = wide.offset_s if host is None else wide.nearest(host[0])
    others = tuple(sorted(round(c - chosen, 3) for c in wide.candidates_s if c != chosen))
    shifts = ", ".join(f"{d:+.3f} s" for d in others)
    notes = []
    if host is None and others:
        notes.append(f"clock: offset ambiguous by repeats of the motion: shifted by {shifts} the streams match as "
                     "well and no shared host clock tells them apart (K and the inertias do not depend on it)")
    # with host stamps the offset is not ambiguous: real stamps on one host clock place it to tens of ms, the
    # alternatives lie a repeat of the motion (≥ 0.4 s) away — no note, as ambiguous_by_s is empty (a note
    # "chose among offsets the data supports equally" read as an ambiguity the result did not have)
    if host is not None and abs(chosen - host[0]) <= narrow_s:
        return host[0], host[1], "host", (), notes
    if host is not None:
        return chosen, 0.0, "wide", (), notes  # the host stamps are overruled
    return chosen, 0.0, "wide", others, notes
