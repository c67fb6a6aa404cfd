"""The motor's electrical offset θ_0 and a phase's sensor DC, by least squares against the encoder's angle.

i = −i_q·sin(θ_e + θ_0) + dc is fitted as a·sin θ_e + b·cos θ_e + c over short windows (:func:`window_phasors`,
also the phase measure of the clock alignment, :mod:`analysis.clock_angle`). θ_0 is known from one phase only modulo π
(the sign of i_q and θ_0 + π give the same current): :func:`phase_offset` returns θ_0 in (−π/2, π/2] and the
caller fixes the sign (one bit) from the motion; :func:`min_speed_rpm` is the slowest motor speed at which it can
be estimated.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from analysis import trig


@dataclass(frozen=True)
class WindowPhasors:
    """Least-squares fits i ≈ a·sin θ_e + b·cos θ_e + c over consecutive windows.

    Attributes
    ----------
    centre_index : ndarray of float
        Sample position of each window's centre (0 = first sample given).
    phasor_a : ndarray of complex
        a + j·b, A; for i = −i_q·sin(θ_e + θ_0) + dc this is −i_q·e^{jθ_0}.
    dc_a : ndarray of float
        c, A.
    valid : ndarray of bool
        The window's angle spans at least ``min_span_rad`` (else the fit is ill-posed; values NaN).
    """

    centre_index: np.ndarray
    phasor_a: np.ndarray
    dc_a: np.ndarray
    valid: np.ndarray


@dataclass(frozen=True)
class PhaseOffset:
    """Electrical offset and sensor DC of one phase.

    Attributes
    ----------
    theta0_rad : float
        θ_0 modulo π, in (−π/2, π/2], rad.
    dc_a : float
        Sensor DC offset, A.
    n_windows : int
        Windows that carried the estimate.
    """

    theta0_rad: float
    dc_a: float
    n_windows: int


def window_phasors(current_a: np.ndarray, theta_e_rad: np.ndarray, window_len: int,
                   min_span_rad: float = np.pi) -> WindowPhasors:
    """Fit a·sin θ_e + b·cos θ_e + c to ``current_a`` over consecutive windows of ``window_len`` samples.

    Parameters
    ----------
    current_a : ndarray
        One phase current, A.
    theta_e_rad : ndarray
        Electrical angle at the same samples, rad.
    window_len : int
        Samples per window (a trailing remainder is dropped).
    min_span_rad : float
        Smallest angle excursion in a window for its fit to count, rad.
    """
    i = np.asarray(current_a, dtype=np.float64)
    th = np.asarray(theta_e_rad, dtype=np.float64)
    if i.shape != th.shape or i.ndim != 1:
        raise ValueError("current_a and theta_e_rad must be 1-D arrays of the same length")
    if window_len < 8:
        raise ValueError(f"window_len must be at least 8 samples, got {window_len}")
    nw = i.size // window_len
    i = i[: nw * window_len].reshape(nw, window_len)
    th = th[: nw * window_len].reshape(nw, window_len)
    s, c = trig.sin_cos(th)
    M = np.empty((nw, 3, 3))
    M[:, 0, 0] = np.einsum("ij,ij->i", s, s)
    M[:, 1, 1] = np.einsum("ij,ij->i", c, c)
    M[:, 0, 1] = M[:, 1, 0] = np.einsum("ij,ij->i", s, c)
    M[:, 0, 2] = M[:, 2, 0] = s.sum(axis=1)
    M[:, 1, 2] = M[:, 2, 1] = c.sum(axis=1)
    M[:, 2, 2] = window_len
    rhs = np.stack([np.einsum("ij,ij->i", s, i), np.einsum("ij,ij->i", c, i), i.sum(axis=1)], axis=1)
    valid = (th.max(axis=1) - th.min(axis=1)) >= min_span_rad
    sol = np.full((nw, 3), np.nan)
    if valid.any():
        sol[valid] = np.linalg.solve(M[valid], rhs[valid, :, None])[..., 0]
    centre = (np.arange(nw) + 0.5) * window_len - 0.5
    return WindowPhasors(centre, sol[:, 0] + 1j * sol[:, 1], sol[:, 2], valid)


class TooSlowError(ValueError):
    """The motor never turns half an electrical revolution within :data:`PHASE_WINDOW_S`: one phase current's angle
    (θ_0) cannot be estimated. A property of the motion, not of the bench or the software: on a machine's own motion
    (no profile) the record did not excite the joint enough for the one-phase torque."""


#: Window of :func:`phase_offset`, s: the motor must turn half an electrical revolution within it.
PHASE_WINDOW_S = 0.02


def min_speed_rpm(pole_pairs: int, window_s: float = PHASE_WINDOW_S) -> float:
    """Slowest motor speed, rpm, that turns half an electrical revolution (1/(2·pole_pairs) rev) within ``window_s``:
    the joint must run faster for that long at a time or :func:`phase_offset` cannot estimate θ_0."""
    return 60.0 * 0.5 / pole_pairs / window_s


def phase_offset(current_a: np.ndarray, theta_e_rad: np.ndarray, rate_hz: float,
                 window_s: float = PHASE_WINDOW_S, pole_pairs: int | None = None,
                 commanded: bool = True) -> PhaseOffset:
    """Estimate θ_0 (mod π) and the sensor DC of one phase by windowed least squares.

    θ_0 is the argument of Σ phasor² / 2 (each window weighted by i_q²); dc the median of the windows'
    constants. Windows where the motor moves less than π electrical are skipped.

    Parameters
    ----------
    current_a, theta_e_rad : ndarray
        Phase current, A, and electrical angle at the same samples, rad.
    rate_hz : float
        Sampling rate, Hz.
    window_s : float
        Window length, s.
    pole_pairs : int, optional
        The motor's pole pairs: the error then says how fast the motor must run.
    commanded : bool
        acq commanded the motion (the error's advice is the profile's); False: a machine's own program moved the
        joint (the advice is to record while it runs fast moves — there is no profile to change).
    """
    w = window_phasors(current_a, theta_e_rad, max(8, int(round(window_s * rate_hz))))
    if not w.valid.any():
        need = "" if pole_pairs is None else (
            f": the motor must run faster than {min_speed_rpm(pole_pairs, window_s):.0f} rpm for {1e3 * window_s:.0f} ms "
            f"at a time ({pole_pairs} pole pairs) — " + (
                "raise the profile's top_speed_rpm, and lengthen accel_time_s and decel_time_s if the drive cannot "
                "follow them" if commanded else "record while the machine runs fast moves of this joint"))
        raise TooSlowError(f"the motor never turns half an electrical revolution within {1e3 * window_s:.0f} ms, so the "
                         f"current's phase (θ_0) and DC cannot be estimated{need}")
    z = np.sum(w.phasor_a[w.valid] ** 2)
    return PhaseOffset(float(np.angle(z) / 2.0), float(np.median(w.dc_a[w.valid])), int(w.valid.sum()))
