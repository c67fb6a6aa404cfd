"""Which bins read the resonance peak (analysis.input_noise.resonance_bins), where H2 replaces H1 for C's interval."""

from __future__ import annotations

import numpy as np

from analysis.frf import KERNEL_HALF_WIDTH_BINS
from analysis.input_noise import resonance_bins
from analysis.model import TwoMassParams

PAPER = TwoMassParams(K_Nm_per_rad=891.0, Jm_kgm2=0.003027, Jl_kgm2=0.00748, C_Nms_per_rad=0.1)
F_HZ = np.arange(0.0, 500.0, 2.0)  # 0.5 s Welch segments


def test_the_half_power_band_widened_by_the_kernel() -> None:
    bins = F_HZ[resonance_bins(F_HZ, PAPER, (10.0, 400.0))]
    assert PAPER.resonance_hz == np.clip(PAPER.resonance_hz, bins[0], bins[-1])  # 102.3 Hz inside
    assert bins.size == np.ptp(bins) / 2.0 + 1  # contiguous
    assert bins.size >= 2 * KERNEL_HALF_WIDTH_BINS + 1


def test_a_band_ending_just_above_the_resonance_still_has_its_peak_and_one_below_it_has_none() -> None:
    # the second read: the band's top at 103 Hz puts the peak on the band's last bin (102 Hz), which counted as "no
    # peak", so C's interval silently lost its input-noise bound
    assert F_HZ[resonance_bins(F_HZ, PAPER, (10.0, 103.0))].tolist() == list(np.arange(92.0, 112.0, 2.0))
    assert not resonance_bins(F_HZ, PAPER, (10.0, 90.0)).any()  # the rising flank, f_r beyond the band: no peak
