"""Torque onto the encoder instants: zero-phase anti-alias low-pass, then read at those instants.

The encoder is never interpolated; only the torque (sampled ~25× faster) is moved. The chain:

1. :func:`scipy.signal.resample_poly` down by an integer q to ≥ ``8·f_stop`` (its FIR is delay-compensated,
   so zero-phase; its cut-off lies far above the band of interest);
2. a linear-phase Kaiser FIR applied centred (zero-phase): flat to ``f_pass_hz`` (ripple 1e-4),
   ≥ 80 dB down from ``f_stop_hz``, so nothing above ``f_stop`` folds below ``f_enc − f_stop``;
3. a cubic spline read at the instants (the signal is then oversampled ≥ 8× its band).

With the defaults for a 1 kHz encoder (pass 400 Hz, stop 600 Hz) the FRF band up to 400 Hz sees the
torque unfiltered and unaliased. The first and last ``edge_s(...)`` seconds are unreliable (filter
transients); callers keep their instants away from the ends.
"""

from __future__ import annotations

import numpy as np
from scipy.ndimage import map_coordinates, spline_filter1d
from scipy.signal import firwin, kaiserord, oaconvolve, resample_poly

_RIPPLE_DB = 80.0
_KEEP_TRANSITION = 0.25  # transition width of :func:`decimate_keeping`'s filter, × the band it keeps


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
    y = resample_poly(x, 1, q, axis=-1) if q > 1 else x
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
    return resample_poly(x, 1, q, window=h, axis=-1), rate_hz / q


def _lowpass(rate_hz: float, f_pass_hz: float, f_stop_hz: float) -> np.ndarray:
    """Odd-length Kaiser FIR, cut-off midway between the edges."""
    numtaps, beta = kaiserord(_RIPPLE_DB, (f_stop_hz - f_pass_hz) / (0.5 * rate_hz))
    numtaps |= 1
    return firwin(numtaps, 0.5 * (f_pass_hz + f_stop_hz), window=("kaiser", beta), fs=rate_hz)


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
    coef = spline_filter1d(np.asarray(x, dtype=np.float64), order=3, axis=-1, mode="mirror")
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
