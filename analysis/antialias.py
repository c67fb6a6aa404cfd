"""What the encoder's sampling asks of the torque moved onto its instants: the anti-alias filter's band edges, and
the torque near k·f_enc that the sampling folds onto the band (design §5.3).
"""

from __future__ import annotations

import numpy as np

from analysis import resample
from analysis.recording import Recording

PASS_FRACTION = 0.4  # anti-alias pass edge, × encoder rate
STOP_FRACTION = 0.6  # anti-alias stop edge, × encoder rate
ALIAS_ORDERS = 2  # torque near k·f_enc, k = 1 … ALIAS_ORDERS, folded by the encoder's sampling


def alias_terms(torque_Nm: np.ndarray, rate_hz: float, t0_s: float, t_drive0_s: float, step_s: float,
                t_s: np.ndarray, period_s: float, f_pass_hz: float, f_stop_hz: float) -> np.ndarray:
    """The torque shifted down by k/T (k = 1 … ``ALIAS_ORDERS``), anti-aliased and read at the DAQ times ``t_s``, N·m,
    shape (``ALIAS_ORDERS``, len(t_s)), complex.

    What ends up below ``f_stop_hz`` after the shift is the torque's content up to ``ALIAS_ORDERS``/T + ``f_stop_hz``,
    so the torque is first decimated to the lowest rate that keeps that band (:func:`resample.decimate_keeping`:
    6.4 kS/s from 25.6 kS/s with a 1 kHz encoder), and the shifted rows are filtered at that rate: one row through
    the DAQ-rate filter instead of 2·``ALIAS_ORDERS``.

    Parameters
    ----------
    torque_Nm : ndarray
        Torque at the DAQ samples ``t0_s + i/rate_hz`` (DAQ time), N·m.
    t_drive0_s, step_s : float
        Drive time of the first sample and drive time per DAQ sample, s (the clock relation).
    """
    low, rate = resample.decimate_keeping(torque_Nm, rate_hz, ALIAS_ORDERS / period_s + f_stop_hz)
    turn = _turn(t_drive0_s, step_s * rate_hz / rate, low.size, period_s)
    rows = np.empty((2 * ALIAS_ORDERS, low.size))
    z = low * turn
    for order in range(ALIAS_ORDERS):
        rows[2 * order], rows[2 * order + 1] = z.real, z.imag
        z *= turn
    moved = resample.to_instants(rows, rate, t0_s, t_s, f_pass_hz, f_stop_hz)
    return moved[0::2] + 1j * moved[1::2]


def _turn(t_first_s: float, step_s: float, n: int, period_s: float) -> np.ndarray:
    """e^{−2πj·t/T} at the n uniform instants t = ``t_first_s`` + k·``step_s`` (drive clock, s), T = ``period_s``.

    The phase is linear in k = a·L + b, so the values are the outer product of a coarse table (k = a·L) and a fine
    one (k = b): one complex product per sample instead of one complex exponential (30× faster; the phases, taken
    modulo one turn, agree with the direct evaluation to 1e-10 rad).
    """
    span = 1024
    coarse = np.exp(-2j * np.pi * (((t_first_s + np.arange(-(-n // span)) * (span * step_s)) / period_s) % 1.0))
    fine = np.exp(-2j * np.pi * ((np.arange(span) * (step_s / period_s)) % 1.0))
    return (coarse[:, None] * fine).ravel()[:n]


def band_edges_hz(rec: Recording) -> tuple[float, float]:
    """Pass and stop edges of the anti-alias filter, Hz."""
    return PASS_FRACTION / rec.period_s, STOP_FRACTION / rec.period_s
