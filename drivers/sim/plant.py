"""The simulated joint as linear numerics: two-mass plant, current lag, ZOH discretisation, speed PI.

Everything is reflected to the motor side, SI units. The state vector is

    x = [θ_m (rad), ω_m (rad/s), θ_l (rad), ω_l (rad/s), i_q (A)]

and the inputs held over a control period are u = [i_q reference (A), gravity torque T_g (N·m)].
The plant is the paper's eq. 3; the current loop is a first-order lag of bandwidth ``current_bw_hz``
and T_e = k_t·i_q. Nonlinear gravity enters only through T_g, which the caller holds per period.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.linalg import expm

N_STATES = 5
N_INPUTS = 2


@dataclass(frozen=True)
class TwoMass:
    """Two-mass joint with a current loop, motor side.

    Attributes
    ----------
    K_Nm_per_rad : joint stiffness, N·m/rad.
    Jm_kgm2, Jl_kgm2 : motor and load inertia, kg·m².
    C_Nms_per_rad : joint damping, N·m·s/rad.
    bm_Nms_per_rad, bl_Nms_per_rad : viscous friction of motor and load, N·m·s/rad.
    kt_Nm_per_A : torque constant, N·m/A.
    current_bw_hz : bandwidth of the current loop (first-order lag), Hz.
    """

    K_Nm_per_rad: float
    Jm_kgm2: float
    Jl_kgm2: float
    C_Nms_per_rad: float
    bm_Nms_per_rad: float
    bl_Nms_per_rad: float
    kt_Nm_per_A: float
    current_bw_hz: float

    def state_space(self) -> tuple[np.ndarray, np.ndarray]:
        """Continuous ``(A, B)`` with ẋ = A·x + B·u (states and inputs as in the module docstring)."""
        K, C, Jm, Jl = self.K_Nm_per_rad, self.C_Nms_per_rad, self.Jm_kgm2, self.Jl_kgm2
        bm, bl = self.bm_Nms_per_rad, self.bl_Nms_per_rad
        wc = 2.0 * np.pi * self.current_bw_hz
        A = np.array([
            [0.0, 1.0, 0.0, 0.0, 0.0],
            [-K / Jm, -(C + bm) / Jm, K / Jm, C / Jm, self.kt_Nm_per_A / Jm],
            [0.0, 0.0, 0.0, 1.0, 0.0],
            [K / Jl, C / Jl, -K / Jl, -(C + bl) / Jl, 0.0],
            [0.0, 0.0, 0.0, 0.0, -wc],
        ])
        B = np.zeros((N_STATES, N_INPUTS))
        B[4, 0] = wc
        B[3, 1] = -1.0 / Jl
        return A, B

    def resonances_hz(self) -> tuple[float, float]:
        """Undamped anti-resonance f_a = √(K/J_l)/2π and resonance f_r = √(K(J_m+J_l)/(J_m J_l))/2π, Hz."""
        K, Jm, Jl = self.K_Nm_per_rad, self.Jm_kgm2, self.Jl_kgm2
        return float(np.sqrt(K / Jl) / (2 * np.pi)), float(np.sqrt(K * (Jm + Jl) / (Jm * Jl)) / (2 * np.pi))

    def scaled(self, K: float = 1.0, Jm: float = 1.0, Jl: float = 1.0) -> TwoMass:
        """The same joint with K, J_m, J_l multiplied by the given factors."""
        return TwoMass(self.K_Nm_per_rad * K, self.Jm_kgm2 * Jm, self.Jl_kgm2 * Jl, self.C_Nms_per_rad,
                       self.bm_Nms_per_rad, self.bl_Nms_per_rad, self.kt_Nm_per_A, self.current_bw_hz)


@dataclass(frozen=True)
class Discretised:
    """Exact zero-order-hold discretisation over one control period, with a fine sub-grid.

    Attributes
    ----------
    period_s : control period T, s.
    Ad, Bd : x[k+1] = Ad·x[k] + Bd·u[k] over one period.
    Phi_sub, Gam_sub : shape (n_sub, 5, 5) and (n_sub, 5, 2): state at t_k + j·T/n_sub, j = 0…n_sub−1,
        is Phi_sub[j]·x[k] + Gam_sub[j]·u[k].
    """

    period_s: float
    Ad: np.ndarray
    Bd: np.ndarray
    Phi_sub: np.ndarray
    Gam_sub: np.ndarray


def discretise(A: np.ndarray, B: np.ndarray, period_s: float, n_sub: int) -> Discretised:
    """ZOH-discretise ``(A, B)`` over ``period_s`` (s) and its ``n_sub`` equal sub-steps (matrix exponential)."""
    n, m = B.shape
    M = np.zeros((n + m, n + m))
    M[:n, :n], M[:n, n:] = A, B
    Phi = np.empty((n_sub + 1, n, n))
    Gam = np.empty((n_sub + 1, n, m))
    for j in range(n_sub + 1):
        E = expm(M * (period_s * j / n_sub))
        Phi[j], Gam[j] = E[:n, :n], E[:n, n:]
    return Discretised(period_s, Phi[n_sub], Gam[n_sub], Phi[:n_sub], Gam[:n_sub])


@dataclass(frozen=True)
class SpeedPI:
    """Discrete PI speed controller with acceleration feed-forward, output in N·m.

    T_ref[k] = J_ff·α_ref[k] + kp·e[k] + I[k],  I[k+1] = I[k] + ki·T·e[k],  e = ω_ref − ω̂,
    with ω̂[k] = (θ̂[k] − θ̂[k−1])/T from the quantised encoder angle θ̂. No gravity model: the
    integrator carries it.

    Attributes
    ----------
    kp_Nms_per_rad : proportional gain, N·m·s/rad.
    ki_Nm_per_rad : integral gain, N·m/rad (per second of integrated speed error).
    ff_inertia_kgm2 : feed-forward inertia J_ff, kg·m².
    period_s : control period T, s.
    """

    kp_Nms_per_rad: float
    ki_Nm_per_rad: float
    ff_inertia_kgm2: float
    period_s: float


def tune_speed_pi(J_total_kgm2: float, bandwidth_hz: float, period_s: float, zero_ratio: float = 4.0) -> SpeedPI:
    """Tune a PI for crossover ``bandwidth_hz`` on a rigid inertia ``J_total_kgm2``.

    kp = J·ω_c puts the crossover at ω_c; the PI zero sits at ω_c/``zero_ratio`` (phase margin ≈ 76°
    for 4). The nominal total inertia also sets the feed-forward.
    """
    wc = 2.0 * np.pi * bandwidth_hz
    kp = J_total_kgm2 * wc
    return SpeedPI(kp, kp * wc / zero_ratio, J_total_kgm2, period_s)


def closed_loop_poles(plant: TwoMass, pi: SpeedPI) -> np.ndarray:
    """Discrete closed-loop poles (z-plane) of plant + current lag + quantisation-free speed PI.

    Closed-loop state: [x (5), θ_m[k−1], I[k]]. A speed loop leaves the absolute position free: shifting
    θ_m, θ_l and θ_m[k−1] together is an exact eigenvector with z = 1, which is projected out, so the
    six poles returned are the dynamics that matter. Gravity is a disturbance (its slope, m·g·d/N², is
    negligible against K) and does not move the poles.
    """
    A, B = plant.state_space()
    d = discretise(A, B, pi.period_s, 1)
    n = N_STATES + 2
    T, kt = pi.period_s, plant.kt_Nm_per_A
    # e[k] = −(θ_m[k] − θ_prev[k])/T ;  i_q_ref = (kp·e + I)/k_t
    e_row = np.zeros(n)
    e_row[0], e_row[N_STATES] = -1.0 / T, 1.0 / T
    u_row = (pi.kp_Nms_per_rad * e_row + np.eye(n)[N_STATES + 1]) / kt
    Acl = np.zeros((n, n))
    Acl[:N_STATES, :N_STATES] = d.Ad
    Acl[:N_STATES] += np.outer(d.Bd[:, 0], u_row)
    Acl[N_STATES, 0] = 1.0
    Acl[N_STATES + 1] = pi.ki_Nm_per_rad * T * e_row
    Acl[N_STATES + 1, N_STATES + 1] += 1.0
    # quotient by the rigid position mode v = (1, 0, 1, 0, 0, 1, 0): coordinates with v in their null space
    Q = np.zeros((n - 1, n))
    Q[0, 0], Q[0, 2] = 1.0, -1.0                  # θ_m − θ_l
    Q[1, 0], Q[1, N_STATES] = 1.0, -1.0           # θ_m − θ_m[k−1]
    for row, col in enumerate((1, 3, 4, N_STATES + 1), start=2):
        Q[row, col] = 1.0                         # ω_m, ω_l, i_q, I
    return np.linalg.eigvals(Q @ Acl @ np.linalg.pinv(Q))


def pole_frequency_damping(z: np.ndarray, period_s: float) -> tuple[np.ndarray, np.ndarray]:
    """Natural frequency (Hz) and damping ratio of discrete poles ``z`` via s = ln(z)/T.

    Poles on the negative real axis or at the origin are reported with the Nyquist frequency;
    a pole at z = 1 (pure integrator) has frequency 0 and damping 1 by convention.
    """
    z = np.asarray(z, dtype=complex)
    s = np.log(np.where(np.abs(z) < 1e-300, 1e-300, z)) / period_s
    wn = np.abs(s)
    zeta = np.where(wn > 0, -s.real / np.where(wn > 0, wn, 1.0), 1.0)
    return wn / (2.0 * np.pi), zeta
