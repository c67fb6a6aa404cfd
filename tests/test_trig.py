"""analysis.trig.sin_cos is np.sin and np.cos to a few ulp, on every range the analysis meets and beyond."""

from __future__ import annotations

import numpy as np
import pytest

from analysis.trig import MAX_FAST_RAD, sin_cos


@pytest.mark.parametrize("scale", [1e-3, 1.0, 40.0, 3e3, MAX_FAST_RAD])
def test_sin_cos_equals_numpy(scale: float) -> None:
    """Uniform angles up to ±scale (the last: the table method's limit): within 2.3e-16 of NumPy's values, ≤ 3 ulp."""
    x = np.random.default_rng(5).uniform(-scale, scale, 300_001)  # more than one block, a partial last one
    s, c = sin_cos(x)
    for mine, ref in ((s, np.sin(x)), (c, np.cos(x))):
        assert np.max(np.abs(mine - ref)) <= 2.3e-16
        assert np.max(np.abs(mine - ref) / np.spacing(np.abs(ref))) <= 3.0


def test_sin_cos_near_zeros_and_table_points() -> None:
    """Near the zeros of sin and cos (k·π/2 as doubles) the error stays absolute-tiny, not one ulp of 1."""
    k = np.arange(-60_000, 60_001)
    x = np.concatenate((k * (np.pi / 2), k * (2 * np.pi / 256), [0.0, -0.0]))
    s, c = sin_cos(x)
    assert max(np.max(np.abs(s - np.sin(x))), np.max(np.abs(c - np.cos(x)))) <= 2.3e-16
    near_zero = np.abs(np.sin(x)) < 1e-3
    assert np.max(np.abs(s - np.sin(x))[near_zero]) < 1e-26
    assert np.max(np.abs(c - np.cos(x))[np.abs(np.cos(x)) < 1e-3]) < 1e-26


def test_sin_cos_shape_large_and_special_values() -> None:
    """Any shape; beyond MAX_FAST_RAD, NaN and ±inf NumPy's own results."""
    grid = np.linspace(-7.0, 7.0, 12).reshape(3, 4)
    s, c = sin_cos(grid)
    assert s.shape == c.shape == (3, 4)
    np.testing.assert_allclose(s, np.sin(grid), rtol=0, atol=2.3e-16)
    big = np.array([1e7, -3.5e9, 1e300, 2.0])
    np.testing.assert_array_equal(sin_cos(big)[0], np.sin(big))
    np.testing.assert_array_equal(sin_cos(big)[1], np.cos(big))
    with np.errstate(invalid="ignore"):
        special = sin_cos(np.array([np.nan, np.inf, 1.0]))
    assert np.isnan(special[0][:2]).all() and np.isnan(special[1][:2]).all()
    assert sin_cos(np.array([]))[0].shape == (0,)


@pytest.mark.parametrize("layout", ["transposed", "fortran", "strided"])
def test_sin_cos_of_non_contiguous_arrays(layout: str) -> None:
    """Transposed, Fortran-ordered and strided input: every output element written (once the outputs were
    Fortran-ordered, the blocks went into a flat copy and the caller got uninitialised memory, error ≈ 1)."""
    x = np.random.default_rng(7).uniform(-10.0, 10.0, (300, 400))
    angles = {"transposed": x.T, "fortran": np.asfortranarray(x), "strided": x[:, ::3]}[layout]
    s, c = sin_cos(angles)
    assert s.shape == c.shape == angles.shape
    assert np.max(np.abs(s - np.sin(angles))) <= 2.3e-16
    assert np.max(np.abs(c - np.cos(angles))) <= 2.3e-16


def test_sin_cos_of_a_scalar_keeps_its_shape():
    for x in (np.float64(0.5), np.float64(np.nan)):
        s, c = sin_cos(x)
        assert s.shape == () and c.shape == ()
        np.testing.assert_allclose([s, c], [np.sin(x), np.cos(x)], rtol=0, atol=3e-16)
