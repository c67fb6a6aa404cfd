"""How much of the encoder's quantisation error repeats with the motion: the share no averaging removes.

A drive runs its profile on its own cycle and samples the encoder on the same cycle. When the trajectory repeats
from one motion period to the next to a small fraction of a count — a quiet loop, a simulated plant — every period
reads the same quantisation errors, and at the motion's lines they add a fixed error that no number of periods
averages away and no scatter between blocks of the record shows: the misfit test and the intervals allow for it
(:func:`analysis.adequacy.quantisation_through_fit`, :func:`analysis.adequacy.quantisation_pull`). When the
trajectory differs by more than a count between periods — the disturbances of a real loop, a dithered profile
(``speed_dither``) — the errors are independent from period to period and scatter like any noise, which the
jackknife sees; allowing for them again would only blind the misfit test (a third mode at 150 Hz hides behind a
5 % allowance per bin at 2^17 counts/rev).

Two quantisation errors a fraction f of a count apart correlate by 1 − 6·f·(1 − f) (the sawtooth's
autocorrelation): a tenth of a count already takes half the correlation away, so the share is measured, not
inferred from the spread of the positions. The third difference of the angle (as in
:func:`analysis.sample_instants.estimate_jitter`) removes the motion up to a parabola and keeps the quantisation
error (×20 in variance); its correlation with itself one motion period later is the share that repeats. A third
difference beyond ±4 counts cannot come from errors of ±½ count (|−1| + 3 + 3 + 1 = 8 halves): those samples are the
motion's own corners and ringing, which repeat as signal, and are left out, as are samples moving less than
:data:`analysis.sample_instants.QUANTISATION_COUNTS` counts a cycle (their errors are correlated along the record).
What of the motion's own third difference stays within ±4 counts still reads as repeating (a dithered 500 Hz
encoder: 0.10), so the share of samples whose count one period later is offset by exactly the usual number of counts
bounds it from the other side (a dithered motion: ~0.01; it reads high only where trajectories differ by a
fraction of a count, which the correlation sees). The motion's period is taken at every high peak of the speed's
autocorrelation (a program of unlike strokes repeats at the whole program, not at a stroke), each refined within
±1 % (at least ±3 samples: a drive's profile may run on a cycle a little off the encoder's), and the highest share
over them counts.
"""

from __future__ import annotations

import numpy as np
from scipy import signal

from analysis.sample_instants import QUANTISATION_COUNTS

# From this share on the analysis says so in its notes: the misfit test's allowance for the quantisation (a standard
# deviation ∝ √share) is then at least 70 % of what a fully repeating error needs, and a few-percent mode can hide in it
NOTED_LOCKED_SHARE = 0.5
_D3 = np.array([-1.0, 3.0, -3.0, 1.0])
_D3_MAX_COUNTS = 4.0  # the largest third difference errors of ±½ count can make
# the autocorrelation's peak of a few periods of a triangle lies up to ~1 % off the period (measured: 805 samples for
# 800 on a 3 s record): the lag is refined within that, and the maximum over ~2·1 % of the lags raises the share by
# its own scatter (≈ 2.5/√pairs, 0.035 at 5 000 pairs) at most
_REFINE_FRACTION = 0.01
_REFINE_MIN_SAMPLES = 3
# Candidate periods: every autocorrelation peak at least half the highest (a program of unlike strokes repeats at
# the whole program, whose peak may be lower than a stroke's; an exact repetition is a peak as high as any), at most
# this many of the highest — each candidate costs ~2·1 % of its lag in dot products
_PEAK_SHARE = 0.5
_MAX_CANDIDATES = 8
# The share is a property of the motion, not of the record's length: it is measured on at most this many samples
# (4.4 min at 4 kHz, 17 min at 1 kHz), which bounds the time and memory on hour-long records
_MAX_SAMPLES = 2**20
_MIN_PAIRS = 200  # fewer pairs than this: the correlation's own scatter (1/√n) is above 0.07, not measured


