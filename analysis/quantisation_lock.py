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
The motion period in samples is the lag of the speed's first autocorrelation peak after its first negative lobe,
refined to the lag within ±1 % (at least ±3 samples) where the third differences correlate best (a drive's profile
may run on a cycle a little off the encoder's).
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
_PEAK_SHARE = 0.8  # a peak this close to the highest is a multiple of the same period, not a lesser echo
_MIN_PAIRS = 200  # fewer pairs than this: the correlation's own scatter (1/√n) is above 0.07, not measured


def motion_period_samples(speed: np.ndarray) -> int | None:
    """Lag, in samples, of the speed's first autocorrelation peak after its first negative lobe that reaches most of
    the highest (the motion's period, not a multiple of it); None when the speed does not repeat within half the
    record."""
    x = np.asarray(speed, dtype=float)
    x = x - x.mean()
    n = x.size
    if n < 8 or not np.any(x):
        return None
    # per pair of samples (the sum over n − lag of them), so that the peak is not pulled towards short lags
    ac = signal.correlate(x, x, mode="full", method="fft")[n - 1:n - 1 + n // 2] / (n - np.arange(n // 2))
    negative = np.flatnonzero(ac < 0.0)
    if negative.size == 0:
        return None
    tail = ac[negative[0]:]
    peaks, _ = signal.find_peaks(tail)
    if peaks.size == 0 or not tail[peaks].max() > 0.0:
        return None
    # every multiple of the period correlates alike: the first peak that reaches most of the highest one
    first = peaks[np.flatnonzero(tail[peaks] >= _PEAK_SHARE * tail[peaks].max())[0]]
    return int(negative[0] + first)


def locked_share(position_counts: np.ndarray) -> float:
    """Share (0…1) of the encoder's quantisation error that repeats one motion period later; NaN when it cannot
    be measured (no periodic motion, too few moving samples).

    Parameters
    ----------
    position_counts : ndarray
        Encoder positions on the regular grid k·T, counts (gap-free, as analysed).
    """
    p = np.asarray(position_counts, dtype=float)
    period = motion_period_samples(np.diff(p))
    if period is None:
        return float("nan")
    d3 = np.convolve(p, _D3[::-1], mode="valid")
    moving = np.abs(np.gradient(p))[:d3.size] >= QUANTISATION_COUNTS
    usable = moving & (np.abs(d3) <= _D3_MAX_COUNTS)
    best = float("nan")
    reach = max(_REFINE_MIN_SAMPLES, int(np.ceil(_REFINE_FRACTION * period)))
    for lag in range(max(period - reach, 1), period + reach + 1):
        if lag >= d3.size:
            break
        pair = usable[:-lag] & usable[lag:]
        if np.count_nonzero(pair) < _MIN_PAIRS:
            continue
        a, b = d3[:-lag][pair], d3[lag:][pair]
        denom = float(np.sqrt(np.dot(a, a) * np.dot(b, b)))
        if denom > 0.0:
            r = float(np.dot(a, b)) / denom
            best = r if not np.isfinite(best) else max(best, r)
    return float(np.clip(best, 0.0, 1.0)) if np.isfinite(best) else float("nan")
