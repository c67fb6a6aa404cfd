"""analysis.welch.psd is scipy.signal.welch's estimate (Hann, 50 % overlap, density, one-sided) to rounding."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import signal

from analysis.welch import psd


@pytest.mark.parametrize("nperseg, detrend", [(256, True), (256, False), (255, True), (1000, False)])
def test_psd_equals_scipy_welch(nperseg: int, detrend: bool) -> None:
    """Odd and even segments, with and without the mean removed, a signal with a large mean and a tone."""
    n = np.arange(20_011)
    x = 3.0 + np.sin(2 * np.pi * 0.0123 * n) + np.random.default_rng(3).standard_normal(n.size)
    f_ref, p_ref = signal.welch(x, fs=2_000.0, nperseg=nperseg, detrend="constant" if detrend else False)
    f, p = psd(x, 2_000.0, nperseg, detrend=detrend)
    np.testing.assert_array_equal(f, f_ref)
    np.testing.assert_allclose(p, p_ref, rtol=1e-11, atol=0.0)
