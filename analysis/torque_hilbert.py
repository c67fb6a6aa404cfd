"""The paper's baseline torque (``--torque hilbert``, ``--paper``): T_e = sign·k_t·|hilbert(i_a − mean)| from one
phase, its sign restored at the speed apexes (paper §3.2); no encoder angle enters."""

from __future__ import annotations

import numpy as np
from scipy.signal import butter, find_peaks, hilbert, sosfiltfilt


def apex_sign(speed_rad_s: np.ndarray, period_s: float, smooth_hz: float = 20.0) -> np.ndarray:
    """Sign of the torque restored at the speed apexes (paper §3.2), ±1 per speed sample.

    Between two apexes (extrema of the speed above half its peak) the sign is that of the speed change
    from one apex to the next; before the first apex it heads towards it, after the last away from it.
    The speed is only used to place the sign flips, never to shape the torque.

    Parameters
    ----------
    speed_rad_s : ndarray
        Motor speed, rad/s, on the drive's grid.
    period_s : float
        Drive cycle, s.
    smooth_hz : float
        Cut-off of the zero-phase low-pass applied before looking for apexes, Hz.
    """
    w = np.asarray(speed_rad_s, dtype=np.float64)
    if w.size < 32:
        raise ValueError("need at least 32 speed samples to find apexes")
    ws = sosfiltfilt(butter(2, smooth_hz, fs=1.0 / period_s, output="sos"), w)
    height = 0.5 * np.max(np.abs(ws))
    distance = max(1, int(0.05 / period_s))
    hi, _ = find_peaks(ws, height=height, distance=distance)
    lo, _ = find_peaks(-ws, height=height, distance=distance)
    apex = np.sort(np.concatenate((hi, lo)))
    if apex.size == 0:
        return np.full(w.size, 1.0 if ws[-1] >= ws[0] else -1.0)
    sign = np.empty(w.size)
    sign[: apex[0]] = np.sign(ws[apex[0]])
    for a, b in zip(apex[:-1], apex[1:]):
        sign[a:b] = 1.0 if ws[b] > ws[a] else -1.0
    sign[apex[-1]:] = -np.sign(ws[apex[-1]])
    sign[sign == 0] = 1.0
    return sign


def torque_hilbert(current_a: np.ndarray, k_t_Nm_per_A: float, sign: np.ndarray) -> np.ndarray:
    """The paper's torque: T_e = sign·k_t·|hilbert(i_a − mean)|, N·m.

    Parameters
    ----------
    current_a : ndarray
        One phase current, A.
    k_t_Nm_per_A : float
        Torque constant, N·m/A.
    sign : ndarray
        ±1 per sample (e.g. :func:`apex_sign` mapped onto the DAQ instants).
    """
    i = np.asarray(current_a, dtype=np.float64)
    if np.shape(sign) != i.shape:
        raise ValueError("sign must have one entry per current sample")
    return k_t_Nm_per_A * np.asarray(sign) * np.abs(hilbert(i - i.mean()))
