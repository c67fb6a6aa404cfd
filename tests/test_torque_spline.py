"""The encoder torque's banded least squares (:mod:`analysis.torque_spline`) against a dense solution and the
sample-by-sample definition of its slow-offset basis."""

from __future__ import annotations

import numpy as np
import pytest

from analysis.torque_spline import SlowOffset, bspline_weights, spline_factor, spline_fit


@pytest.mark.parametrize("n, span", [(51_201, 5_120.0), (12_345, 3_333.3), (999, 77.7)])
def test_slow_offset_basis_matches_its_dense_definition(n: int, span: float) -> None:
    """Intervals as min(⌊i/span⌋, last) sample by sample; block values a partition of unity inside the
    supports; the curve Σβ_j·B_j equal to the dense product."""
    basis = SlowOffset(n, span)
    q = np.minimum(np.floor(np.arange(n) / span), basis.intervals - 1)
    np.testing.assert_array_equal(basis.bounds(), np.searchsorted(q, np.arange(basis.intervals + 1)))
    dense = np.zeros((basis.count, n))
    for s0 in range(0, n, 1000):
        index, values = basis.block(s0, min(n, s0 + 1000))
        dense[index, s0:s0 + values.shape[1]] = values
    np.testing.assert_allclose(dense.sum(axis=0), 1.0, atol=1e-12)
    for j, (a, b) in enumerate(basis.support()):
        assert not dense[j, :a].any() and not dense[j, b:].any()
    beta = np.random.default_rng(1).standard_normal(basis.count)
    np.testing.assert_allclose(basis.curve(beta), beta @ dense, atol=1e-12)


def test_spline_fit_equals_the_dense_penalised_least_squares() -> None:
    """β and the spline of the bordered banded solve equal the dense normal equations' to 1e-8 relative."""
    rng = np.random.default_rng(2)
    n, m, smoothing = 3_000, 5, 1e-2
    g = -np.sin(2 * np.pi * 7.0 * np.arange(n) / n)
    offset = SlowOffset(n, 700.0)
    extra = np.stack((np.cos(np.arange(n) * 0.01), np.sin(np.arange(n) * 0.013) * np.linspace(-1.0, 1.0, n)))
    y = rng.standard_normal((n, 2))
    s, beta = spline_fit(y, g, m, spline_factor(g, m, smoothing), extra, offset)

    nk = -(-n // m)
    B = np.zeros((nk * m, nk + 3))
    W = bspline_weights(m)
    for k in range(nk):
        B[k * m:(k + 1) * m, k:k + 4] = W
    B = B[:n]
    X = g[:, None] * B
    U = np.column_stack([offset.curve(e) for e in np.eye(offset.count)] + list(extra))
    D2 = np.diff(np.eye(nk + 3), 2, axis=0)
    A = X.T @ X
    lam = smoothing * np.mean(np.diag(A))
    full = np.column_stack((X, U))
    N = full.T @ full
    N[:nk + 3, :nk + 3] += lam * D2.T @ D2
    sol = np.linalg.solve(N, full.T @ y)
    np.testing.assert_allclose(beta, sol[nk + 3:], rtol=1e-8, atol=1e-10)
    np.testing.assert_allclose(s, B @ sol[:nk + 3], rtol=1e-8, atol=1e-10)


@pytest.mark.parametrize("commanded, advice", [
    (True, "raise the profile's top_speed_rpm, and lengthen accel_time_s and decel_time_s if the drive cannot follow "
           "them"),
    (False, "record while the machine runs fast moves of this joint")])  # no profile to change (the second trial)
def test_a_motor_that_never_turns_half_an_electrical_revolution_gets_advice_for_who_moved_it(
        commanded: bool, advice: str) -> None:
    from analysis.phase_offset import phase_offset

    with pytest.raises(ValueError) as err:
        phase_offset(np.zeros(25600), np.zeros(25600), 25600.0, pole_pairs=4, commanded=commanded)
    assert str(err.value).endswith(f"(4 pole pairs) — {advice}")