def candidate_periods(speed: np.ndarray) -> list[int]:
    """Lags, in samples, at which the speed may repeat: the peaks of its autocorrelation after its first negative
    lobe that reach half the highest, the highest first (at most :data:`_MAX_CANDIDATES`); empty when the speed
    does not repeat within half the record."""
    x = np.asarray(speed, dtype=float)[:_MAX_SAMPLES]
    x = x - x.mean()
    n = x.size
    if n < 8 or not np.any(x):
        return []
    # per pair of samples (the sum over n − lag of them), so that the peak is not pulled towards short lags
    ac = signal.correlate(x, x, mode="full", method="fft")[n - 1:n - 1 + n // 2] / (n - np.arange(n // 2))
    negative = np.flatnonzero(ac < 0.0)
    if negative.size == 0:
        return []
    tail = ac[negative[0]:]
    peaks, _ = signal.find_peaks(tail)
    if peaks.size == 0 or not tail[peaks].max() > 0.0:
        return []
    high = peaks[tail[peaks] >= _PEAK_SHARE * tail[peaks].max()]
    high = high[np.argsort(-tail[high], kind="stable")][:_MAX_CANDIDATES]
    return [int(negative[0] + k) for k in high]


def locked_share(position_counts: np.ndarray) -> float:
    """Share (0…1) of the encoder's quantisation error that repeats with the motion; NaN when it cannot be measured
    (no repeating motion, too few moving samples).

    At each candidate period (:func:`candidate_periods`) the lower of two readings, each of which can only read high:
    the correlation of the angle's third differences one period apart (high also where the motion's own third
    differences repeat — its corners and ringing within ±4 counts), and the share of moving samples whose count
    one period later differs by exactly the record's usual offset (high also where the trajectories differ by a
    fraction of a count, which already decorrelates the errors). The highest over the candidates is returned: a
    period taken for the motion's that is not would read a low share and hide a repeating error.

    Parameters
    ----------
    position_counts : ndarray
        Encoder positions on the regular grid k·T, counts (gap-free, as analysed).
    """
    p = np.asarray(position_counts, dtype=float)[:_MAX_SAMPLES]
    periods = candidate_periods(np.diff(p))
    if not periods:
        return float("nan")
    d3 = np.convolve(p, _D3[::-1], mode="valid")  # d3[i] from p[i] … p[i + 3]
    step = np.abs(np.diff(p))
    # every step the third difference spans moves at least QUANTISATION_COUNTS: their errors are independent
    moving = np.convolve(step >= QUANTISATION_COUNTS, np.ones(_D3.size - 1), mode="valid") == _D3.size - 1
    usable = moving & (np.abs(d3) <= _D3_MAX_COUNTS)
    best = float("nan")
    for period in periods:
        reach = max(_REFINE_MIN_SAMPLES, int(np.ceil(_REFINE_FRACTION * period)))
        for lag in range(max(period - reach, 1), period + reach + 1):
            share = _share_at(p, d3, usable, lag)
            if np.isfinite(share):
                best = share if not np.isfinite(best) else max(best, share)
    return float(np.clip(best, 0.0, 1.0)) if np.isfinite(best) else float("nan")


def _share_at(p: np.ndarray, d3: np.ndarray, usable: np.ndarray, lag: int) -> float:
    """The lower of the two readings of :func:`locked_share` at one lag (samples); NaN with too few pairs."""
    if lag >= d3.size:
        return float("nan")
    pair = usable[:-lag] & usable[lag:]
    if np.count_nonzero(pair) < _MIN_PAIRS:
        return float("nan")
    a, b = d3[:-lag][pair], d3[lag:][pair]
    denom = float(np.sqrt(np.dot(a, a) * np.dot(b, b)))
    if not denom > 0.0:
        return float("nan")
    m = d3.size - lag
    offset = (p[lag:lag + m] - p[:m])[pair]
    same_count = float(np.mean(offset == np.median(offset)))
    return min(float(np.dot(a, b)) / denom, same_count)
