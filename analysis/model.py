"""The two-mass model of a robot joint: torque → motor speed (design §2, paper eq. 4/13/15).

All quantities are reflected to the motor side: motor inertia ``J_m`` and load inertia ``J_l``
(kg·m²), joint stiffness ``K`` (N·m/rad), joint damping ``C`` (N·m·s/rad), viscous frictions
``b_m``, ``b_l`` (N·m·s/rad). The frequency response from electromagnetic torque T_e (N·m) to motor
speed ω_m (rad/s) is::

    H(s) = (J_l s² + (C + b_l) s + K) /
           (J_m J_l s³ + ((J_m+J_l) C + J_l (b_m + b_v) + J_m b_l) s²
            + ((J_m+J_l) K + (b_m+b_l) C + b_m b_l) s + K (b_m+b_l))

with ``b_v`` a motor-side damping of the vibration alone: b_m's share of the resonance's damping without its rigid-body
terms (b_m C s, K b_m, which set the rigid-body pole at b_m/(J_m+J_l) and shape |H| below a few hertz). It stands for a
motor-side friction that damps the vibration while the motor rests or creeps (where Coulomb and Stribeck friction act
like a steep viscous one) but is a nearly constant torque over a move (no damping of the rigid-body motion). Neither
b_m nor b_v enters the numerator: the anti-resonance's depth is C's alone (ζ_a ≈ C/(2√(K J_l))), the resonance's is
((J_m+J_l) C + J_l b_v)/(2 √(K J_m J_l (J_m+J_l))).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: Symbol and SI unit of each parameter of :class:`TwoMassParams`, for people (tables, verdict sentences).
PARAM_LABELS: dict[str, tuple[str, str]] = {"K_Nm_per_rad": ("K", "N·m/rad"), "Jm_kgm2": ("J_m", "kg·m²"),
                                            "Jl_kgm2": ("J_l", "kg·m²"), "C_Nms_per_rad": ("C", "N·m·s/rad"),
                                            "bv_Nms_per_rad": ("b_v", "N·m·s/rad")}


@dataclass(frozen=True)
class TwoMassParams:
    """Parameters of the two-mass joint model, SI units, reflected to the motor side.

    Attributes
    ----------
    K_Nm_per_rad : float
        Torsional stiffness of the joint, N·m/rad.
    Jm_kgm2 : float
        Motor-side inertia, kg·m².
    Jl_kgm2 : float
        Load inertia reflected to the motor side, kg·m².
    C_Nms_per_rad : float
        Joint damping, N·m·s/rad.
    bm_Nms_per_rad, bl_Nms_per_rad : float
        Viscous friction of motor and load, N·m·s/rad (0 by default).
    bv_Nms_per_rad : float
        Motor-side damping of the vibration alone (the module's b_v), N·m·s/rad (0 by default); may be negative down to
        −(J_m+J_l) C/J_l, where the resonance would be undamped.
    """

    K_Nm_per_rad: float
    Jm_kgm2: float
    Jl_kgm2: float
    C_Nms_per_rad: float
    bm_Nms_per_rad: float = 0.0
    bl_Nms_per_rad: float = 0.0
    bv_Nms_per_rad: float = 0.0

    @property
    def antiresonance_hz(self) -> float:
        """Anti-resonance √(K/J_l)/2π, Hz (undamped)."""
        return antiresonance_hz(self.K_Nm_per_rad, self.Jl_kgm2)

    @property
    def resonance_hz(self) -> float:
        """Resonance √(K (J_m+J_l)/(J_m J_l))/2π, Hz (undamped)."""
        return resonance_hz(self.K_Nm_per_rad, self.Jm_kgm2, self.Jl_kgm2)


def antiresonance_hz(K_Nm_per_rad: float, Jl_kgm2: float) -> float:
    """Anti-resonance frequency √(K/J_l)/2π, Hz (paper eq. 5)."""
    return float(np.sqrt(K_Nm_per_rad / Jl_kgm2) / (2.0 * np.pi))


def resonance_hz(K_Nm_per_rad: float, Jm_kgm2: float, Jl_kgm2: float) -> float:
    """Resonance (natural torsional) frequency √(K (J_m+J_l)/(J_m J_l))/2π, Hz (paper eq. 6)."""
    return float(np.sqrt(K_Nm_per_rad * (Jm_kgm2 + Jl_kgm2) / (Jm_kgm2 * Jl_kgm2)) / (2.0 * np.pi))


def transfer_function(p: TwoMassParams) -> tuple[np.ndarray, np.ndarray]:
    """Numerator and denominator of H(s) = ω_m/T_e in powers of s, highest first.

    Parameters
    ----------
    p : TwoMassParams
        Model parameters, SI units.

    Returns
    -------
    num : ndarray, shape (3,)
        ``[J_l, C + b_l, K]``.
    den : ndarray, shape (4,)
        ``[J_m J_l, (J_m+J_l) C + J_l (b_m + b_v) + J_m b_l, (J_m+J_l) K + (b_m+b_l) C + b_m b_l, K (b_m+b_l)]``.
        Units make H rad/s per N·m (as expected by ``scipy.signal.lti``).
    """
    num, den = _coefficients(p, p.Jl_kgm2)
    return np.array(num), np.array(den)


def _coefficients(p: TwoMassParams, Jl: float | np.ndarray) -> tuple[tuple, tuple]:
    """:func:`transfer_function`'s coefficients with ``Jl`` (kg·m², a float or one value per frequency) in J_l's
    place."""
    K, Jm, C = p.K_Nm_per_rad, p.Jm_kgm2, p.C_Nms_per_rad
    bm, bl, bv = p.bm_Nms_per_rad, p.bl_Nms_per_rad, p.bv_Nms_per_rad
    num = (Jl, C + bl, K)
    den = (Jm * Jl, (Jm + Jl) * C + Jl * (bm + bv) + Jm * bl, (Jm + Jl) * K + (bm + bl) * C + bm * bl, K * (bm + bl))
    return num, den


def frequency_response(p: TwoMassParams, f_hz: np.ndarray, load_factor: np.ndarray | None = None) -> np.ndarray:
    """The model's frequency response H(j2πf) from torque to motor speed.

    Parameters
    ----------
    p : TwoMassParams
        Model parameters, SI units.
    f_hz : array_like
        Frequencies, Hz.
    load_factor : ndarray of complex, optional
        The load inertia's dependence on frequency at ``f_hz``: J_l·load_factor takes J_l's place (the load's
        J_l s² becomes the dynamic stiffness of whatever hangs behind it, e.g. :func:`third_mass_load_factor`);
        None: the rigid load.

    Returns
    -------
    ndarray of complex
        H at ``f_hz``, (rad/s)/(N·m), same shape as ``f_hz``.
    """
    s = 2j * np.pi * np.asarray(f_hz, dtype=float)
    num, den = _coefficients(p, p.Jl_kgm2 if load_factor is None else p.Jl_kgm2 * np.asarray(load_factor))
    # Horner's scheme written out: np.polyval's arithmetic (0·s + c₀ = c₀ exactly) without its per-call overhead
    # (the fit evaluates this ~1400 times per analysis)
    return ((num[0] * s + num[1]) * s + num[2]) / (((den[0] * s + den[1]) * s + den[2]) * s + den[3])


def third_mass_load_factor(f_hz: np.ndarray, mass_ratio: float, third_hz: float, damping_ratio: float) -> np.ndarray:
    """The load's inertia factor (:func:`frequency_response`) with a third mass J_3 = ``mass_ratio``·J_l behind it on a
    spring K_2 = J_3 (2π f_3)² and a damper C_2 = 2ζ√(K_2 J_3): the load then needs J_l s² + J_3 s² R(s) to turn,

        1 + (J_3/J_l)·R(s),  R(s) = ω_3² (1 + 2ζ s/ω_3) / (s² + 2ζ ω_3 s + ω_3²),  ω_3 = 2π f_3,

    (J_3 s² θ_3 = (K_2 + C_2 s)(θ_l − θ_3)); below f_3 the third mass moves with the load (factor 1 + J_3/J_l),
    well above it the spring holds it back (factor → 1).

    Parameters
    ----------
    f_hz : array_like
        Frequencies, Hz.
    mass_ratio : float
        J_3/J_l.
    third_hz : float
        f_3 = √(K_2/J_3)/2π, Hz: the third mass's natural frequency on its spring with the load held.
    damping_ratio : float
        ζ of that spring's damper.
    """
    s = 2j * np.pi * np.asarray(f_hz, dtype=float)
    w3 = 2.0 * np.pi * third_hz
    return 1.0 + mass_ratio * w3**2 * (1.0 + 2.0 * damping_ratio * s / w3) / (s**2 + 2.0 * damping_ratio * w3 * s + w3**2)
