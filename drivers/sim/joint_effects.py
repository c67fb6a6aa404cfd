"""Nonlinear and extra-mass effects of the simulated joint and its encoder, each off unless its ``[sim]`` option is set.

All motor side (rad, rad/s, N·m), like :mod:`drivers.sim.plant`:

* :class:`Friction` — Coulomb + Stribeck friction of the load (``load_*``) or of the motor (``motor_*``: the
  reducer's input side, bearings and seals), T_f(ω) = (F_c + F_s·exp(−(ω/ω_s)²))·tanh(ω/ε). The tanh (width ε,
  ``friction_smoothing_rad_s``) stands for sign(ω): the friction is held over a control period like gravity, and
  a true sign would chatter at the reversals. Stable while F/ε·T/J ≪ 1 (default 0.5 rad/s: 0.02 at 0.3 N·m on
  J_l, 0.05 on J_m).
* :class:`Cogging` — the PMSM's cogging torque, T_c(θ_m) = A·sin(n·θ_m + φ) with n periods per mechanical
  revolution (the least common multiple of slots and poles: 24 for 12 slots and 8 poles). It is a torque on the
  motor that the phase current does not carry (what the drive's current sensor sees is k_t·i_q alone), held
  over a control period; its stiffness A·n (4.8 N·m/rad at 0.2 N·m) is far below K. Motor friction and cogging
  enter as one more held input (the last column of B), a torque on the motor alone.
* :class:`Eccentricity` — the encoder's once-per-revolution error: it reads θ_m + e·sin(θ_m + φ) (a disc off-centre by
  r·e on radius r). The drive's speed loop, its commutation (so the phase currents' angle) and the streamed position
  read it; the torque stays k_t·i_q (the commutation's error p·e changes it by cos(p·e) − 1: −7e-5 at e = 3 mrad).
* :class:`Backlash` — a dead zone of full width b (load side; N·b motor side) in the shaft: the shaft
  torque is K·dz(δ) with dz(δ) = δ − clip(δ, −N·b/2, N·b/2), δ = θ_m − θ_l. The linear plant carries
  K·δ; the correction K·clip(δ, ±N·b/2) enters as a torque pair (+ on the motor, − on the load) held
  over a control period (an explicit step: its gain K over T = 250 µs is ω_r·T ≈ 0.16 at 102 Hz).
  The shaft damping C stays on across the gap (a simplification).
* :class:`ThirdMass` — a second elastic element K_2, C_2 and inertia J_3 behind the load, natural
  frequency √(K_2/J_3)/2π on a clamped load; its states [θ_3, ω_3] are appended to the plant's.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from drivers.config import SimSettings


@dataclass(frozen=True)
class Friction:
    """Coulomb F_c + Stribeck F_s (N·m) friction of one side, Stribeck speed ω_s and tanh width ε (rad/s)."""

    coulomb_Nm: float
    stribeck_Nm: float
    stribeck_speed_rad_s: float
    smoothing_rad_s: float

    def torque_Nm(self, omega_rad_s: np.ndarray | float) -> np.ndarray | float:
        """Friction torque opposing the motion at speed ``omega_rad_s``, N·m (positive for positive speed)."""
        w = np.asarray(omega_rad_s, dtype=float)
        level = self.coulomb_Nm + self.stribeck_Nm * np.exp(-(w / self.stribeck_speed_rad_s) ** 2)
        out = level * np.tanh(w / self.smoothing_rad_s)
        return float(out) if out.ndim == 0 else out


@dataclass(frozen=True)
class Cogging:
    """Cogging torque of amplitude ``amplitude_Nm`` with ``per_rev`` periods per motor revolution, phase ``phase_rad``."""

    amplitude_Nm: float
    per_rev: int
    phase_rad: float

    def torque_Nm(self, theta_m_rad: np.ndarray | float) -> np.ndarray | float:
        """Cogging torque on the motor at motor angle ``theta_m_rad`` (rad), N·m, counted like friction (it
        opposes the motor when positive)."""
        return self.amplitude_Nm * np.sin(self.per_rev * np.asarray(theta_m_rad, dtype=float) + self.phase_rad)


@dataclass(frozen=True)
class Eccentricity:
    """The encoder's once-per-revolution error of amplitude ``amplitude_rad`` and phase ``phase_rad``."""

    amplitude_rad: float
    phase_rad: float

    def read_rad(self, theta_m_rad: np.ndarray | float) -> np.ndarray | float:
        """The angle the encoder reads at motor angle ``theta_m_rad`` (rad), rad."""
        return theta_m_rad + self.amplitude_rad * np.sin(theta_m_rad + self.phase_rad)


@dataclass(frozen=True)
class Backlash:
    """Dead zone of full width ``width_rad`` (motor side) in a shaft of stiffness ``K_Nm_per_rad``."""

    width_rad: float
    K_Nm_per_rad: float

    def correction_Nm(self, twist_rad: float) -> float:
        """K·clip(δ, ±b/2), N·m: what the linear shaft torque K·δ has too much."""
        half = 0.5 * self.width_rad
        return self.K_Nm_per_rad * min(max(twist_rad, -half), half)

    def shaft_torque_Nm(self, twist_rad: np.ndarray) -> np.ndarray:
        """Elastic shaft torque K·dz(δ), N·m, at twists ``twist_rad`` (rad)."""
        half = 0.5 * self.width_rad
        return self.K_Nm_per_rad * (twist_rad - np.clip(twist_rad, -half, half))


