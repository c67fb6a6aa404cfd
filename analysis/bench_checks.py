"""The selftest's other bench checks read from the data: the encoder's first move direction, the phase sequence of
2–3 phases against the encoder (:func:`sequence_fault` words a reversed one), and the rigid-body inertia the torque
implies (k_t and the sensor scale against a known inertia).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import signal

from analysis.encoder import speed_from_counts

SEQUENCE_MAX_S = 60.0  # the phase sequence is judged on at most the first minute, s


def sequence_fault(agreement: float, phases: list[str]) -> str | None:
    """The words for a phase sequence turning against the encoder (None unless clearly reversed, < −0.5)."""
    if not agreement < -0.5:
        return None
    swapped = ", ".join(f'"{ {"i_b": "i_c", "i_c": "i_b"}.get(n, n)}"' for n in phases)
    return (f"the phase sequence {'/'.join(n[2:] for n in phases)} turns against the encoder (correlation "
            f"{agreement:+.2f}): set [daq] channels = [{swapped}] (two phases swapped) or reverse the encoder's "
            "counting direction")


def first_move_sign(position_counts: np.ndarray) -> int:
    """+1 / −1: the direction of the encoder's first clear move (5 % of its largest excursion), 0 if none."""
    x = np.asarray(position_counts, dtype=np.float64) - float(position_counts[0])
    reach = float(np.max(np.abs(x))) if x.size else 0.0
    if reach <= 0.0:
        return 0
    first = int(np.argmax(np.abs(x) > 0.05 * reach))
    return int(np.sign(x[first]))


#: e^{−j·s_x} for a phase at electrical shift s_x (a: 0, b: −2π/3, c: +2π/3): Σ i_x·w_x turns with +θ_e.
_SPACE_VECTOR_WEIGHTS = {"i_a": 1.0 + 0j, "i_b": np.exp(2j * np.pi / 3), "i_c": np.exp(-2j * np.pi / 3)}


def phase_sequence_agreement(currents_a: dict[str, np.ndarray], rate_hz: float, encoder_index: np.ndarray,
                             position_counts: np.ndarray, period_s: float, lag_s: float,
                             window_s: float = 0.02) -> float:
    """Correlation (−1…1) of the current space vector's sense of rotation with the encoder's speed.

    With two phases the third is −(sum) (balanced windings). +1: the phases are in the order their
    names say and turn with the encoder; −1: the sequence is reversed (two phases swapped, or the
    encoder counts the other way). ``lag_s`` maps DAQ time to drive time (:attr:`analysis.speed_ratio.SpeedRatio.lag_s`).

    Parameters
    ----------
    currents_a : dict of str → ndarray
        Two or three phases, A, gap-free, DAQ sample 0 at t_daq = 0.
    rate_hz, period_s : float
        DAQ rate, Hz, and drive cycle, s.
    encoder_index, position_counts : ndarray of int
        Drive cycle and unwrapped position of each encoder sample.
    lag_s : float
        Time since the first encoder sample minus DAQ time, s (:attr:`analysis.speed_ratio.SpeedRatio.lag_s`).
    window_s : float
        Windows in which the rotation is summed, s (a few electrical periods at slow speed).
    """
    names = list(currents_a)
    n_max = int(SEQUENCE_MAX_S * rate_hz)  # the sequence is the same all along: bound the memory of long records
    phases = {n: np.asarray(currents_a[n][:n_max], dtype=np.float64) for n in names}
    phases = {n: x - np.median(x) for n, x in phases.items()}  # sensor offsets would add a fixed vector
    if len(phases) == 2:
        (missing,) = set(_SPACE_VECTOR_WEIGHTS) - set(phases)
        phases[missing] = -sum(phases.values())
    z = sum(_SPACE_VECTOR_WEIGHTS[n] * x for n, x in phases.items())
    turn = np.imag(np.conj(z[:-1]) * z[1:])  # ∝ |z|²·dθ per sample: positive while the vector turns forward
    per = max(2, int(window_s * rate_hz))
    n = turn.size // per
    rot = turn[:n * per].reshape(n, per).sum(axis=1)
    t_drive = (np.arange(n) + 0.5) * per / rate_hz + lag_s
    omega = speed_from_counts(position_counts, 1, period_s)  # rev/s: only the sign and shape matter
    t_enc = (np.asarray(encoder_index)[1:] - int(encoder_index[0])) * period_s
    w = np.interp(t_drive, t_enc, omega, left=0.0, right=0.0)
    norm = math.sqrt(float(np.dot(rot, rot)) * float(np.dot(w, w)))
    return float(np.dot(rot, w) / norm) if norm > 0 else float("nan")


@dataclass(frozen=True)
class InertiaFromTorque:
    """The rigid-body inertia the torque implies: T = J·α + b·ω + c·sign ω + gravity + offset, low-passed.

    Attributes
    ----------
    J_kgm2, J_std_kgm2 : float
        Total motor-side inertia J_m + J_l and its standard error, kg·m² (scales with k_t and the
        current sensor's scale).
    """

    J_kgm2: float
    J_std_kgm2: float


def inertia_from_torque(t_s: np.ndarray, torque_Nm: np.ndarray, speed_rad_s: np.ndarray, gear_ratio: float,
                        cutoff_hz: float = 10.0) -> InertiaFromTorque:
    """Fit the joint as one rigid inertia below ``cutoff_hz`` (well under the anti-resonance).

    Below f_a the load follows the motor, so T_e = (J_m + J_l)·α + viscous and Coulomb friction +
    the arm's weight (A·cos + B·sin of the arm angle θ/N) + an offset. Every regressor and the
    torque pass the same zero-phase low-pass; the standard error counts one independent sample per
    1/(2·cutoff).

    Parameters
    ----------
    t_s, torque_Nm, speed_rad_s : ndarray
        Encoder instants (regular), s; electromagnetic torque, N·m; motor speed, rad/s.
    gear_ratio : float
        Motor turns per arm turn.
    cutoff_hz : float
        Low-pass corner, Hz. 10 Hz: the rigid-body error ~ J_l/J·(f/f_a)² is ≤ 3 % for f_a ≥ 55 Hz.
    """
    dt = float(np.median(np.diff(t_s)))
    theta = np.cumsum(speed_rad_s) * dt
    arm = theta / gear_ratio
    columns = [np.gradient(speed_rad_s, dt), speed_rad_s, np.tanh(speed_rad_s / 0.5),  # Coulomb, smoothed at 0.5 rad/s
               np.cos(arm), np.sin(arm), np.ones_like(arm)]
    sos = signal.butter(4, cutoff_hz, fs=1.0 / dt, output="sos")
    X = np.column_stack([signal.sosfiltfilt(sos, c) for c in columns])
    y = signal.sosfiltfilt(sos, torque_Nm)
    edge = min(int(0.5 / dt), X.shape[0] // 10)  # filter transients at both ends
    X, y = X[edge:X.shape[0] - edge], y[edge:y.size - edge]
    coef, *_ = np.linalg.lstsq(X, y, rcond=None)
    resid = y - X @ coef
    n_eff = max(X.shape[0] * 2.0 * cutoff_hz * dt, X.shape[1] + 1.0)
    sigma2 = float(np.dot(resid, resid)) / X.shape[0] * n_eff / (n_eff - X.shape[1])
    cov = sigma2 * np.linalg.inv(X.T @ X) * X.shape[0] / n_eff
    return InertiaFromTorque(float(coef[0]), float(math.sqrt(max(cov[0, 0], 0.0))))
