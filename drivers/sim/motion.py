"""The drive's speed reference: triangle profiles started and stopped at given times (drive clock, s).

A stop ramps the reference to zero at the profile's deceleration (top speed / ``decel_time_s``), never
a step. A dithered profile (``speed_dither``) without a ``dither_seed`` gets one drawn at its start
(:func:`drivers.motion.with_dither_seed`; the recorder draws it before, so that the session keeps it). The
schedule only grows forwards in time, so the past of a running simulation never changes.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from drivers.config import Profile
from drivers.motion import RPM_TO_RAD_S, triangle_accel_rad_s2, triangle_speed_rad_s, with_dither_seed


@dataclass
class _Segment:
    profile: Profile
    t_start_s: float
    t_stop_s: float = np.inf


class MotionSchedule:
    """Piecewise speed and acceleration reference of the motor, rad/s and rad/s²."""

    def __init__(self) -> None:
        self._segments: list[_Segment] = []

    @property
    def moving(self) -> bool:
        """True while a started profile has not been told to stop."""
        return bool(self._segments) and np.isinf(self._segments[-1].t_stop_s)

    def start(self, profile: Profile, t_start_s: float) -> float:
        """Start ``profile`` at ``t_start_s`` (s), not before the previous stop ramp ends; return the start."""
        if self.moving:
            raise RuntimeError("a motion is already running; stop it first")
        if self._segments:
            t_start_s = max(t_start_s, self.rest_from_s(self._segments[-1]))
        self._segments.append(_Segment(with_dither_seed(profile), t_start_s))
        return t_start_s

    def stop(self, t_stop_s: float) -> float | None:
        """Begin the ramp to rest at ``t_stop_s`` (s); return the time the motor is at rest, None if idle."""
        if not self.moving:
            return None
        seg = self._segments[-1]
        seg.t_stop_s = max(t_stop_s, seg.t_start_s)
        return self.rest_from_s(seg)

    @staticmethod
    def rest_from_s(seg: _Segment) -> float:
        """Time (s) at which a stopped segment's reference reaches zero."""
        v0 = float(triangle_speed_rad_s(seg.t_stop_s - seg.t_start_s, seg.profile))
        return seg.t_stop_s + abs(v0) / _decel_rad_s2(seg.profile)

    def reference(self, t_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Speed (rad/s) and acceleration (rad/s²) references at drive times ``t_s`` (s)."""
        t = np.asarray(t_s, dtype=float)
        speed = np.zeros_like(t)
        accel = np.zeros_like(t)
        for seg in self._segments:
            run = (t >= seg.t_start_s) & (t < seg.t_stop_s)
            if run.any():
                speed[run] = triangle_speed_rad_s(t[run] - seg.t_start_s, seg.profile)
                accel[run] = triangle_accel_rad_s2(t[run] - seg.t_start_s, seg.profile)
            ramp = t >= seg.t_stop_s
            if np.isfinite(seg.t_stop_s) and ramp.any():
                v0 = float(triangle_speed_rad_s(seg.t_stop_s - seg.t_start_s, seg.profile))
                a = _decel_rad_s2(seg.profile)
                left = np.abs(v0) - a * (t[ramp] - seg.t_stop_s)
                speed[ramp] += np.sign(v0) * np.maximum(left, 0.0)
                accel[ramp] += np.where(left > 0.0, -np.sign(v0) * a, 0.0)
        return speed, accel

    def describe(self) -> list[dict[str, float]]:
        """Start and stop times (s, drive clock) of every motion so far."""
        return [{"t_start_s": s.t_start_s, "t_stop_s": s.t_stop_s} for s in self._segments]


def _decel_rad_s2(profile: Profile) -> float:
    return profile.top_speed_rpm * RPM_TO_RAD_S / profile.decel_time_s
