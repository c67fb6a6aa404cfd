"""Electrical frequency from zero crossings: of one phase current on the DAQ clock, of sin(p·θ_m) from the encoder's
angle on the drive clock (the same estimator for both, so their biases cancel).

The clock alignment (:mod:`analysis.clocks`) and the bench check of the speed ratio (:mod:`analysis.speed_ratio`)
compare the two tracks.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from scipy.interpolate import CubicSpline
from scipy.ndimage import median_filter

from analysis import trig

#: Samples per pass over the DAQ record (each pass holds ~15 float64 temporaries of this length: 30 MB).
CHUNK_SAMPLES = 1 << 18


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
    if n <= 4 * CHUNK_SAMPLES:
        return float(np.percentile(x, q))
    pos = q / 100.0 * (n - 1)
    k = int(np.floor(pos))
    k1 = min(k + 1, n - 1)
    if any(np.isnan(x[s:s + CHUNK_SAMPLES]).any() for s in range(0, n, CHUNK_SAMPLES)):
        return float("nan")  # as NumPy
    sample = np.sort(x[:: n // 65536])
    j = int(round(q / 100.0 * (sample.size - 1)))
    for half in (64, 1024, sample.size):
        a = sample[j - half] if j - half >= 0 else -np.inf
        b = sample[j + half] if j + half < sample.size else np.inf
        below, inside = 0, []
        for s in range(0, n, CHUNK_SAMPLES):
            c = x[s:s + CHUNK_SAMPLES]
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
    for a in range(0, n, CHUNK_SAMPLES):
        x = chunk(a, min(n, a + CHUNK_SAMPLES))
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
