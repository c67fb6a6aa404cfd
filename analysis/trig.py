"""Sine and cosine of many angles at once, about 4× faster than ``np.sin`` + ``np.cos`` and equal to them to ≈ 1 ulp.

Measured on 1.5·10⁶ angles in ±300 rad (a minute of current), 2 cores at load average 1.0: 12.3 ms against 48.8 ms
(4.0×; 3.7× measured at a higher load), best of 5 of::

    python -m timeit -s "import numpy as np; from analysis.trig import sin_cos; \\
        x = np.random.default_rng(0).uniform(-300, 300, 1_536_000)" "sin_cos(x)"
    python -m timeit -s "import numpy as np; x = np.random.default_rng(0).uniform(-300, 300, 1_536_000)" \\
        "np.sin(x); np.cos(x)"

NumPy's float64 sin and cos call the C library once per element (16 ns per sample on this 2-core machine, about
100× an array multiply); the encoder torque and the clock's angle stage take the sine and cosine of every DAQ sample's
electrical angle (3·10⁶ per minute of session: ~10 % of an analysis). No well-kept library offers a vectorised
float64 sincos for NumPy arrays (SciPy has none; numexpr and numba would be new dependencies for two functions), so
here the textbook table method, in cache-sized blocks of array operations:

x = k·δ + r with δ = 2π/N, k the nearest integer to x/δ (|r| ≤ δ/2), then
sin x = S_k·cos r + C_k·sin r and cos x = C_k·cos r − S_k·sin r, S_k, C_k = sin, cos(k·δ) from an N-entry table and
sin r, cos r from their Taylor series to r⁷ and r⁶ (next terms < 2e-20). δ is split in three parts (Cody–Waite) so
that x − k·δ is exact for |x| ≤ :data:`MAX_FAST_RAD`; larger angles, NaN and ±inf go to NumPy.
"""

from __future__ import annotations

import math
from decimal import Decimal, localcontext

import numpy as np

_N = 256  # table entries per turn (2 × 2 kB, cache-resident)
_BLOCK = 1 << 14  # samples per block of array operations (its ~8 temporaries stay in a core's L2 cache)


def _step_parts() -> tuple[float, float, float]:
    """2π/N as hi + mid + lo: 30, 30 and 53 significant bits (Cody–Waite), from π to 40 digits."""
    with localcontext(prec=60):
        step = 2 * Decimal("3.141592653589793238462643383279502884197") / _N
        hi = math.ldexp(round(math.ldexp(float(step), 35)), -35)  # 2π/N ≈ 0.0245 < 2⁻⁵: 30 significant bits
        mid = math.ldexp(round(math.ldexp(float(step - Decimal(hi)), 65)), -65)  # |step − hi| < 2⁻³⁶: 30 bits
        return hi, mid, float(step - Decimal(hi) - Decimal(mid))


def _table(parts: tuple[float, float, float]) -> tuple[np.ndarray, np.ndarray]:
    """sin and cos of k·2π/N, k = 0 … N − 1: the first quadrant in extended precision (x86's long double), rounded,
    the others by symmetry (so the zeros and ±1 are exact)."""
    step = sum(np.longdouble(p) for p in parts)
    j = np.arange(_N // 4, dtype=np.longdouble)
    s, c = np.sin(j * step).astype(np.float64), np.cos(j * step).astype(np.float64)
    return np.concatenate((s, c, -s, -c)), np.concatenate((c, -s, -c, s))


_STEP_HI, _STEP_MID, _STEP_LO = _step_parts()
_SIN, _COS = _table((_STEP_HI, _STEP_MID, _STEP_LO))
#: Largest |x|, rad, of the table method: k < 2²³ keeps k·hi and k·mid exact (30 + 23 bits). An electrical angle of
#: 2·10⁵ rad is 8 000 revolutions of a 4-pole-pair motor.
MAX_FAST_RAD = 2.0**23 * 2.0 * np.pi / _N
_ROUND = 1.5 * 2.0**52  # adding and subtracting it rounds a double of magnitude < 2⁵¹ to the nearest integer


def sin_cos(x_rad: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """sin and cos of every element of ``x_rad`` (rad, any shape), as ``np.sin`` and ``np.cos`` to ≈ 1 ulp."""
    shape = np.shape(x_rad)  # a 0-d input comes back 0-d (ascontiguousarray makes it 1-d)
    x = np.ascontiguousarray(x_rad, dtype=np.float64)  # C order: the flat views below are views, not copies
    s, c = np.empty(x.shape), np.empty(x.shape)
    if x.size and not (x.max() <= MAX_FAST_RAD and x.min() >= -MAX_FAST_RAD):  # also NaN, ±inf
        np.sin(x, out=s)
        np.cos(x, out=c)
        return s.reshape(shape), c.reshape(shape)
    flat, s_flat, c_flat = x.reshape(-1), s.reshape(-1), c.reshape(-1)
    for a in range(0, flat.size, _BLOCK):
        _block(flat[a:a + _BLOCK], s_flat[a:a + _BLOCK], c_flat[a:a + _BLOCK])
    return s.reshape(shape), c.reshape(shape)


def _block(x: np.ndarray, s: np.ndarray, c: np.ndarray) -> None:
    """sin(x) into ``s`` and cos(x) into ``c`` by the table method (|x| ≤ :data:`MAX_FAST_RAD`)."""
    k = x * (_N / (2.0 * np.pi))
    k += _ROUND
    index = k.view(np.int64) & (_N - 1)  # k mod N from the low bits of the rounded double (two's complement)
    k -= _ROUND
    r = x - k * _STEP_HI
    r -= k * _STEP_MID
    r -= k * _STEP_LO
    r2 = r * r
    sin_r = r2 * (-1.0 / 5040.0)  # Horner: r·(1 − r²/3! + r⁴/5! − r⁶/7!)
    sin_r += 1.0 / 120.0
    sin_r *= r2
    sin_r -= 1.0 / 6.0
    sin_r *= r2
    sin_r *= r
    sin_r += r
    cos_r = r2 * (-1.0 / 720.0)  # 1 − r²/2! + r⁴/4! − r⁶/6!
    cos_r += 1.0 / 24.0
    cos_r *= r2
    cos_r -= 0.5
    cos_r *= r2
    cos_r += 1.0
    s_k, c_k = _SIN.take(index), _COS.take(index)
    np.multiply(s_k, cos_r, out=s)
    s += c_k * sin_r
    np.multiply(c_k, cos_r, out=c)
    c -= s_k * sin_r
