"""The triangle speed profile of the paper, as a function of time (SI units, motor side).

One cycle: speed ramps 0 → +top in ``accel_time_s``, stays at top ``cruise_s`` (a trapezoid; 0 by
default), ramps +top → 0 in ``decel_time_s``, rests ``dwell_s``, then the same mirrored (0 → −top → 0),
rests again. The motor torque is then a rectangular wave (paper §3.1). The swing of one half-cycle is
``top·((accel+decel)/2 + cruise)`` rad.

S-curve (``jerk_time_s`` = t_j > 0): each ramp of duration t_r keeps its duration and end speeds, but
its acceleration rises linearly over t_j, holds A = top/(t_r − t_j) and falls linearly over t_j (jerk
limit A/t_j); the ramp is point-symmetric, so the swing is unchanged. t_j is capped at half a ramp.

Speed dither (``speed_dither`` = d > 0): full cycle c (c = 0, 1, … from the start) runs at s_c times the
nominal speed and acceleration, s_c = :func:`speed_factors` — the same timing, s_c times the swing out and
back, so every cycle ends where it started.
"""

from __future__ import annotations

import functools
import secrets

import numpy as np

from drivers.config import Profile

RPM_TO_RAD_S = 2.0 * np.pi / 60.0


def with_dither_seed(profile: Profile) -> Profile:
    """``profile`` itself, or — if it is dithered without a ``dither_seed`` — a copy with a seed drawn from the
    operating system's entropy (the one that must be stored with the session)."""
    if profile.speed_dither == 0.0 or profile.dither_seed is not None:
        return profile
    return profile.model_copy(update={"dither_seed": secrets.randbelow(2**63)})


def speed_factors(profile: Profile, cycles: np.ndarray | int) -> np.ndarray:
    """The factors s_c of full cycles ``cycles`` (numbered 0, 1, … from the start), of the shape of ``cycles``.

    ``numpy.random.default_rng(dither_seed).uniform(1 − d, 1 + d, size)``: one draw per cycle in order (the
    first n draws do not depend on how many are asked for — numpy's generator fills the array in order), so a
    drive, the simulator and an audit all compute the same s_c. All ones for d = 0.
    """
    c = np.asarray(cycles, dtype=np.int64)
    d = profile.speed_dither
    if d == 0.0:
        return np.ones(c.shape)
    if profile.dither_seed is None:
        raise ValueError("a dithered profile needs its dither_seed (drivers.motion.with_dither_seed)")
    count = 1 << max(int(c.max(initial=0)), 1).bit_length()  # a power of two above the last cycle: few cached arrays
    return _factors(profile.dither_seed, d, count)[c]


@functools.lru_cache(maxsize=8)
def _factors(seed: int, dither: float, count: int) -> np.ndarray:
    factors = np.random.default_rng(seed).uniform(1.0 - dither, 1.0 + dither, count)
    factors.flags.writeable = False
    return factors


def half_swing_rad(profile: Profile) -> float:
    """Motor travel of one half-cycle (one ramp up, the cruise and the ramp down), rad."""
    ramps_s = (profile.accel_time_s + profile.decel_time_s) / 2.0 + profile.cruise_s
    return profile.top_speed_rpm * RPM_TO_RAD_S * ramps_s


