"""The speed reference of a simulated drive in cyclic synchronous velocity (CiA 402 mode 9).

A master sends a target velocity (0x60FF) by RPDO each cycle; the drive applies it at a SYNC and ramps its
reference linearly from the previous target to the new one, reached at the instant the drive gives it
(the interpolation CiA 402 drives do between cyclic set-points). The physics (:class:`drivers.sim.bench.SimBench`) may already have asked for
times beyond a set-point's instant when it arrives late; what was answered never changes: the previous
target is held up to the latest time asked, and a set-point for an instant already answered (or already
given a newer one) is dropped (counted in :attr:`late`) — as a real drive holds its last set-point when the
next one is late, and a stalled master's burst of SYNCs carries the same present set-point.
"""

from __future__ import annotations

import threading

import numpy as np

#: break points kept before the latest time asked (the physics asks forwards only)
_KEEP_BEHIND = 4


class SetpointReference:
    """Piecewise-linear speed (rad/s) through the applied set-points; ``period_s``: the drive's cycle, s."""

    def __init__(self, period_s: float) -> None:
        self._period_s = period_s
        self._t = [0.0]
        self._v = [0.0]
        self._asked_s = -np.inf
        self._lock = threading.Lock()
        self.late = 0

    def push(self, t_s: float, speed_rad_s: float) -> None:
        """Reach ``speed_rad_s`` (rad/s) at drive time ``t_s`` (s), linearly from the previous set-point (later if
        the physics already answered for ``t_s``)."""
        with self._lock:
            pin = max(self._t[-1], self._asked_s)
            if t_s <= pin:  # its instant is answered already (or a newer set-point's): superseded
                self.late += 1
                return
            if pin > self._t[-1]:  # the previous target was held up to here: keep it so
                self._t.append(pin)
                self._v.append(self._v[-1])
            self._t.append(t_s)
            self._v.append(speed_rad_s)

    def reference(self, t_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Speed (rad/s) and acceleration (rad/s²) at drive times ``t_s`` (s); the last target after the last
        set-point, rest before the first."""
        t = np.asarray(t_s, dtype=float)
        with self._lock:
            if t.size:
                self._asked_s = max(self._asked_s, float(t.max()))
            tt, vv = np.array(self._t), np.array(self._v)
            drop = int(np.searchsorted(tt, self._asked_s)) - _KEEP_BEHIND
            if drop > 256:  # amortised: forget break points the physics will not ask for again
                del self._t[:drop], self._v[:drop]
        speed = np.interp(t, tt, vv)
        slopes = np.r_[0.0, np.diff(vv) / np.diff(tt), 0.0]
        return speed, slopes[np.searchsorted(tt, t, side="right")]
