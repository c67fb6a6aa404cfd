"""Torque onto the encoder instants: zero-phase anti-alias low-pass, then read at those instants.

The encoder is never interpolated; only the torque (sampled ~25× faster) is moved. The chain:

1. :func:`scipy.signal.resample_poly` down by an integer q to ≥ ``8·f_stop`` (its FIR is delay-compensated,
   so zero-phase; its cut-off lies far above the band of interest), computed by :func:`fir_decimate`;
2. a linear-phase Kaiser FIR applied centred (zero-phase): flat to ``f_pass_hz`` (ripple 1e-4),
   ≥ 80 dB down from ``f_stop_hz``, so nothing above ``f_stop`` folds below ``f_enc − f_stop``;
3. a cubic spline read at the instants (the signal is then oversampled ≥ 8× its band).

With the defaults for a 1 kHz encoder (pass 400 Hz, stop 600 Hz) the FRF band up to 400 Hz sees the
torque unfiltered and unaliased. The first and last ``edge_s(...)`` seconds are unreliable (filter
transients); callers keep their instants away from the ends.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np
from scipy.ndimage import map_coordinates, spline_filter1d
from scipy.signal import firwin, kaiserord, oaconvolve

_RIPPLE_DB = 80.0
_KEEP_TRANSITION = 0.25  # transition width of :func:`decimate_keeping`'s filter, × the band it keeps
_DECIMATE_BLOCK = 1 << 14  # outputs per matrix product of :func:`fir_decimate` (its (taps/q + 1) rows stay in cache)


def antialias(x: np.ndarray, rate_hz: float, f_pass_hz: float, f_stop_hz: float) -> tuple[np.ndarray, float]:
    """Zero-phase low-pass and decimate ``x``; returns the filtered signal and its rate, Hz.

    Parameters
    ----------
    x : ndarray
        Signal sampled at ``rate_hz`` (sample 0 at time 0 of its own clock); shape (..., n): several signals
        on the same samples are filtered along the last axis in one call.
    rate_hz : float
        Sampling rate of ``x``, Hz.
    f_pass_hz, f_stop_hz : float
        Pass-band and stop-band edges of the anti-alias filter, Hz (0 < pass < stop).
    """
    if not 0.0 < f_pass_hz < f_stop_hz:
        raise ValueError(f"need 0 < f_pass_hz < f_stop_hz, got {f_pass_hz}, {f_stop_hz}")
    q = max(1, int(rate_hz // (8.0 * f_stop_hz)))
    x = np.asarray(x, dtype=np.float64)
    y = fir_decimate(x, _decimation_fir(q), q) if q > 1 else x
    rate = rate_hz / q
    h = _lowpass(rate, f_pass_hz, f_stop_hz)
    return oaconvolve(y, h.reshape((1,) * (y.ndim - 1) + h.shape), mode="same", axes=-1), rate


def decimate_keeping(x: np.ndarray, rate_hz: float, f_keep_hz: float) -> tuple[np.ndarray, float]:
    """Zero-phase decimation of ``x`` by the largest integer q whose output still carries 0…``f_keep_hz`` flat
    (ripple 1e-4) and unaliased (what folds onto it is ≥ 80 dB down); returns the signal and its rate, Hz.

    The Kaiser FIR passes ``f_keep_hz`` and stops from rate/q − ``f_keep_hz`` (what folds onto ``f_keep_hz``); q
    leaves that transition at least :data:`_KEEP_TRANSITION` × ``f_keep_hz`` wide (the filter's length grows as
    1/width: a cost, not an accuracy choice). Shape (..., n) decimates several signals along the last axis.
    """
    q = max(1, int(rate_hz // ((2.0 + _KEEP_TRANSITION) * f_keep_hz)))
    if q == 1:
        return np.asarray(x, dtype=np.float64), rate_hz
    h = _lowpass(rate_hz, f_keep_hz, rate_hz / q - f_keep_hz)
    return fir_decimate(x, h, q), rate_hz / q


def fir_decimate(x: np.ndarray, h: np.ndarray, q: int) -> np.ndarray:
    """``scipy.signal.resample_poly(x, 1, q, window=h, axis=-1)`` (zero padding, q ≥ 2): every q-th sample of x
    filtered by the FIR h centred on it (delay (len(h) − 1)/2 removed), shape (..., ⌈n/q⌉).

    resample_poly's polyphase loop (:func:`scipy.signal.upfirdn`) multiplies and adds one tap at a time (≈ 2·10⁹ per
    second here: 9 ms for the torque and its noise of a 20 s chunk). The same sums as matrix products: x in rows of q
    samples, y[k] = Σ_r Σ_c x[(k + R − r)·q + c]·G[r, c] with G the taps rearranged by row offset r and phase c, so a
    (taps/q + 1) × q matrix times the rows (BLAS), then the sum of each output's diagonal — 2.2–2.6× faster, equal to
    resample_poly to 1.2e-15 relative (tests/test_resample.py). No library offers a fast integer decimating FIR.
    """
    if q < 2 or np.iscomplexobj(x):
        raise ValueError(f"fir_decimate: needs a real x and an integer factor q ≥ 2 (got q = {q}, "
                         f"{'complex' if np.iscomplexobj(x) else 'real'} x)")
    x = np.asarray(x, dtype=np.float64)
    n_in = x.shape[-1]
    n_out = -(-n_in // q)
    half_len = (h.size - 1) // 2
    pre_pad = q - half_len % q  # resample_poly's alignment: output k centred on input k·q
    first = (half_len + pre_pad) // q
    taps = np.concatenate((np.zeros(pre_pad), h))
    m = -(-taps.size // q)
    taps = np.concatenate((taps, np.zeros(m * q - taps.size)))
    g = np.zeros((m + 1, q))  # g[r, c]: the weight of x[(k + first − r)·q + c] in y[k]
    g[:m, 0] = taps[0::q]
    for c in range(1, q):
        g[1:, c] = taps[q - c::q]
    row0 = first - m  # x in rows of q samples from row0·q on, zero outside it
    y = np.empty(x.shape[:-1] + (n_out,))
    for k0 in range(0, n_out, _DECIMATE_BLOCK):
        k1 = min(n_out, k0 + _DECIMATE_BLOCK)
        blocks = _sample_rows(x, (row0 + k0) * q, k1 - k0 + m, q)
        products = g @ np.swapaxes(blocks, -1, -2)  # (..., m + 1, k1 − k0 + m)
        out = y[..., k0:k1]
        np.copyto(out, products[..., m, :k1 - k0])
        for r in range(m - 1, -1, -1):
            out += products[..., r, m - r:m - r + k1 - k0]
    return y


def _sample_rows(x: np.ndarray, start: int, count: int, q: int) -> np.ndarray:
    """``x[..., start:start + count·q]`` as ``count`` rows of ``q`` samples, shape (..., count, q), zero outside x: a
    view of x where the rows lie inside it (no copy of the record), a zero-padded copy at its ends."""
    stop = start + count * q
    if start >= 0 and stop <= x.shape[-1]:
        return x[..., start:stop].reshape(x.shape[:-1] + (count, q))
    rows = np.zeros(x.shape[:-1] + (count * q,))
    a, b = max(0, start), min(x.shape[-1], stop)
    if a < b:
        rows[..., a - start:b - start] = x[..., a:b]
    return rows.reshape(x.shape[:-1] + (count, q))


# The filters below are designed once per set of arguments (read-only): an analysis asks for the same few ~10 times
# (each chunk, the torque and its alias terms), and scipy's firwin takes ~0.1 ms a call in argument checks.
@lru_cache(maxsize=32)
def _decimation_fir(q: int) -> np.ndarray:
    """resample_poly's own filter for (1, q): a Kaiser (β = 5) windowed sinc of 20·q + 1 taps, cut-off at the new
    Nyquist."""
    h = firwin(20 * q + 1, 1.0 / q, window=("kaiser", 5.0))
    h.flags.writeable = False
    return h


@lru_cache(maxsize=32)
def _lowpass(rate_hz: float, f_pass_hz: float, f_stop_hz: float) -> np.ndarray:
    """Odd-length Kaiser FIR, cut-off midway between the edges."""
    numtaps, beta = kaiserord(_RIPPLE_DB, (f_stop_hz - f_pass_hz) / (0.5 * rate_hz))
    numtaps |= 1
    h = firwin(numtaps, 0.5 * (f_pass_hz + f_stop_hz), window=("kaiser", beta), fs=rate_hz)
    h.flags.writeable = False
    return h


def edge_s(rate_hz: float, f_pass_hz: float, f_stop_hz: float) -> float:
    """Length at each end of a record that the anti-alias filter's transient spoils, s."""
    q = max(1, int(rate_hz // (8.0 * f_stop_hz)))
    return (_lowpass(rate_hz / q, f_pass_hz, f_stop_hz).size // 2 + 20) * q / rate_hz


def sample_at(x: np.ndarray, rate_hz: float, t0_s: float, t_s: np.ndarray) -> np.ndarray:
    """Read a uniformly sampled band-limited signal at instants ``t_s`` (s) by cubic spline.

    Parameters
    ----------
    x : ndarray
        Samples at ``t0_s + i/rate_hz``, shape (..., n) (several signals read at once).
    rate_hz : float
        Sampling rate of ``x``, Hz.
    t0_s : float
        Time of ``x[0]``, s.
    t_s : ndarray
        Instants, s, inside the sampled span.
    """
    t = np.asarray(t_s, dtype=np.float64)
    span = (t0_s, t0_s + (x.shape[-1] - 1) / rate_hz)
    if t.size and (t.min() < span[0] - 1e-12 or t.max() > span[1] + 1e-12):
        raise ValueError(f"instants {t.min():.6f}…{t.max():.6f} s outside the signal {span[0]:.6f}…{span[1]:.6f} s")
    # The interpolating cubic spline through uniform samples by scipy.ndimage: its B-spline prefilter is a recursive
    # filter (O(n), no banded solve) and each instant reads 4 coefficients. It is CubicSpline's interpolant but for
    # the end conditions (mirror instead of not-a-knot), whose effect decays by 2 − √3 ≈ 0.27 per sample from the
    # ends: < 1e-11 beyond the 20 samples of the anti-alias filter's edge_s margin.
    pos = (t - t0_s) * rate_hz
    x = np.asarray(x, dtype=np.float64)
    # into an empty array: ndimage zeroes the output it allocates, and the filter writes every element of it anyway
    coef = spline_filter1d(x, order=3, axis=-1, output=np.empty(x.shape), mode="mirror")
    flat = coef.reshape(-1, coef.shape[-1])
    at = np.reshape(pos, (1, -1))
    out = np.stack([map_coordinates(row, at, order=3, prefilter=False, mode="mirror") for row in flat])
    return out.reshape(coef.shape[:-1] + t.shape)


def to_instants(x: np.ndarray, rate_hz: float, t0_s: float, t_s: np.ndarray, f_pass_hz: float,
                f_stop_hz: float) -> np.ndarray:
    """Anti-alias (zero-phase) then read at ``t_s``: :func:`antialias` followed by :func:`sample_at`.

    Parameters
    ----------
    x : ndarray
        Samples at ``t0_s + i/rate_hz`` (e.g. torque, N·m, at DAQ instants); shape (..., n) moves several
        signals at once (one filter call, one spline), shape (..., len(t_s)) out.
    rate_hz : float
        Sampling rate of ``x``, Hz.
    t0_s : float
        Time of ``x[0]`` on the clock of ``t_s``, s.
    t_s : ndarray
        Target instants, s (e.g. encoder instants mapped into DAQ time).
    f_pass_hz, f_stop_hz : float
        Anti-alias pass and stop edges, Hz.
    """
    y, rate = antialias(x, rate_hz, f_pass_hz, f_stop_hz)
    return sample_at(y, rate, t0_s, t_s)


def linear_at(x: np.ndarray, rate_hz: float, t0_s: float, t_s: np.ndarray) -> np.ndarray:
    """The paper's resampling: linear interpolation at ``t_s`` (s) without anti-alias filter."""
    return np.interp(np.asarray(t_s, dtype=np.float64), t0_s + np.arange(x.size) / rate_hz, x)
