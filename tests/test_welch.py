"""analysis.welch.psd is scipy.signal.welch's estimate (Hann, 50 % overlap, density, one-sided) to rounding."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import signal

from analysis.welch import psd


@pytest.mark.parametrize("nperseg, detrend, nfft", [(256, "constant", None), (256, None, None), (255, "constant", None),
                                                    (1000, None, None), (1000, "linear", 8000), (999, "linear", 999)])
def test_psd_equals_scipy_welch(nperseg: int, detrend: str | None, nfft: int | None) -> None:
    """Odd and even segments, each detrending, zero padding; a signal with a large mean, a ramp and a tone."""
    n = np.arange(20_011)
    x = 3.0 + 1e-3 * n + np.sin(2 * np.pi * 0.0123 * n) + np.random.default_rng(3).standard_normal(n.size)
    f_ref, p_ref = signal.welch(x, fs=2_000.0, nperseg=nperseg, nfft=nfft, detrend=detrend or False)
    f, p = psd(x, 2_000.0, nperseg, detrend=detrend, nfft=nfft)
    np.testing.assert_array_equal(f, f_ref)
    np.testing.assert_allclose(p, p_ref, rtol=1e-11, atol=0.0)
