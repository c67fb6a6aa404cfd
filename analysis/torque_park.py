"""Torque from two or three phase currents by Clarke + Park with the encoder angle (``--torque park``), exact, and
the three phases' relative sensor gains from i_a + i_b + i_c = 0 (:func:`phase_gains`), divided out before it."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

_SQRT3 = np.sqrt(3.0)


@dataclass(frozen=True)
class PhaseGains:
    """Relative sensor gains of three recorded phases, each divided by their mean (the common scale is k_t's).

    Attributes
    ----------
    gain : dict
        Phase name → gain / mean gain of the three phases.
    sigma : dict
        Phase name → standard error of that ratio (block jackknife).
    n_samples : int
        Samples that carried the estimate.
    """

    gain: dict[str, float]
    sigma: dict[str, float]
    n_samples: int


def phase_gains(currents_a: dict[str, np.ndarray], blocks: int = 10) -> PhaseGains | None:
    """Relative sensor gains of three phases from i_a + i_b + i_c = 0; None with fewer than three phases.

    The motor's currents sum to zero at every instant (star point not connected — the usual drive), so
    the measured m_x = g_x·i_x + dc_x satisfy Σ m_x / g_x = const. The vector (1/g_a, 1/g_b, 1/g_c) is the
    direction in which the centred currents have least variance: the smallest eigenvector of their 3×3
    covariance (total least squares — the sensors' noise enters all three alike). No angle and no model
    of the torque enter. The standard error is a jackknife over ``blocks`` contiguous pieces (a choice of
    resolution, not a tuned value: ~10 pieces leave each enough motion).

    Parameters
    ----------
    currents_a : dict
        ``"i_a"``, ``"i_b"``, ``"i_c"`` at the same samples, A.
    blocks : int
        Pieces of the jackknife.
    """
    names = ("i_a", "i_b", "i_c")
    if not all(n in currents_a for n in names):
        return None
    m = np.stack([np.asarray(currents_a[n], dtype=np.float64) for n in names])
    m = m - m.mean(axis=1, keepdims=True)
    n = m.shape[1] // blocks * blocks
    scatter = np.einsum("ibk,jbk->bij", m[:, :n].reshape(3, blocks, -1), m[:, :n].reshape(3, blocks, -1))

    def gains(s: np.ndarray) -> np.ndarray:
        inv = np.linalg.eigh(s)[1][:, 0]  # ∝ 1/g, sign arbitrary
        g = 1.0 / inv
        return g / g.mean()

    total = scatter.sum(axis=0)
    g = gains(total)
    jack = np.array([gains(total - s) for s in scatter])
    se = np.sqrt((blocks - 1) / blocks * np.sum((jack - jack.mean(axis=0)) ** 2, axis=0))
    return PhaseGains({k: float(v) for k, v in zip(names, g)}, {k: float(v) for k, v in zip(names, se)}, n)


def torque_park(currents_a: dict[str, np.ndarray], theta_e_rad: np.ndarray, k_t_Nm_per_A: float,
                theta0_rad: float, dc_a: dict[str, float], gain: dict[str, float] | None = None) -> np.ndarray:
    """Torque from two or three phases by Clarke + Park with the encoder angle, N·m.

    i_α = i_a, i_β = (i_b − i_c)/√3 (amplitude-invariant; i_c = −i_a − i_b when only a and b are
    recorded), i_q = −i_α·sin φ + i_β·cos φ with φ = θ_e + θ_0.

    Parameters
    ----------
    currents_a : dict
        ``"i_a"``, ``"i_b"`` and optionally ``"i_c"``, A.
    theta_e_rad : ndarray
        Electrical angle at the same samples, rad.
    k_t_Nm_per_A : float
        Torque constant, N·m/A.
    theta0_rad : float
        Electrical offset θ_0 (sign chosen), rad.
    dc_a : dict
        Sensor DC of each phase used, A.
    gain : dict, optional
        Relative sensor gain of each phase used (:func:`phase_gains`); the currents are divided by it.
    """
    if "i_a" not in currents_a or "i_b" not in currents_a:
        raise ValueError("park needs at least the phases i_a and i_b")
    g = gain or {}
    ia = (np.asarray(currents_a["i_a"], dtype=np.float64) - dc_a["i_a"]) / g.get("i_a", 1.0)
    ib = (np.asarray(currents_a["i_b"], dtype=np.float64) - dc_a["i_b"]) / g.get("i_b", 1.0)
    ic = ((np.asarray(currents_a["i_c"], dtype=np.float64) - dc_a["i_c"]) / g.get("i_c", 1.0)
          if "i_c" in currents_a else -ia - ib)
    i_alpha = (2.0 * ia - ib - ic) / 3.0
    i_beta = (ib - ic) / _SQRT3
    phi = np.asarray(theta_e_rad, dtype=np.float64) + theta0_rad
    return k_t_Nm_per_A * (-i_alpha * np.sin(phi) + i_beta * np.cos(phi))
