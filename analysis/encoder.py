"""Encoder counts → angle and speed on the drive's own regular time base.

The drive samples the position register once per cycle; sample ``k`` (the cumulative cycle index)
is at drive time ``t = k·T``. Everything here works on that grid, never on host arrival stamps.
The backward difference is not d/dt: its response (1 − e^{−jωT})/(jωT) is returned by
:func:`difference_response` so the FRF stage can divide it out.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.interpolate import CubicSpline

_INT32_SPAN = 1 << 32


@dataclass(frozen=True)
class Span:
    """A gap-free run of encoder samples.

    Attributes
    ----------
    start, stop : int
        Array positions of the run, ``stop`` exclusive (``index[start:stop]`` is gap-free).
    gaps : tuple of tuple of int
        Every discontinuity of the whole record as ``(cycle before, cycle after)`` pairs.
    """

    start: int
    stop: int
    gaps: tuple[tuple[int, int], ...]

    @property
    def count(self) -> int:
        """Samples in the run."""
        return self.stop - self.start


def counts_to_rad(position_counts: np.ndarray, counts_per_rev: int) -> np.ndarray:
    """Mechanical angle, rad, from an unwrapped position in encoder counts.

    Parameters
    ----------
    position_counts : array_like of int
        Position, counts (unwrapped, see :func:`unwrap_int32`).
    counts_per_rev : int
        Encoder counts per mechanical revolution.
    """
    if counts_per_rev <= 0:
        raise ValueError(f"counts_per_rev must be positive, got {counts_per_rev}")
    return np.asarray(position_counts, dtype=np.float64) * (2.0 * np.pi / counts_per_rev)


def unwrap_int32(raw_counts: np.ndarray) -> np.ndarray:
    """Undo the int32 wrap of a position register, counts (int64).

    A step of more than half the int32 range between consecutive samples is taken as a wrap.
    """
    raw = np.asarray(raw_counts, dtype=np.int64)
    if raw.size == 0:
        return raw.copy()
    step = np.diff(raw)
    wraps = np.where(step > _INT32_SPAN // 2, -1, 0) + np.where(step < -(_INT32_SPAN // 2), 1, 0)
    return raw + np.concatenate(([0], np.cumsum(wraps) * _INT32_SPAN))


def gap_free_spans(index: np.ndarray) -> list[Span]:
    """Every run of consecutive drive cycles in ``index`` (a step of exactly 1 is no gap), in order.

    Parameters
    ----------
    index : array_like of int
        Cumulative drive cycle index of each sample.
    """
    idx = np.asarray(index, dtype=np.int64)
    if idx.ndim != 1 or idx.size == 0:
        raise ValueError("index must be a non-empty 1-D array")
    breaks = np.flatnonzero(np.diff(idx) != 1) + 1
    edges = np.concatenate(([0], breaks, [idx.size]))
    gaps = tuple((int(idx[b - 1]), int(idx[b])) for b in breaks)
    return [Span(int(a), int(b), gaps) for a, b in zip(edges[:-1], edges[1:])]


def longest_gap_free_span(index: np.ndarray) -> Span:
    """The longest run of consecutive drive cycles in ``index`` (the first of equals; :func:`gap_free_spans`)."""
    return max(gap_free_spans(index), key=lambda s: s.count)


def speed_from_counts(position_counts: np.ndarray, counts_per_rev: int, period_s: float) -> np.ndarray:
    """Motor speed, rad/s, by backward difference on the drive's grid k·T.

    ``speed[i] = (θ[i+1] − θ[i]) / T`` belongs to the instant of sample ``i+1``; the result has one
    sample fewer than ``position_counts``. Its response against the true speed is
    :func:`difference_response`. The samples must be gap-free (see :func:`longest_gap_free_span`).

    Parameters
    ----------
    position_counts : array_like of int
        Unwrapped position, counts, one per drive cycle.
    counts_per_rev : int
        Counts per mechanical revolution.
    period_s : float
        Drive cycle T, s.
    """
    if period_s <= 0:
        raise ValueError(f"period_s must be positive, got {period_s}")
    counts = np.asarray(position_counts, dtype=np.int64)
    if counts.size < 2:
        raise ValueError("need at least two encoder samples for a speed")
    return counts_to_rad(np.diff(counts), counts_per_rev) / period_s


def speed_from_angle(theta_rad: np.ndarray, period_s: float) -> np.ndarray:
    """Motor speed, rad/s, by backward difference of an angle on the drive's grid k·T (as
    :func:`speed_from_counts`, for an angle that is no longer whole counts, e.g. moved to k·T)."""
    if period_s <= 0:
        raise ValueError(f"period_s must be positive, got {period_s}")
    theta = np.asarray(theta_rad, dtype=np.float64)
    if theta.size < 2:
        raise ValueError("need at least two encoder samples for a speed")
    return np.diff(theta) / period_s


def difference_response(f_hz: np.ndarray, period_s: float) -> np.ndarray:
    """Complex response (1 − e^{−jωT})/(jωT) of the backward difference against d/dt (1 at 0 Hz).

    Parameters
    ----------
    f_hz : array_like
        Frequencies, Hz.
    period_s : float
        Drive cycle T, s.
    """
    wT = 2.0 * np.pi * np.asarray(f_hz, dtype=np.float64) * period_s
    # (1 − e^{−jx})/(jx) = e^{−jx/2}·sinc(x/2π), exact also at x = 0
    return np.exp(-0.5j * wT) * np.sinc(wT / (2.0 * np.pi))


def angle_spline(first_cycle: int, period_s: float, theta_rad: np.ndarray) -> CubicSpline:
    """Cubic spline θ(t) through the encoder angles at drive times t = (first_cycle + i)·T.

    Used to read the electrical angle at the DAQ instants for demodulation and alignment (the speed
    itself is never interpolated). The samples must be gap-free.

    Parameters
    ----------
    first_cycle : int
        Drive cycle index of ``theta_rad[0]``.
    period_s : float
        Drive cycle T, s.
    theta_rad : ndarray
        Angle, rad (mechanical or electrical), one per cycle.
    """
    th = np.asarray(theta_rad, dtype=np.float64)
    if th.size < 4:
        raise ValueError("need at least four encoder samples for an angle spline")
    return CubicSpline((first_cycle + np.arange(th.size)) * period_s, th)


def quantisation_speed_psd(f_hz: np.ndarray, period_s: float, lsb_rad: float) -> np.ndarray:
    """One-sided PSD, (rad/s)²/Hz, of the backward-difference speed noise of a position quantised to ``lsb_rad``.

    White position errors of variance lsb²/12 (the position moving several counts a cycle; slower they are
    correlated and smaller, so this is an upper bound) through (1 − z⁻¹)/T.
    """
    s = np.sin(np.pi * np.asarray(f_hz, dtype=np.float64) * period_s)
    return 8.0 * lsb_rad**2 / 12.0 * s * s / period_s


def quantisation_bound(f_hz: np.ndarray, h: np.ndarray, torque_psd: np.ndarray, period_s: float,
                       lsb_rad: float) -> np.ndarray:
    """The white-quantisation bound of |H| at ``f_hz``: √(N_q/|H·D|²G_xx), the speed noise of the encoder's resolution
    over the speed the torque drives (D the backward difference), relative (0.05 = 5 %); inf where there is no
    signal. ``h`` the measured torque → speed response, ``torque_psd`` G_xx, (N·m)²/Hz."""
    signal = np.abs(h * difference_response(f_hz, period_s)) ** 2 * torque_psd
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.sqrt(quantisation_speed_psd(f_hz, period_s, lsb_rad) / signal)

