"""The simulated production robot: a program of point-to-point moves that its own controller runs.

With ``[drive] motion = "external"`` the simulated bench takes its speed reference from here, never from
acq (acq only listens, as on a machine whose controller owns the drive). Machine time τ (s) is cut into
cycles of :data:`CYCLE_S`; cycle c is drawn from ``(seed, c)`` alone, so any cycle of any shift is
reproducible without simulating the ones before it:

* with probability ``robot_idle_fraction`` the robot waits the whole cycle (no motion: nothing excites);
* otherwise it moves between random targets until the cycle is full and returns home, each move a trapezoid speed profile (accelerate
  in ``accel_s``, cruise, decelerate in ``accel_s``; a triangle when the move is too short to reach
  the top speed) of random length, top speed and acceleration time, with a pause after each move; a share
  ``robot_s_curve_fraction`` of the moves ramps as an S-curve instead (speed (1 − cos)/2 over the ramp:
  the acceleration rises and falls smoothly, jerk-limited, with the same ramp time and distance);
* the payload (kg at the arm's tip) is drawn per cycle; it changes the gravity load the drive carries.

All positions and speeds are on the motor side (rad, rad/s).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, replace

import numpy as np

from drivers.motion import RPM_TO_RAD_S

#: One program cycle, s: moves fill it (the robot returns home before its end).
CYCLE_S = 15.0
_TARGET_RAD = 12.0            # targets within ±12 rad of home on the motor side (±69° of arm at ratio 10)
_SPEED_RPM = (400.0, 1500.0)  # top speed of a move
_ACCEL_S = (0.08, 0.3)        # time to reach the top speed (sets the torque step and so the excitation)
_PAUSE_S = (0.1, 0.8)         # pause after a move


@dataclass(frozen=True)
class Move:
    """One point-to-point move: starts at ``t_start_s`` (s into its cycle), travels ``distance_rad``."""

    t_start_s: float
    distance_rad: float
    top_rad_s: float
    accel_s: float
    s_curve: bool = False

    @property
    def peak_rad_s(self) -> float:
        """Speed reached, rad/s (below the top speed for a move too short to reach it)."""
        return min(self.top_rad_s, math.sqrt(abs(self.distance_rad) * self.top_rad_s / self.accel_s))

    @property
    def ramp_s(self) -> float:
        """Time to reach :attr:`peak_rad_s`, s."""
        return self.accel_s * self.peak_rad_s / self.top_rad_s

    @property
    def duration_s(self) -> float:
        """Time from rest to rest, s."""
        return self.ramp_s + abs(self.distance_rad) / self.peak_rad_s

    def reference(self, u_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Speed (rad/s) and acceleration (rad/s²) at ``u_s`` (s since the move's start; zero outside it)."""
        v, tr, T = self.peak_rad_s, self.ramp_s, self.duration_s
        sign = math.copysign(1.0, self.distance_rad)
        up, down = (u_s >= 0) & (u_s < tr), (u_s >= T - tr) & (u_s < T)
        cruise = (u_s >= tr) & (u_s < T - tr)
        rise, fall = u_s, T - u_s  # time into the ramp up, time left of the ramp down
        if self.s_curve:  # raised cosine: v·(1 − cos(π·r/tr))/2 covers the same v·tr/2 as the linear ramp
            w = math.pi / tr
            ramp, slope = (lambda r: 0.5 * v * (1.0 - np.cos(w * r))), (lambda r: 0.5 * v * w * np.sin(w * r))
        else:
            ramp, slope = (lambda r: v / tr * r), (lambda r: np.full_like(r, v / tr))
        speed = np.where(up, ramp(rise), 0.0) + np.where(cruise, v, 0.0) + np.where(down, ramp(fall), 0.0)
        accel = np.where(up, slope(rise), 0.0) - np.where(down, slope(fall), 0.0)
        return sign * speed, sign * accel


@dataclass(frozen=True)
class Cycle:
    """One program cycle: its payload (kg) and moves (none when the robot waits)."""

    payload_kg: float
    moves: tuple[Move, ...]


