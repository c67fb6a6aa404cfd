"""How much of the encoder's quantisation error repeats with the motion: the share no averaging removes.

A drive runs its profile on its own cycle and samples the encoder on the same cycle. When the trajectory repeats
from one motion period to the next to a small fraction of a count — a quiet loop, a simulated plant — every period
reads the same quantisation errors, and at the motion's lines they add a fixed error that no number of periods
averages away and no scatter between blocks of the record shows: the misfit test and the intervals allow for it
(:func:`analysis.systematic_errors.quantisation_through_fit`, :func:`analysis.systematic_errors.quantisation_pull`). When the
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
encoder: 0.10), so the share of neighbouring samples whose counts one period later are offset by the same whole
number of counts bounds it from the other side (a dithered motion: ~0.01; it reads high only where trajectories
differ by a fraction of a count, which the correlation sees). The motion's period is taken at every high peak of the speed's
autocorrelation (a program of unlike strokes repeats at the whole program, not at a stroke), each refined within
±1 % (at least ±3 samples: a drive's profile may run on a cycle a little off the encoder's), and the highest share
over them counts.
"""

from __future__ import annotations

import numpy as np
from scipy import fft, signal

from analysis.sample_instants import QUANTISATION_COUNTS, THIRD_DIFFERENCE, third_difference

# From this share on the analysis says so in its notes: the misfit test's allowance for the quantisation (a standard
# deviation ∝ √share) is then at least 70 % of what a fully repeating error needs, and a few-percent mode can hide in it
NOTED_LOCKED_SHARE = 0.5
# the largest third difference errors of ±½ count can make: ½·(1 + 3 + 3 + 1) = 4 counts
_D3_MAX_COUNTS = 0.5 * float(np.abs(THIRD_DIFFERENCE).sum())
# the autocorrelation's peak of a few periods of a triangle lies up to ~1 % off the period (measured: 805 samples for
# 800 on a 3 s record): the lag is refined within that, and the maximum over ~2·1 % of the lags raises the share by
# its own scatter (≈ 2.5/√pairs, 0.035 at 5 000 pairs) at most
_REFINE_FRACTION = 0.01
_REFINE_MIN_SAMPLES = 3
# Candidate periods: the autocorrelation's peaks of at least half the highest, within a third of the record (the
# per-pair normalisation makes longer lags noisy), the shortest first — the motion's period, or one stroke of a
# program of unlike strokes, which repeats at a few strokes (its whole period): each candidate is also taken ×2…×4,
# refined within k times its reach. Peaks near a multiple of a shorter candidate add nothing; at most this many
_PEAK_SHARE = 0.5
_MAX_CANDIDATES = 4
_MULTIPLES = 4
# The share is a property of the motion, not of the record's length: it is measured on at most this many samples
# (65 s at 4 kHz, 4.4 min at 1 kHz: tens of thousands of pairs, a scatter of the share below 0.01), which bounds the
# time and memory on hour-long records
_MAX_SAMPLES = 2**18
_MIN_PAIRS = 200  # fewer pairs than this: the correlation's own scatter (1/√n) is above 0.07, not measured


def candidate_periods(speed: np.ndarray) -> list[int]:
    """Lags, in samples, at which the speed may repeat: the peaks of its autocorrelation after its first negative
    lobe that reach half the highest within a third of the record, the shortest first, none near a multiple of a
    shorter one (at most :data:`_MAX_CANDIDATES`); empty when the speed does not repeat within a third of the
    record."""
    x = np.asarray(speed, dtype=float)[:_MAX_SAMPLES]
    x = x - x.mean()
    n = x.size
    if n < 8 or not np.any(x):
        return []
    reach = n // 3
    # per pair of samples (the sum over n − lag of them), so that the peak is not pulled towards short lags; the
    # autocorrelation as the inverse transform of the power spectrum (one forward transform, not correlate's two)
    size = fft.next_fast_len(2 * n - 1, real=True)
    spec = fft.rfft(x, size)
    ac = fft.irfft(spec.real**2 + spec.imag**2, size)[:reach] / (n - np.arange(reach))
    negative = np.flatnonzero(ac < 0.0)
    if negative.size == 0:
        return []
    tail = ac[negative[0]:]
    peaks, _ = signal.find_peaks(tail)
    if peaks.size == 0 or not tail[peaks].max() > 0.0:
        return []
    kept: list[int] = []
    for lag in negative[0] + peaks[tail[peaks] >= _PEAK_SHARE * tail[peaks].max()]:
        if not any(abs(lag - round(lag / k) * k) <= _refine_reach(lag) for k in kept):
            kept.append(int(lag))
        if len(kept) == _MAX_CANDIDATES:
            break
    return kept


def _refine_reach(lag: int) -> int:
    """Samples either side of ``lag`` over which a period is refined."""
    return max(_REFINE_MIN_SAMPLES, int(np.ceil(_REFINE_FRACTION * lag)))


