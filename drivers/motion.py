"""The triangle speed profile of the paper, as a function of time (SI units, motor side).

One cycle: speed ramps 0 → +top in ``accel_time_s``, +top → 0 in ``decel_time_s``, rests
``dwell_s``, then the same mirrored (0 → −top → 0), rests again. The motor torque is then a
rectangular wave (paper §3.1). The swing of one half-cycle is ``top·(accel+decel)/2`` rad.
"""

from __future__ import annotations

import numpy as np

from drivers.config import Profile

RPM_TO_RAD_S = 2.0 * np.pi / 60.0


def cycle_period_s(profile: Profile) -> float:
    """Duration of one full back-and-forth cycle, s."""
    return 2.0 * (profile.accel_time_s + profile.decel_time_s + profile.dwell_s)


def half_swing_rad(profile: Profile) -> float:
    """Motor travel of one half-cycle (one ramp up and down), rad."""
    return profile.top_speed_rpm * RPM_TO_RAD_S * (profile.accel_time_s + profile.decel_time_s) / 2.0


def _phase(t_s: np.ndarray | float, profile: Profile) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(t, direction ±1 of the current half-cycle, time u into that half-cycle), s."""
    t = np.asarray(t_s, dtype=float)
    half = profile.accel_time_s + profile.decel_time_s + profile.dwell_s
    tau = np.mod(np.maximum(t, 0.0), 2.0 * half)
    return t, np.where(tau < half, 1.0, -1.0), np.mod(tau, half)


def triangle_speed_rad_s(t_s: np.ndarray | float, profile: Profile) -> np.ndarray:
    """Speed reference of the motor, rad/s, at times ``t_s`` (s) since the motion started.

    Zero before the start. Returns an array of the shape of ``t_s``.
    """
    t, sign, u = _phase(t_s, profile)
    top = profile.top_speed_rpm * RPM_TO_RAD_S
    ta, td = profile.accel_time_s, profile.decel_time_s
    ramp = np.where(u < ta, u / ta, np.where(u < ta + td, 1.0 - (u - ta) / td, 0.0))
    return np.where(t < 0.0, 0.0, sign * top * ramp)


def triangle_accel_rad_s2(t_s: np.ndarray | float, profile: Profile) -> np.ndarray:
    """Acceleration reference, rad/s², at times ``t_s`` (s) since the motion started (the feed-forward)."""
    t, sign, u = _phase(t_s, profile)
    top = profile.top_speed_rpm * RPM_TO_RAD_S
    ta, td = profile.accel_time_s, profile.decel_time_s
    acc = np.where(u < ta, top / ta, np.where(u < ta + td, -top / td, 0.0))
    return np.where(t < 0.0, 0.0, sign * acc)
