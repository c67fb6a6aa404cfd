"""The one-phase torque's standard error from the angle (analysis.torque.angle_information_std) and the Welch segments
left out where it is an outlying share of the torque (analysis.unknown_torque.unknown_torque_segments), on synthetic
signals."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from analysis.frf import estimate_frf
from analysis.torque import angle_information_std
from analysis.unknown_torque import unknown_torque_segments

NPERSEG, STEP = 500, 250


def _torque(n: int, seed: int = 0) -> np.ndarray:
    return np.random.default_rng(seed).standard_normal(n)


def test_the_standard_error_is_the_noise_over_the_root_of_the_information_in_a_cell() -> None:
    # 25.6 kS/s, 1.25 ms cells (32 samples): at a fixed angle k_t·σ/(√32·|sin|); where sin = 0 no information at all
    theta = np.full(1000, 0.1)
    std = angle_information_std(theta, 0.0, 25600.0, 3.0, 0.01, 1.25e-3)
    assert std[500] == pytest.approx(3.0 * 0.01 / (np.sqrt(32) * np.sin(0.1)), rel=1e-9)
    assert np.isinf(angle_information_std(np.zeros(100), 0.0, 25600.0, 3.0, 0.01, 1.25e-3)).all()


def test_only_the_segment_where_the_error_stands_out_is_left_out() -> None:
    x = _torque(NPERSEG + 20 * STEP)
    std = np.full(x.size, 0.01)
    assert not unknown_torque_segments(x, std, NPERSEG, STEP).any()  # an even error: nothing stands out
    std[10 * STEP + NPERSEG // 2 - 5:10 * STEP + NPERSEG // 2 + 5] = 2.0  # 10 samples mid-segment 10
    out = unknown_torque_segments(x, std, NPERSEG, STEP)
    assert np.flatnonzero(out).tolist() == [10]  # the neighbours hold it at the window's edges only
    std[10 * STEP + NPERSEG // 2] = np.inf  # no information at all there: still that segment alone
    assert np.flatnonzero(unknown_torque_segments(x, std, NPERSEG, STEP)).tolist() == [10]
    keep = np.ones(out.size, dtype=bool)
    keep[10] = False  # a segment the selection did not keep is never flagged (nor are the others)
    assert not unknown_torque_segments(x, std, NPERSEG, STEP, keep).any()


def test_a_noise_free_phase_flags_only_the_segments_without_information_and_warns_nothing() -> None:
    # σ = 0 (a noise-free phase current): the standard error is 0 wherever the angle shows the torque and ∞ where it
    # never does; log R = −∞ has no spread to fence by (the rule overflowed to nothing, with a RuntimeWarning)
    x = _torque(NPERSEG + 20 * STEP, 3)
    theta = np.full(x.size, 0.7)
    theta[10 * STEP + NPERSEG // 2 - 40:10 * STEP + NPERSEG // 2 + 40] = 0.0  # sin = 0 over 80 samples mid-segment 10
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # any RuntimeWarning fails the test
        std = angle_information_std(theta, 0.0, 25600.0, 3.0, 0.0, 1.25e-3)
        assert np.isinf(std).sum() == 80 - 31 and np.count_nonzero(std[np.isfinite(std)]) == 0
        # the three segments that hold the samples without information, as with a noisy phase
        assert np.flatnonzero(unknown_torque_segments(x, std, NPERSEG, STEP)).tolist() == [9, 10, 11]
        noisy = angle_information_std(theta, 0.0, 25600.0, 3.0, 0.01, 1.25e-3)
        assert np.flatnonzero(unknown_torque_segments(x, noisy, NPERSEG, STEP)).tolist() == [9, 10, 11]
        assert not unknown_torque_segments(x, np.zeros(x.size), NPERSEG, STEP).any()  # all known exactly: none
        frf = estimate_frf(x, np.cumsum(x) * 1e-3, 1e-3, torque_std_Nm=std)
    assert frf.n_segments == 18
    std[:] = np.inf  # no information anywhere: nothing to tell the segments apart by, none flagged
    assert not unknown_torque_segments(x, std, NPERSEG, STEP).any()


def test_more_blind_segments_of_a_noise_free_phase_are_flagged_as_with_a_noisy_one_and_an_unknown_error_is_blind() -> None:
    # the second read: 600 samples without information at σ = 0 (five segments) had flagged none where 80 flagged three
    x = _torque(NPERSEG + 40 * STEP, 4)
    theta = np.full(x.size, 0.7)
    theta[20 * STEP + NPERSEG // 2 - 300:20 * STEP + NPERSEG // 2 + 300] = 0.0
    for noise_a in (0.0, 0.01):
        std = angle_information_std(theta, 0.0, 25600.0, 3.0, noise_a, 1.25e-3)
        assert np.flatnonzero(unknown_torque_segments(x, std, NPERSEG, STEP)).tolist() == [18, 19, 20, 21, 22], noise_a
    std = np.full(x.size, 0.01)
    std[10 * STEP + NPERSEG // 2] = np.nan  # an error not known there: no information, as ∞ (it was taken as exact)
    assert np.flatnonzero(unknown_torque_segments(x, std, NPERSEG, STEP)).tolist() == [10]


def test_the_frf_averages_without_the_left_out_segment() -> None:
    x = _torque(NPERSEG + 20 * STEP, 1)
    y = np.cumsum(x) * 1e-3
    std = np.full(x.size, 0.01)
    std[10 * STEP + NPERSEG // 2] = 5.0
    frf = estimate_frf(x, y, 1e-3, torque_std_Nm=std)
    assert np.flatnonzero(frf.unknown_torque).tolist() == [10]
    assert frf.n_segments == 20  # 21 segments, one left out
    assert estimate_frf(x, y, 1e-3, torque_std_Nm=np.full(x.size, 0.01)).n_segments == 21


def test_the_note_names_the_times_of_the_segments_left_out_also_when_the_hop_rounds() -> None:
    # 0.503 s at 1 ms: 503 samples, estimate_frf's hop 503 − round(251.5) = 251 (round half to even), not 252
    from dataclasses import replace

    from analysis.pipeline import _unknown_torque_note

    x = _torque(503 + 31 * 251, 2)
    frf = estimate_frf(x, np.cumsum(x) * 1e-3, 1e-3, segment_s=0.503)
    assert frf.n_segments == 32
    left_out = np.zeros(32, dtype=bool)
    left_out[30] = True
    t_s = 1.0 + np.arange(x.size) * 1e-3
    (note,) = _unknown_torque_note(replace(frf, unknown_torque=left_out), t_s)
    assert "1 of 32 Welch segments left out (8.53–9.03 s)" in note  # 1 s + 30 · 251 ms