def locked_share(position_counts: np.ndarray) -> float:
    """Share (0…1) of the encoder's quantisation error that repeats with the motion; NaN when it cannot be measured
    (no repeating motion, too few moving samples).

    At each candidate period (:func:`candidate_periods`) the lower of two readings: the correlation of the angle's
    third differences one period apart, at the lag within ±1 % where it is highest (it reads high also where the
    motion's own third differences repeat — its corners and ringing within ±4 counts), and, at that lag, the share of
    neighbouring moving samples whose counts one period later are offset by the same whole number of counts (a
    trajectory that starts each period a whole count away from the last keeps its errors and reads 1; it reads high
    also where trajectories differ by a fraction of a count, which the correlation sees). The highest over the
    candidates is returned: a period taken for the motion's that is not would read a low share and hide a repeating
    error.

    Parameters
    ----------
    position_counts : ndarray
        Encoder positions on the regular grid k·T, counts (gap-free, as analysed).
    """
    p = np.asarray(position_counts, dtype=float)[:_MAX_SAMPLES]
    periods = candidate_periods(np.diff(p))
    if not periods:
        return float("nan")
    d3 = third_difference(p)  # d3[i] from p[i] … p[i + 3]
    step = np.abs(np.diff(p))
    # every step the third difference spans moves at least QUANTISATION_COUNTS: their errors are independent
    spans = THIRD_DIFFERENCE.size - 1
    moving = np.convolve(step >= QUANTISATION_COUNTS, np.ones(spans), mode="valid") == spans
    usable = moving & (np.abs(d3) <= _D3_MAX_COUNTS)
    correlation = _correlations(d3, usable)
    best = float("nan")
    for period in periods:
        for k in range(1, _MULTIPLES + 1):  # a program of unlike strokes repeats at a few of them
            reach = k * _refine_reach(period)
            window = correlation[max(k * period - reach, 1):min(k * period + reach + 1, correlation.size)]
            if not np.any(np.isfinite(window)):
                continue
            lag = max(k * period - reach, 1) + int(np.nanargmax(window))
            share = min(float(correlation[lag]), _same_offset_share(p, usable, lag, d3.size))
            best = share if not np.isfinite(best) else max(best, share)
    return float(np.clip(best, 0.0, 1.0)) if np.isfinite(best) else float("nan")


def _correlations(d3: np.ndarray, usable: np.ndarray) -> np.ndarray:
    """Correlation of the usable third differences ``lag`` samples apart, for every lag (index = lag; NaN where
    fewer than :data:`_MIN_PAIRS` pairs): sums over the pairs usable at both ends, all lags at once by FFT — a dot
    product per lag would cost the record's length for each of thousands.

    The four sums come from the spectra of the three signals (mask, masked d3, masked d3²), each transformed once, and
    three inverse transforms: the sums of the squares at the later and at the earlier end are the positive and the
    negative lags of one cross-correlation (scipy.signal.correlate per sum took 8 forward and 4 inverse transforms,
    24.7 ms of a 60 s session's 31 ms here, against 6 transforms now).
    """
    m = usable.astype(float)
    am, a2m = d3 * m, d3 * d3 * m
    n = d3.size
    size = fft.next_fast_len(2 * n - 1, real=True)  # no wrap-around for lags −(n − 1) … n − 1
    spec_m, spec_am, spec_a2m = (fft.rfft(x, size) for x in (m, am, a2m))
    pairs = fft.irfft(spec_m * spec_m.conj(), size)[:n]  # Σ_k m[k + lag]·m[k], lag = 0 … n − 1
    products = fft.irfft(spec_am * spec_am.conj(), size)[:n]
    cross = fft.irfft(spec_a2m * spec_m.conj(), size)  # [lag mod size]: Σ_k a2m[k + lag]·m[k], lag = −(n − 1) … n − 1
    later, earlier = cross[:n], cross[-np.arange(n) % size]  # Σ of the squares at the later / the earlier end
    with np.errstate(invalid="ignore", divide="ignore"):
        out = products / np.sqrt(later * earlier)
    out[(np.rint(pairs) < _MIN_PAIRS) | ~(later > 0) | ~(earlier > 0)] = np.nan
    return out


def _same_offset_share(p: np.ndarray, usable: np.ndarray, lag: int, n: int) -> float:
    """Share of neighbouring usable samples whose counts ``lag`` samples later are offset by the same whole number
    of counts (the positions one period apart differ by a constant, so their quantisation errors are the same — also
    where a motion starts each period a whole count away from the last); 1 where there are no neighbours to tell."""
    m = n - lag
    pair = np.flatnonzero(usable[:m] & usable[lag:lag + m])
    offset = p[lag + pair] - p[pair]
    neighbours = pair[1:] == pair[:-1] + 1
    if not np.any(neighbours):
        return 1.0
    return float(np.mean(offset[1:][neighbours] == offset[:-1][neighbours]))
