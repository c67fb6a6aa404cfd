"""Time-stepping of the simulated joint: discrete speed loop around the exactly discretised plant.

Per control period T (``speed_loop_hz``) the drive reads its encoder (quantised to counts), runs the PI
with acceleration feed-forward, and holds the current reference i_q,ref and the gravity torque T_g over
the period; the plant + current lag then advance by the exact ZOH map. With backlash the period is cut
into :data:`BACKLASH_SUBSTEPS` physics steps (the controller still runs once per period; the load-side
torques are re-evaluated every step). Only [x[k], u[k]] per physics step is stored; the state at any
instant comes from the fine sub-grid (n_sub points per step, exact
through precomputed stacked matrices) and cubic Hermite interpolation between two fine points with the
exact derivative A·x + B·u (error ~1e-6 of a current step).

Torque limit (CiA 402 0x6072, :attr:`JointSimulation.torque_limit_Nm`, infinite unless a simulated drive is told
one): the PI's torque reference is clamped to ±the limit, as a drive's current limit does, and its integrator holds
while the clamp acts against the error (anti-windup by conditional integration); :meth:`JointSimulation.limited_at`
says at which instants the clamp acted (what the drive reports as "internal limit active", 0x6041 bit 11).

Time is the drive's clock in seconds, t = 0 at the first control step. Before t = 0 the joint rests at
its gravity equilibrium. Not thread-safe: :class:`drivers.sim.bench.SimBench` serialises access.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from drivers.sim.joint_effects import JointEffects
from drivers.sim.motion import MotionSchedule
from drivers.sim.plant import N_STATES, SpeedPI, TwoMass, discretise

G_M_S2 = 9.80665
#: physics steps per control period with backlash: the load-side torques are re-evaluated every
#: 250 µs/16 ≈ 16 µs, so a gap of 0.5 mrad (motor side) crossed at a few rad/s takes tens of steps
BACKLASH_SUBSTEPS = 16


@dataclass(frozen=True)
class Gravity:
    """Arm weight through the gear: T_g = m·g·d·cos(φ0 + θ_l/N)/N on the motor side, N·m."""

    mass_kg: float
    com_distance_m: float
    start_rad: float
    ratio: float

    def torque_Nm(self, theta_l_rad: float) -> float:
        """Gravity torque on the motor side, N·m, at load angle ``theta_l_rad`` (motor-side rad)."""
        arm_rad = self.start_rad + theta_l_rad / self.ratio
        return self.mass_kg * G_M_S2 * self.com_distance_m * math.cos(arm_rad) / self.ratio


class _Rows:
    """A growable 2-D array that drops rows at the front cheaply (amortised)."""

    def __init__(self, width: int) -> None:
        self._data = np.empty((1024, width))
        self._lo = 0
        self._hi = 0

    def __len__(self) -> int:
        return self._hi - self._lo

    @property
    def view(self) -> np.ndarray:
        return self._data[self._lo:self._hi]

    def append(self, rows: np.ndarray) -> None:
        n = rows.shape[0]
        if self._hi + n > self._data.shape[0]:
            keep = self.view
            bigger = np.empty((max(2 * (len(self) + n), 1024), self._data.shape[1]))
            bigger[:len(keep)] = keep
            self._data, self._lo, self._hi = bigger, 0, len(keep)
        self._data[self._hi:self._hi + n] = rows
        self._hi += n

    def drop_front(self, n: int) -> None:
        self._lo += min(max(n, 0), len(self))


class JointSimulation:
    """The joint under its speed loop, advanced on demand.

    Parameters
    ----------
    plant : the true joint (simulated truth).
    pi : speed controller (tuned on the nominal inertia).
    gravity : arm weight model.
    counts_per_rev : encoder resolution the speed loop sees, counts/rev.
    schedule : the speed reference.
    n_sub : fine-grid points per control period.
    effects : optional load friction, backlash, third mass, motor friction, cogging and the encoder's eccentricity
        (:mod:`drivers.sim.joint_effects`); the load friction adds to the held load torque input, the backlash
        correction is a third held input, the motor's friction and cogging the last one, the third mass's states
        follow the plant's five; the speed loop reads the eccentric encoder.
    """

    def __init__(self, plant: TwoMass, pi: SpeedPI, gravity: Gravity, counts_per_rev: int,
                 schedule: MotionSchedule, n_sub: int = 16, effects: JointEffects = JointEffects()) -> None:
        self.plant, self.pi, self.gravity, self.schedule = plant, pi, gravity, schedule
        self.effects = effects
        A, B = plant.state_space()
        self.A, self.B = effects.state_space(A, B, plant.Jm_kgm2, plant.Jl_kgm2)
        self.n_states, self.n_inputs = self.B.shape
        # the backlash's held correction needs steps much shorter than the gap's crossing (~1 control period)
        self.n_inner = BACKLASH_SUBSTEPS if effects.backlash is not None else 1
        self.step_s = pi.period_s / self.n_inner
        self.disc = discretise(self.A, self.B, self.step_s, n_sub)
        self.n_sub = n_sub
        self.h_s = self.step_s / n_sub
        self._rad_per_count = 2.0 * math.pi / counts_per_rev
        self.x_rest = self._equilibrium()
        self._x = self.x_rest.copy()
        self._counts_prev = math.floor(self._encoder_rad(self._x[0]) / self._rad_per_count)
        self._integral_Nm = self.gravity.torque_Nm(self._x[2])
        self._iq_ref_A = 0.0
        self._clamped = False
        self._k = 0                      # control steps done
        self._steps = _Rows(self.n_states + self.n_inputs)   # [x[k], u[k]] of steps k0 … k−1
        self._limited = _Rows(1)                              # 1.0 where step k's torque reference was clamped
        #: motor torque limit, N·m (k_t·i_q,ref clamped to ±it); a change acts from the next simulated step on
        self.torque_limit_Nm = math.inf
        self._k0 = 0
        # fine point j of a step (j = 0 … n_sub, n_sub being the next control instant) = Psi[j]·[x[k], u[k]]
        psi = np.concatenate([self.disc.Phi_sub, self.disc.Gam_sub], axis=2)
        last = np.concatenate([self.disc.Ad, self.disc.Bd], axis=1)[None]
        self._psi = np.concatenate([psi, last], axis=0)

    def _equilibrium(self) -> np.ndarray:
        """Rest under gravity: θ_m at half a count, the shaft twisted by T_g/K (plus half the backlash),
        i_q carrying T_g; a third mass rests at the load's angle."""
        p = self.plant
        theta_m = 0.5 * self._rad_per_count
        theta_l = theta_m
        gap = 0.5 * self.effects.backlash.width_rad if self.effects.backlash is not None else 0.0
        for _ in range(5):
            t_g = self.gravity.torque_Nm(theta_l)
            theta_l = theta_m - t_g / p.K_Nm_per_rad - math.copysign(gap, t_g)
        iq = self.gravity.torque_Nm(theta_l) / p.kt_Nm_per_A
        x = np.zeros(self.n_states)
        x[:N_STATES] = [theta_m, 0.0, theta_l, 0.0, iq]
        x[N_STATES:] = [theta_l, 0.0][:self.n_states - N_STATES]
        return x

    def _encoder_rad(self, theta_m_rad: float) -> float:
        """The angle the drive's encoder reads at motor angle ``theta_m_rad`` (rad; the eccentricity's error added)."""
        ecc = self.effects.eccentricity
        return theta_m_rad if ecc is None else float(ecc.read_rad(theta_m_rad))

    @property
    def t_end_s(self) -> float:
        """Drive time up to which states are known, s."""
        return self._k * self.step_s

    @property
    def t_begin_s(self) -> float:
        """Earliest drive time still held (before t = 0 the joint is at rest), s."""
        return self._k0 * self.step_s if self._k0 > 0 else -math.inf

    def advance_to(self, t_s: float) -> None:
        """Simulate until the known span covers ``t_s`` (s, drive clock), i.e. :attr:`t_end_s` > ``t_s``."""
        n = math.floor(t_s / self.step_s) + 1 - self._k
        if n <= 0:
            return
        T, kt = self.pi.period_s, self.plant.kt_Nm_per_A
        kp, ki_T, Jff = self.pi.kp_Nms_per_rad, self.pi.ki_Nm_per_rad * T, self.pi.ff_inertia_kgm2
        speed_ref, accel_ref = self.schedule.reference((self._k + np.arange(n)) * self.step_s)
        n_inner, k0 = self.n_inner, self._k
        iq_ref = self._iq_ref_A
        iq_max = self.torque_limit_Nm / kt
        clamped = self._clamped
        limited = [False] * n
        ff = (Jff * accel_ref).tolist()
        wref = speed_ref.tolist()
        ns = self.n_states
        xs = np.empty((n, ns + self.n_inputs))  # [x[k], u[k]] per step
        AB = self._psi[-1]
        z = np.empty(ns + self.n_inputs)
        friction, backlash = self.effects.friction, self.effects.backlash
        motor = self.effects if self.effects.motor_torque else None
        ecc = self.effects.eccentricity
        motor_col = ns + self.n_inputs - 1
        x, counts_prev, integral = self._x, self._counts_prev, self._integral_Nm
        rad_per_count, q_per_T = self._rad_per_count, self._rad_per_count / T
        g = self.gravity
        g_scale, g_start, g_ratio = g.mass_kg * G_M_S2 * g.com_distance_m / g.ratio, g.start_rad, g.ratio
        for j in range(n):
            if (k0 + j) % n_inner == 0:                             # a control instant
                counts = math.floor((x[0] if ecc is None else ecc.read_rad(x[0])) / rad_per_count)
                err = wref[j] - (counts - counts_prev) * q_per_T
                iq_ref = (ff[j] + kp * err + integral) / kt         # i_q reference, A
                clamped = abs(iq_ref) > iq_max
                if clamped:
                    iq_ref = math.copysign(iq_max, iq_ref)
                if not clamped or (err > 0) != (iq_ref > 0):        # anti-windup: no integration into the clamp
                    integral += ki_T * err
                counts_prev = counts
            limited[j] = clamped
            z[:ns] = x
            z[ns] = iq_ref
            z[ns + 1] = g_scale * math.cos(g_start + x[2] / g_ratio)  # T_g, N·m (= Gravity.torque_Nm)
            if friction is not None:
                z[ns + 1] += friction.torque_Nm(x[3])               # load friction, held like T_g
            if backlash is not None:
                z[ns + 2] = backlash.correction_Nm(x[0] - x[2])     # dead-zone torque pair
            if motor is not None:
                z[motor_col] = motor.motor_torque_Nm(x[0], x[1])    # motor friction + cogging, held like T_g
            xs[j] = z
            x = AB @ z
        self._x, self._counts_prev, self._integral_Nm, self._iq_ref_A = x, counts_prev, integral, iq_ref
        self._clamped = clamped
        self._steps.append(xs)
        self._limited.append(np.array(limited, dtype=float)[:, None])
        self._k += n

    def states_at(self, t_s: np.ndarray) -> np.ndarray:
        """States (n, 5) at drive times ``t_s`` (s); rest before 0. Call :meth:`advance_to` first."""
        t = np.asarray(t_s, dtype=float).ravel()
        out = np.empty((t.size, self.n_states))
        rest = t < 0.0
        out[rest] = self.x_rest
        tt = t[~rest]
        if tt.size == 0:
            return out
        if tt.max() > self.t_end_s + 1e-12 or tt.min() < self.t_begin_s - 1e-12:
            raise ValueError(f"state requested at {tt.min():.6f}…{tt.max():.6f} s outside the simulated span "
                             f"{max(self.t_begin_s, 0.0):.6f}…{self.t_end_s:.6f} s")
        T = self.step_s
        k = np.clip(np.floor(tt / T).astype(np.int64), self._k0, self._k - 1)
        j = np.clip(np.floor((tt - k * T) / self.h_s).astype(np.int64), 0, self.n_sub - 1)
        tau = ((tt - k * T - j * self.h_s) / self.h_s)[:, None]
        z = self._steps.view[k - self._k0]
        x0 = np.einsum("nij,nj->ni", self._psi[j], z)
        x1 = np.einsum("nij,nj->ni", self._psi[j + 1], z)
        bu = z[:, self.n_states:] @ self.B.T
        d0 = (x0 @ self.A.T + bu) * self.h_s
        d1 = (x1 @ self.A.T + bu) * self.h_s
        tau2, tau3 = tau * tau, tau * tau * tau
        out[~rest] = ((2 * tau3 - 3 * tau2 + 1) * x0 + (tau3 - 2 * tau2 + tau) * d0
                      + (3 * tau2 - 2 * tau3) * x1 + (tau3 - tau2) * d1)
        return out

    def limited_at(self, t_s: np.ndarray) -> np.ndarray:
        """Whether the torque limit clamped the reference held at drive times ``t_s`` (s), bool; False before 0.
        Call :meth:`advance_to` first."""
        t = np.asarray(t_s, dtype=float).ravel()
        out = np.zeros(t.size, dtype=bool)
        held = t >= 0.0
        k = np.clip(np.floor(t[held] / self.step_s).astype(np.int64), self._k0, self._k - 1)
        out[held] = self._limited.view[k - self._k0, 0] > 0
        return out

    def forget_before(self, t_s: float) -> None:
        """Drop history older than ``t_s`` (s); later reads before it raise ValueError."""
        k_cut = min(math.floor(t_s / self.step_s), self._k - 1)
        if k_cut > self._k0:
            self._steps.drop_front(k_cut - self._k0)
            self._limited.drop_front(k_cut - self._k0)
            self._k0 = k_cut

    @property
    def held_s(self) -> float:
        """Span of history in memory, s (for tests of the history bound)."""
        return len(self._steps) * self.step_s
