"""Stage 3 of the clock alignment: offset and drift from the lag between the current's electrical frequency and the
encoder's (design §4).

The electrical frequency carried by the current (zero-crossing rate of i_a, :mod:`analysis.zero_crossings`) must
equal p·|ω|/2π from the encoder (zero-crossing rate of sin θ_e); the lag between the two, found in windows along the
record, gives offset and drift to a fraction of a ms. Independent of θ_0, of the torque's sign and of the plant.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from analysis.clock_model import MAX_DRIFT_PPM


def frequency_alignment(f_current_hz: np.ndarray, t_daq_s: np.ndarray, f_encoder: Callable[[np.ndarray], np.ndarray],
                        offset_s: float, drift_ppm: float, max_lag_s: float,
                        window_s: float = 2.0) -> tuple[float, float, int]:
    """Stage 3: refine ``offset_s``/``drift_ppm`` so the encoder's electrical frequency matches the current's.

    In each window the lag τ minimising Σ (f_current(t) − f_encoder(t_drive(t) + τ))² over
    |τ| ≤ ``max_lag_s`` is found on the grid and refined by a parabola; a line through the windows'
    lags (outliers beyond 4 MAD dropped) corrects offset and drift. Windows without motion are skipped.

    Parameters
    ----------
    f_current_hz : ndarray
        Current's electrical frequency on the uniform DAQ-time grid ``t_daq_s``, Hz.
    t_daq_s : ndarray
        Uniform grid, s.
    f_encoder : callable
        Encoder's electrical frequency, Hz, as a function of drive time, s.
    offset_s, drift_ppm : float
        Starting relation.
    max_lag_s : float
        Search half-range, s.
    window_s : float
        Window length, s.

    Returns
    -------
    offset_s, drift_ppm : float
        The refined relation (the inputs if no window was usable).
    n_windows : int
        Windows used.
    """
    dt = t_daq_s[1] - t_daq_s[0]
    lags = np.arange(-int(round(max_lag_s / dt)), int(round(max_lag_s / dt)) + 1) * dt
    nw_len = max(3, int(round(window_s / dt)))
    nw = t_daq_s.size // nw_len
    if nw == 0:
        return offset_s, drift_ppm, 0
    n = nw * nw_len
    t_drive = offset_s + t_daq_s[:n] * (1.0 + drift_ppm * 1e-6)
    fc = f_current_hz[:n].reshape(nw, nw_len)
    f_enc0 = f_encoder(t_drive).reshape(nw, nw_len)
    f_top = max(float(np.max(f_enc0)), 1e-9)
    # only where the motor turns fast: there a half period is short and the estimate local; a truncated
    # square ignores the spikes of the current's frequency where i_q changes sign
    fast = f_enc0 > 0.25 * f_top
    weight = fast / np.maximum(fast.sum(axis=1, keepdims=True), 1)
    clip = (0.1 * f_top) ** 2
    cost = np.empty((lags.size, nw))
    for j, lag in enumerate(lags):
        cost[j] = np.sum(weight * np.minimum((fc - f_encoder(t_drive + lag).reshape(nw, nw_len)) ** 2, clip), axis=1)
    moving = (f_enc0.std(axis=1) > 0.05 * f_top) & (fast.mean(axis=1) > 0.1)
    best = np.argmin(cost, axis=0)
    interior = (best > 0) & (best < lags.size - 1)
    ok = moving & interior
    if not ok.any():
        return offset_s, drift_ppm, 0
    cols = np.flatnonzero(ok)
    c0, c1, c2 = cost[best[cols] - 1, cols], cost[best[cols], cols], cost[best[cols] + 1, cols]
    curv = c0 - 2 * c1 + c2
    tau = lags[best[cols]] + dt * np.where(curv > 0, 0.5 * (c0 - c2) / np.where(curv > 0, curv, 1.0), 0.0)
    t_c = t_daq_s[0] + (cols + 0.5) * nw_len * dt
    keep = np.ones(cols.size, bool)
    for _ in range(3):
        a, b = np.polyfit(t_c[keep], tau[keep], 1)[::-1] if keep.sum() >= 3 else (0.0, 0.0)
        if keep.sum() < 3 or abs(drift_ppm + b * 1e6) > MAX_DRIFT_PPM:
            # too few windows for a slope, or a slope no pair of clocks has (a few windows of motion, their lags
            # scattered by ms): the offset only, the starting drift kept — the angle stage fits the drift
            a, b = float(np.median(tau[keep])), 0.0
        r = tau - a - b * t_c
        mad = 1.4826 * np.median(np.abs(r[keep]))
        keep = np.abs(r) <= max(4.0 * mad, 2.0 * dt)
    return offset_s + a, drift_ppm + b * 1e6, int(keep.sum())