def _phase(t_s: np.ndarray | float, profile: Profile) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(t, ±s_c: direction of the current half-cycle times its cycle's factor, time u into that half-cycle), s.

    The phase is counted in whole nanoseconds, as a drive's generator counts whole cycles: in floating point,
    t mod the cycle puts an instant at a corner (the apex, where the acceleration reverses) on either side of it
    in different cycles, and the motion would not repeat — measured on the simulated bench: 8 control steps with
    the feed-forward reversed in 10 s, the joint 44 counts (2^17/rev) off its previous period there.
    """
    t = np.asarray(t_s, dtype=float)
    half_ns = round((profile.accel_time_s + profile.cruise_s + profile.decel_time_s + profile.dwell_s) * 1e9)
    cycle, tau_ns = np.divmod(np.round(np.maximum(t, 0.0) * 1e9).astype(np.int64), 2 * half_ns)
    sign = np.where(tau_ns < half_ns, 1.0, -1.0)
    if profile.speed_dither:
        sign = sign * speed_factors(profile, cycle)
    return t, sign, np.mod(tau_ns, half_ns) / 1e9


def peak_ramp_rate(ramp_s: float, jerk_s: float) -> float:
    """The steepest part of a ramp of ``ramp_s`` (s) with jerk time ``jerk_s`` (s), per unit of its speed step, 1/s:
    A = 1/(t_r − t_j), t_j at most t_r/2 (the module's S-curve; 1/t_r for a plain ramp)."""
    return 1.0 / (ramp_s - min(jerk_s, ramp_s / 2.0))


def _ramp(u_s: np.ndarray, ramp_s: float, jerk_s: float) -> tuple[np.ndarray, np.ndarray]:
    """Fraction of the speed step (0…1) and its time derivative (1/s) at ``u_s`` into a ramp of ``ramp_s``."""
    u = np.clip(u_s, 0.0, ramp_s)
    tj = min(jerk_s, ramp_s / 2.0)
    if tj <= 0.0:
        return u / ramp_s, np.full_like(u, 1.0 / ramp_s)
    a = peak_ramp_rate(ramp_s, jerk_s)
    rest = ramp_s - u
    frac = np.where(u < tj, a * u**2 / (2 * tj), np.where(rest < tj, 1.0 - a * rest**2 / (2 * tj), a * (u - tj / 2)))
    rate = np.where(u < tj, a * u / tj, np.where(rest < tj, a * rest / tj, a))
    return frac, rate


def triangle_speed_rad_s(t_s: np.ndarray | float, profile: Profile) -> np.ndarray:
    """Speed reference of the motor, rad/s, at times ``t_s`` (s) since the motion started.

    Zero before the start. Returns an array of the shape of ``t_s``.
    """
    t, sign, u = _phase(t_s, profile)
    top = profile.top_speed_rpm * RPM_TO_RAD_S
    ta, tc, td, tj = profile.accel_time_s, profile.cruise_s, profile.decel_time_s, profile.jerk_time_s
    if tc == 0.0 and tj == 0.0:  # the paper's triangle, exactly as before these options existed
        ramp = np.where(u < ta, u / ta, np.where(u < ta + td, 1.0 - (u - ta) / td, 0.0))
        return np.where(t < 0.0, 0.0, sign * top * ramp)
    up, _ = _ramp(u, ta, tj)
    down, _ = _ramp(u - ta - tc, td, tj)
    ramp = np.where(u < ta + tc, up, 1.0 - down)
    ramp = np.where(u < ta + tc + td, ramp, 0.0)
    return np.where(t < 0.0, 0.0, sign * top * ramp)


def triangle_accel_rad_s2(t_s: np.ndarray | float, profile: Profile) -> np.ndarray:
    """Acceleration reference, rad/s², at times ``t_s`` (s) since the motion started (the feed-forward)."""
    t, sign, u = _phase(t_s, profile)
    top = profile.top_speed_rpm * RPM_TO_RAD_S
    ta, tc, td, tj = profile.accel_time_s, profile.cruise_s, profile.decel_time_s, profile.jerk_time_s
    if tc == 0.0 and tj == 0.0:
        acc = np.where(u < ta, top / ta, np.where(u < ta + td, -top / td, 0.0))
        return np.where(t < 0.0, 0.0, sign * acc)
    _, up = _ramp(u, ta, tj)
    _, down = _ramp(u - ta - tc, td, tj)
    acc = np.where(u < ta, up, np.where(u < ta + tc, 0.0, np.where(u < ta + tc + td, -down, 0.0)))
    return np.where(t < 0.0, 0.0, sign * top * acc)
