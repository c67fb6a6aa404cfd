"""analysis.resample.fir_decimate is scipy.signal.resample_poly(x, 1, q, window=h) to rounding."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.signal import firwin, resample_poly

from analysis.resample import fir_decimate


@pytest.mark.parametrize("n", [1, 2, 7, 40, 101, 12_345, 40_003])
@pytest.mark.parametrize("q", [2, 3, 4, 5, 7])
def test_fir_decimate_equals_resample_poly(n: int, q: int) -> None:
    """resample_poly's own filter and windows of odd, even, short and long lengths; one signal and two at once."""
    rng = np.random.default_rng(n * 10 + q)
    x = rng.standard_normal((2, n))
    own = firwin(20 * q + 1, 1.0 / q, window=("kaiser", 5.0))
    for h in (own, rng.standard_normal(33), rng.standard_normal(20), rng.standard_normal(107), rng.standard_normal(3)):
        ref = resample_poly(x, 1, q, window=h, axis=-1)
        got = fir_decimate(x, h, q)
        assert got.shape == ref.shape
        np.testing.assert_allclose(got, ref, rtol=0.0, atol=2e-15 * np.abs(ref).max())
        np.testing.assert_allclose(fir_decimate(x[1], h, q), ref[1], rtol=0.0, atol=2e-15 * np.abs(ref).max())
    np.testing.assert_allclose(fir_decimate(x, own, q), resample_poly(x, 1, q, axis=-1), rtol=0.0,
                               atol=2e-15 * np.abs(x).max())


def test_fir_decimate_refuses_q_below_2_and_complex_input() -> None:
    """q = 1 gave wrong values and complex x lost its imaginary part, silently: now one clear ValueError each."""
    h = firwin(21, 0.5)
    with pytest.raises(ValueError, match=r"^fir_decimate: needs a real x and an integer factor q ≥ 2 \(got q = 1, real x\)$"):
        fir_decimate(np.ones(100), h, 1)
    with pytest.raises(ValueError, match=r"^fir_decimate: needs a real x and an integer factor q ≥ 2 \(got q = 2, complex x\)$"):
        fir_decimate(np.ones(100) * (1 + 1j), h, 2)
