"""The excess incoherence (analysis/excess_incoherence.py): the coherence lost beyond the encoder's quantisation, the
torque estimate's noise and the Welch window's own loss, judged by the session's own replicates, and the systematic
error of ln H it stands for."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from analysis.excess_incoherence import excess, excess_std, excess_words, replicate_excess, with_excess_reason
from analysis.frf import FrequencyResponse

PERIOD_S = 1.0 / 2000.0  # a 2 kHz encoder
BAND = (10.0, 200.0)


def response(coherence: np.ndarray, noise_ratio: float = 0.0, torque_psd: float = 1.0) -> FrequencyResponse:
    """An FRF on 2 Hz bins to 400 Hz with |H| = 1 (rad/s)/(N·m), ``torque_psd`` (N·m)²/Hz and ``coherence``."""
    f = np.arange(201) * 2.0
    return FrequencyResponse(f_hz=f, H=np.ones(f.size, complex), coherence=coherence,
                             torque_psd=np.full(f.size, torque_psd),
                             torque_psd_fine=np.ones(4 * f.size), segment_s=0.5, n_segments=30, period_s=PERIOD_S,
                             noise_ratio=np.full(f.size, noise_ratio))


def test_the_known_causes_explain_the_coherence_they_leave_and_the_rest_is_the_excess() -> None:
    # the window leaves 0.95, the torque estimate's noise 10 % of the torque: 0.95/1.1 is explained; a record at
    # 0.95/1.1/1.05 has 0.05·1.1/0.95 = 0.0579 of unexplained noise-to-signal (a tiny lsb: no quantisation)
    window = response(np.full(201, 0.95))
    explained = response(np.full(201, 0.95 / 1.1), noise_ratio=0.1)
    extra = response(np.full(201, 0.95 / 1.1 / 1.05), noise_ratio=0.1)
    e0, reps0 = replicate_excess(explained, window, BAND, 1e-12)
    e1, _ = replicate_excess(extra, window, BAND, 1e-12)
    assert e0.size == 96 and np.allclose(e0, 0.0, atol=1e-12) and reps0.shape == (0, 96)  # no replicates: none
    assert np.allclose(e1, 0.05 * 1.1 / 0.95, rtol=1e-9)


def test_each_replicate_is_judged_against_its_own_model_estimate() -> None:
    # two replicate pairs: the first's window loss matches its coherence (no excess), the second loses 1/0.8 − 1/0.9
    full = replace(response(np.full(201, 0.9)),
                   replicates=(response(np.full(201, 0.8)), response(np.full(201, 0.8))))
    model = replace(response(np.full(201, 0.9)),
                    replicates=(response(np.full(201, 0.8)), response(np.full(201, 0.9))))
    e, reps = replicate_excess(full, model, BAND, 1e-12)
    assert np.allclose(e, 0.0) and reps.shape == (2, 96)
    assert np.allclose(reps[0], 0.0) and np.allclose(reps[1], 1 / 0.8 - 1 / 0.9)
    lopsided = replace(model, replicates=model.replicates[:1])  # the blocks do not pair: nothing to calibrate with
    assert replicate_excess(full, lopsided, BAND, 1e-12)[1].shape == (0, 96)


def test_the_encoders_quantisation_is_a_known_cause() -> None:
    # the white quantisation of a 2 kHz encoder's speed, 8·lsb²/12·sin²(πfT)/T, over the speed 1e-3 (N·m)²/Hz of torque
    # drives through the backward difference, |H|²·sinc²(fT)·G_xx: q² = (2/3)·lsb²·π²f²T/1e-3, 0.033 at 100 Hz for
    # 1 mrad per count; a coherence of 1/(1 + q²) is all explained
    f = np.arange(201) * 2.0
    lsb = 1e-3
    q2 = (2 / 3 * lsb**2 * np.pi**2 * f**2 * PERIOD_S / 1e-3)[5:101]  # the bins of 10…200 Hz
    coherence = np.ones(201)
    coherence[5:101] = 1 / (1 + q2)
    window = response(np.ones(201))
    sel = (f >= 10.0) & (f <= 200.0)
    e = excess(response(coherence, torque_psd=1e-3), window, sel, lsb)
    assert np.isclose(q2[45], 0.0329, rtol=1e-3) and np.allclose(e, 0.0, atol=1e-9)
    e_fine = excess(response(coherence, torque_psd=1e-3), window, sel, lsb / 2)
    assert np.allclose(e_fine, 0.75 * q2, rtol=1e-6)  # an encoder twice as fine explains a quarter of it


def test_only_a_window_whose_mean_stands_out_of_its_jackknife_scatter_gives_a_floor() -> None:
    # 3 windows of 8 bins, 10 replicates whose window means alternate ±δ around the record's: the jackknife standard
    # error is √(9/10·10δ²) = 3δ; one-sided 95 % shared by 3 windows, t(9) = 2.5096
    e = np.concatenate([np.full(8, 0.09), np.full(8, 0.07), np.full(8, 0.012)])
    sign = np.where(np.arange(10) % 2 == 0, 1.0, -1.0)[:, None]
    delta = np.concatenate([np.full(8, 0.01), np.full(8, 0.01), np.full(8, 0.001)])
    std = excess_std(e, e + sign * delta)
    # 0.09 > 2.5096·0.03 = 0.0753 stands out, 0.07 does not; 0.012 > 2.5096·0.003 does
    assert np.allclose(std[:8], 0.3) and np.all(std[8:16] == 0.0) and np.allclose(std[16:], np.sqrt(0.012))
    assert np.all(excess_std(e, (e + sign * delta)[:1]) == 0.0)  # one replicate: no scatter to judge by
    assert np.all(excess_std(np.full(8, np.nan), np.zeros((10, 8))) == 0.0)  # no signal: no floor
    assert np.all(excess_std(np.full(8, -0.01), np.full((10, 8), -0.01)) == 0.0)  # less lost than known: none


def test_the_words_name_the_band_and_the_reason_sits_after_the_intervals() -> None:
    f = np.arange(10.0, 74.0, 2.0)
    std = np.where((f >= 26) & (f < 58), 0.1, 0.0)
    std[f == 50] = 0.4
    said = excess_words(f, std)
    assert said.startswith("the speed follows the torque less closely at 26…56 Hz than the encoder's resolution")
    assert "by up to 40 % of |H| near 50 Hz" in said and "friction" in said
    assert excess_words(f, np.zeros(f.size)) is None
    reasons = ("K is known only to ±7.4 % (95 %)", "J_l is known only to ±11.1 % (95 %)", "note: clock")
    assert with_excess_reason(reasons, "w") == (*reasons[:2], "w", "note: clock")
    assert with_excess_reason(("mean coherence 0.5", "note: x"), "w") == ("mean coherence 0.5", "w", "note: x")