@dataclass(frozen=True)
class ThirdMass:
    """Inertia ``J3_kgm2`` on a spring ``K2_Nm_per_rad`` with damping ``C2_Nms_per_rad`` behind the load."""

    J3_kgm2: float
    K2_Nm_per_rad: float
    C2_Nms_per_rad: float

    def extend(self, A: np.ndarray, B: np.ndarray, Jl_kgm2: float) -> tuple[np.ndarray, np.ndarray]:
        """The plant ``(A, B)`` (θ_l, ω_l at rows 2, 3) with [θ_3, ω_3] appended."""
        n, m = B.shape
        A3 = np.zeros((n + 2, n + 2))
        A3[:n, :n] = A
        K2, C2, J3 = self.K2_Nm_per_rad, self.C2_Nms_per_rad, self.J3_kgm2
        A3[3, 2] -= K2 / Jl_kgm2
        A3[3, 3] -= C2 / Jl_kgm2
        A3[3, n] += K2 / Jl_kgm2
        A3[3, n + 1] += C2 / Jl_kgm2
        A3[n, n + 1] = 1.0
        A3[n + 1, 2], A3[n + 1, 3] = K2 / J3, C2 / J3
        A3[n + 1, n], A3[n + 1, n + 1] = -K2 / J3, -C2 / J3
        B3 = np.zeros((n + 2, m))
        B3[:n] = B
        return A3, B3


@dataclass(frozen=True)
class JointEffects:
    """The optional effects of one simulated joint (None = off)."""

    friction: Friction | None = None
    backlash: Backlash | None = None
    third_mass: ThirdMass | None = None
    motor_friction: Friction | None = None
    cogging: Cogging | None = None
    eccentricity: Eccentricity | None = None

    @property
    def motor_torque(self) -> bool:
        """Whether a torque on the motor alone (motor friction, cogging) is an input: the last column of B."""
        return self.motor_friction is not None or self.cogging is not None

    def motor_torque_Nm(self, theta_m_rad: float, omega_m_rad_s: float) -> float:
        """The motor-side friction and cogging torque opposing the motor, N·m (0 when both are off)."""
        out = 0.0
        if self.motor_friction is not None:
            out += self.motor_friction.torque_Nm(omega_m_rad_s)
        if self.cogging is not None:
            out += self.cogging.torque_Nm(theta_m_rad)
        return out

    @classmethod
    def from_settings(cls, s: SimSettings, gear_ratio: float) -> JointEffects:
        """The effects the ``[sim]`` options switch on (K and J_l from the same settings)."""
        friction = None
        if s.load_coulomb_Nm > 0 or s.load_stribeck_Nm > 0:
            friction = Friction(s.load_coulomb_Nm, s.load_stribeck_Nm, s.load_stribeck_speed_rad_s,
                                    s.friction_smoothing_rad_s)
        backlash = Backlash(s.backlash_load_rad * gear_ratio, s.K_Nm_per_rad) if s.backlash_load_rad > 0 else None
        third = None
        if s.third_mass_Jl_fraction > 0:
            J3 = s.third_mass_Jl_fraction * s.Jl_kgm2
            K2 = J3 * (2 * math.pi * s.third_mass_hz) ** 2
            third = ThirdMass(J3, K2, 2 * s.third_mass_damping_ratio * math.sqrt(K2 * J3))
        motor = None
        if s.motor_coulomb_Nm > 0 or s.motor_stribeck_Nm > 0:
            motor = Friction(s.motor_coulomb_Nm, s.motor_stribeck_Nm, s.motor_stribeck_speed_rad_s,
                             s.friction_smoothing_rad_s)
        cogging = Cogging(s.cogging_Nm, s.cogging_per_rev, s.cogging_phase_rad) if s.cogging_Nm > 0 else None
        eccentricity = None
        if s.encoder_eccentricity_rad > 0:
            eccentricity = Eccentricity(s.encoder_eccentricity_rad, s.encoder_eccentricity_phase_rad)
        return cls(friction, backlash, third, motor, cogging, eccentricity)

    def state_space(self, A: np.ndarray, B: np.ndarray, Jm_kgm2: float, Jl_kgm2: float
                    ) -> tuple[np.ndarray, np.ndarray]:
        """The two-mass ``(A, B)`` with the third mass's states, the backlash torque-pair input and the motor-side
        torque input (last) added."""
        if self.third_mass is not None:
            A, B = self.third_mass.extend(A, B, Jl_kgm2)
        if self.backlash is not None:
            col = np.zeros((B.shape[0], 1))
            col[1, 0], col[3, 0] = 1.0 / Jm_kgm2, -1.0 / Jl_kgm2
            B = np.hstack([B, col])
        if self.motor_torque:
            col = np.zeros((B.shape[0], 1))
            col[1, 0] = -1.0 / Jm_kgm2
            B = np.hstack([B, col])
        return A, B