class RobotProgram:
    """The robot's program over machine time.

    Parameters
    ----------
    seed : the program's seed (``[sim] seed``).
    idle_fraction : share of cycles in which the robot waits.
    payload_max_kg : payload per cycle, uniform in 0 … this, kg.
    s_curve_fraction : share of the moves with S-curve ramps (drawn from a stream of its own, so the moves
        themselves do not change with it).
    """

    def __init__(self, seed: int, idle_fraction: float, payload_max_kg: float, s_curve_fraction: float = 0.0) -> None:
        self.seed, self.idle_fraction, self.payload_max_kg = seed, idle_fraction, payload_max_kg
        self.s_curve_fraction = s_curve_fraction

    @functools.lru_cache(maxsize=64)  # noqa: B019 - a few programs live per process, each one bench's
    def cycle(self, index: int) -> Cycle:
        """Cycle ``index`` (0, 1, …), drawn from (seed, index) only."""
        rng = np.random.default_rng([self.seed % 2**32, 0x520B07, index])
        payload = float(rng.uniform(0.0, self.payload_max_kg))
        if rng.random() < self.idle_fraction:
            return Cycle(payload, ())
        moves: list[Move] = []
        t, here = float(rng.uniform(*_PAUSE_S)), 0.0
        while True:  # moves to random targets while one more and the way home still fit in the cycle
            target = float(rng.uniform(-_TARGET_RAD, _TARGET_RAD))
            move, pause = self._move(rng, t, target - here), float(rng.uniform(*_PAUSE_S))
            home = self._move(rng, t + move.duration_s + pause, -target)
            if moves and home.t_start_s + home.duration_s > CYCLE_S:
                break
            moves.append(move)
            t, here = t + move.duration_s + pause, target
        moves.append(self._move(rng, t, -here))
        shapes = np.random.default_rng([self.seed % 2**32, 0x5C0E, index]).random(len(moves)) < self.s_curve_fraction
        return Cycle(payload, tuple(replace(m, s_curve=bool(s)) for m, s in zip(moves, shapes)))

    @staticmethod
    def _move(rng: np.random.Generator, t_start_s: float, distance_rad: float) -> Move:
        return Move(t_start_s, distance_rad, float(rng.uniform(*_SPEED_RPM)) * RPM_TO_RAD_S, float(rng.uniform(*_ACCEL_S)))

    def rest_before(self, tau_s: float) -> float:
        """The latest machine time ≤ ``tau_s`` (s) at which the robot is at rest (a move's start, or itself)."""
        index = math.floor(tau_s / CYCLE_S)
        for move in self.cycle(index).moves:
            start = index * CYCLE_S + move.t_start_s
            if start <= tau_s < start + move.duration_s:
                return start
        return tau_s

    def reference(self, tau_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Speed (rad/s) and acceleration (rad/s²) references at machine times ``tau_s`` (s)."""
        tau = np.asarray(tau_s, dtype=float)
        speed, accel = np.zeros_like(tau), np.zeros_like(tau)
        index = np.floor(tau / CYCLE_S).astype(np.int64)
        for c in np.unique(index):
            sel = index == c
            for move in self.cycle(int(c)).moves:
                v, a = move.reference(tau[sel] - c * CYCLE_S - move.t_start_s)
                speed[sel] += v
                accel[sel] += a
        return speed, accel


class WindowReference:
    """The program as one session's speed reference: drive time t = 0 is machine time ``tau0_s``.

    ``tau0_s`` is a rest instant of the robot (see :meth:`RobotProgram.rest_before`): the simulated joint
    starts every session at rest, so the session begins where the robot rests. Before t = 0 the joint rests.
    """

    def __init__(self, program: RobotProgram, tau0_s: float) -> None:
        self.program, self.tau0_s = program, tau0_s

    def reference(self, t_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Speed (rad/s) and acceleration (rad/s²) at drive times ``t_s`` (s) (the SimBench's source)."""
        t = np.asarray(t_s, dtype=float)
        speed, accel = self.program.reference(self.tau0_s + t)
        return np.where(t < 0, 0.0, speed), np.where(t < 0, 0.0, accel)

    def payload_kg(self) -> float:
        """Payload of the cycle the session starts in, kg."""
        return self.program.cycle(math.floor(self.tau0_s / CYCLE_S)).payload_kg
