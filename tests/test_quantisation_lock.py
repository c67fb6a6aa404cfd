"""The share of the encoder's quantisation error that repeats with the motion (analysis.quantisation_lock)."""

from __future__ import annotations

import numpy as np
import pytest

from analysis.quantisation_lock import _MIN_PAIRS, _correlations, candidate_periods, locked_share

PERIOD = 800  # samples per motion period (0.8 s at 1 kHz)
CYCLES = 12


def triangle_counts(amplitudes: np.ndarray, noise_counts: float = 0.0, seed: int = 0,
                    strokes: tuple[float, ...] = (1.0,)) -> np.ndarray:
    """Encoder counts of a motion of triangle speed, one amplitude (counts per sample at top speed) per period:
    out and back, so every period returns to the start; ``noise_counts`` of white position noise before the
    quantisation (a loop's disturbances); ``strokes``: the period made of out-and-back strokes of these relative
    amplitudes (a program)."""
    quarter = PERIOD // (4 * len(strokes))
    ramp = np.concatenate([np.arange(quarter), quarter - np.arange(quarter)]) / quarter
    unit = np.concatenate([k * np.concatenate([ramp, -ramp]) for k in strokes])  # speed of one period
    speed = np.concatenate([a * unit for a in amplitudes])
    position = 12345.3 + np.cumsum(speed)
    position += np.random.default_rng(seed).normal(0.0, noise_counts, position.size) if noise_counts else 0.0
    return np.floor(position).astype(np.int64)


TOP = 512.345  # counts per sample at top speed: an acceleration that is no simple fraction of a count per sample²


def test_the_motion_period_is_among_the_candidates_found_from_the_speed():
    counts = triangle_counts(np.full(CYCLES, TOP))
    assert min(abs(c - PERIOD) for c in candidate_periods(np.diff(counts.astype(float)))) <= 0.01 * PERIOD


def test_a_trajectory_that_repeats_exactly_repeats_its_quantisation_error():
    assert locked_share(triangle_counts(np.full(CYCLES, TOP))) > 0.95


@pytest.mark.parametrize("dither", [0.005, 0.02])
def test_an_amplitude_dithered_motion_decorrelates_it(dither):
    amplitudes = TOP * (1.0 + dither * np.random.default_rng(1).uniform(-1.0, 1.0, CYCLES))
    # the third differences alone read 0.07 here (the motion's own); the counts' offsets one period apart vary
    assert locked_share(triangle_counts(amplitudes)) < 0.03


def test_disturbances_of_a_few_counts_decorrelate_it():
    assert locked_share(triangle_counts(np.full(CYCLES, TOP), noise_counts=2.0)) < 0.03


def test_a_motion_that_starts_each_period_whole_counts_away_keeps_its_quantisation_error():
    # relative moves from the count the last one ended on: the same errors, shifted by whole counts (the review of
    # session 6: an offset compared with the record's median read 0.45–0.55 here)
    counts = triangle_counts(np.full(CYCLES, TOP))
    shifts = np.repeat(np.cumsum(np.random.default_rng(3).integers(-2, 3, CYCLES)), PERIOD)
    assert locked_share(counts + shifts) > 0.9


def test_a_tenth_of_a_count_already_takes_much_of_it_away():
    # two errors a fraction f of a count apart correlate by 1 − 6 f (1 − f): 0.1 count RMS leaves about half
    share = locked_share(triangle_counts(np.full(CYCLES, TOP), noise_counts=0.1))
    assert 0.2 < share < 0.8


@pytest.mark.parametrize("strokes", [(1.0, 0.99), (1.0, 0.7)])
def test_a_program_of_unlike_strokes_that_repeats_exactly_is_found_locked(strokes):
    # two strokes per period: the speed's autocorrelation peaks at a stroke as well as at the period; only the period
    # repeats the positions (the review of session 6: the first high peak read 0.11 and 0.03 here)
    assert locked_share(triangle_counts(np.full(CYCLES, TOP), strokes=strokes)) > 0.9


def test_no_periodic_motion_is_not_measured():
    speed = np.cumsum(np.random.default_rng(2).normal(0.0, 50.0, PERIOD * CYCLES))  # a wandering speed
    share = locked_share(np.floor(np.cumsum(speed)).astype(np.int64))
    assert np.isnan(share) or share < 0.1
    assert np.isnan(locked_share(np.zeros(100, dtype=np.int64)))


def test_the_correlations_by_fft_equal_their_sums_over_the_usable_pairs() -> None:
    """Every lag's correlation from the three spectra equals Σ a[k + lag]·a[k] / √(Σ a[k + lag]²·Σ a[k]²) over the
    pairs usable at both ends (the later and the earlier end's sums differ: the mask is not symmetric), to 1e-9; NaN
    where fewer than _MIN_PAIRS pairs."""
    rng = np.random.default_rng(3)
    n = 3_001
    d3 = rng.normal(0.0, 1.0, n) + np.sin(np.arange(n) * 2 * np.pi / 97.0)
    usable = rng.random(n) < np.linspace(0.2, 0.9, n)
    out = _correlations(d3, usable)
    assert out.shape == (n,)
    checked = {True: 0, False: 0}  # lags with enough pairs, and with too few
    for lag in (0, 1, 2, 97, 500, 1_234, 2_000, 2_600, 2_900):
        pair = usable[lag:] & usable[:n - lag]
        later, earlier = d3[lag:][pair], d3[:n - lag][pair]
        enough = pair.sum() >= _MIN_PAIRS
        checked[bool(enough)] += 1
        if enough:
            expected = np.sum(later * earlier) / np.sqrt(np.sum(later**2) * np.sum(earlier**2))
            assert out[lag] == pytest.approx(expected, rel=1e-9, abs=1e-12)
        else:
            assert np.isnan(out[lag])
    assert checked[True] >= 5 and checked[False] >= 1
