"""A servo drive's profile-position trajectory generator, as the simulated bench's speed reference.

CiA 402 Profile Position with set-of-set-points: each accepted target starts when the previous move
has ended (at rest) and runs a trapezoid — accelerate at 0x6083, cruise at 0x6081, decelerate at
0x6084 — or a triangle when the distance is too short to reach the profile velocity. Two targets
±(top·(accel+decel)/2) apart with top = 0x6081 give exactly the paper's triangle speed profile.
A quick stop (or a disable) ramps the present speed to zero at the given deceleration.

Everything is on the drive clock (s), motor side, rad. The reference is piecewise linear in speed:
segments (t0, t1, v0, a, p0) with v(t) = v0 + a·(t − t0), p(t) = p0 + v0·τ + a·τ²/2. The physics asks
:meth:`ProfileGenerator.reference` for increasing times only, so the generator never changes the
reference before the latest time asked for (the simulated past) and drops segments already used.
Thread-safe: the drive's bus thread edits, the physics reads.
"""

from __future__ import annotations

import math
import threading

import numpy as np

_Segment = tuple[float, float, float, float, float]  # t0, t1, v0 (rad/s), a (rad/s²), p0 (rad)


class ProfileGenerator:
    """Back-to-back point-to-point moves and stop ramps (rad, rad/s, rad/s²; times s, drive clock)."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._segments: list[_Segment] = []
        self._asked_s = -math.inf
        self._end_s = -math.inf
        self._end_rad = 0.0
        self._move_starts: list[float] = []

    def reference(self, t_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Speed (rad/s) and acceleration (rad/s²) at increasing drive times ``t_s`` (s)."""
        t = np.asarray(t_s, dtype=float)
        speed, accel = np.zeros_like(t), np.zeros_like(t)
        with self._lock:
            if t.size:
                self._asked_s = max(self._asked_s, float(t.max()))
            lo = float(t.min(initial=math.inf))
            self._segments = [seg for seg in self._segments if seg[1] > lo] if self._segments else []
            for t0, t1, v0, a, _ in self._segments:
                inside = (t >= t0) & (t < t1)
                speed[inside] = v0 + a * (t[inside] - t0)
                accel[inside] = a
        return speed, accel

    def hold_at(self, position_rad: float) -> None:
        """The commanded position when the drive is enabled at rest (the next move starts from it)."""
        with self._lock:
            self._end_rad = position_rad

    @property
    def commanded_rad(self) -> float:
        """Where the last accepted move ends (rad)."""
        return self._end_rad

    def at_rest(self, t_s: float) -> bool:
        """True if every move and ramp has ended by drive time ``t_s`` (s)."""
        return t_s >= self._end_s

    def pending(self, t_s: float) -> bool:
        """True if an accepted move has not started yet at ``t_s`` (s): the set-point buffer is full."""
        return any(start > t_s for start in self._move_starts)

    def move_to(self, target_rad: float, t_s: float, v_rad_s: float, a_rad_s2: float, d_rad_s2: float) -> float:
        """Queue a move to ``target_rad`` after the present one (not before ``t_s``); its start, s."""
        with self._lock:
            start = max(t_s, self._end_s, math.nextafter(self._asked_s, math.inf))
            distance = target_rad - self._end_rad
            sign, dist = math.copysign(1.0, distance), abs(distance)
            v_top = min(v_rad_s, math.sqrt(2.0 * dist * a_rad_s2 * d_rad_s2 / (a_rad_s2 + d_rad_s2)))
            t_acc, t_dec = v_top / a_rad_s2, v_top / d_rad_s2
            t_cruise = (dist - v_top * (t_acc + t_dec) / 2.0) / v_top if v_top > 0 else 0.0
            p, t = self._end_rad, start
            for duration, v0, a in ((t_acc, 0.0, a_rad_s2), (t_cruise, v_top, 0.0), (t_dec, v_top, -d_rad_s2)):
                if duration > 0:
                    self._segments.append((t, t + duration, sign * v0, sign * a, p))
                    p += sign * (v0 * duration + a * duration**2 / 2.0)
                    t += duration
            self._move_starts = [s for s in self._move_starts if s > t_s] + [start]
            self._end_s, self._end_rad = t, target_rad
            return start

    def stop(self, t_s: float, decel_rad_s2: float) -> float:
        """Ramp to rest from drive time ``t_s`` (s, or the simulated frontier) at ``decel_rad_s2``;
        drops queued moves. Returns the time at rest, s."""
        with self._lock:
            t = max(t_s, math.nextafter(self._asked_s, math.inf))
            v, p = self._state_at(t)
            kept = [(t0, min(t1, t), v0, a, p0) for t0, t1, v0, a, p0 in self._segments if t0 < t]
            duration = abs(v) / decel_rad_s2
            if duration > 0:
                kept.append((t, t + duration, v, -math.copysign(decel_rad_s2, v), p))
            self._segments, self._move_starts = kept, []
            self._end_s = t + duration
            self._end_rad = p + v * duration / 2.0
            return self._end_s

    def _state_at(self, t: float) -> tuple[float, float]:
        """Commanded speed (rad/s) and position (rad) at ``t`` (s), not before the segments held."""
        p_rest = self._segments[0][4] if self._segments else self._end_rad
        for t0, t1, v0, a, p0 in self._segments:
            if t < t0:
                break
            tau = min(t, t1) - t0
            p_rest = p0 + v0 * tau + a * tau**2 / 2.0
            if t < t1:
                return v0 + a * tau, p_rest
        return 0.0, p_rest
