"""The data of the report figures, as plain arrays (no plotting library here).

A viewer or the PNG writer draws: the torque and speed traces (decimated), the measured |H| with
the fitted model and its 95 % band, how far the model misses the measured |H| (in %) over the fit band, f_a and
f_r marked, the misfit band or third mode a ``poor`` verdict names,
the coherence, and — when the clocks are aligned well enough for a phase to mean something — the measured and the
model's phase.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field, replace

import numpy as np

from analysis.fit import Z95, FitResult
from analysis.frf import FrequencyResponse
from analysis.model import frequency_response

MAX_TRACE_POINTS = 5000
MODEL_POINTS = 600
_LOG_STEP = 1e-6


@dataclass(frozen=True)
class FigureData:
    """Everything a report figure shows, SI units.

    Attributes
    ----------
    t_s, torque_Nm, speed_rad_s : ndarray
        Time traces, decimated to at most :data:`MAX_TRACE_POINTS` samples.
    f_hz, H_abs, coherence : ndarray
        Measured FRF amplitude, (rad/s)/(N·m), and coherence γ² from 0 Hz to Nyquist.
    model_f_hz, model_abs, model_low, model_high : ndarray
        Fitted model |H| on a log grid over the fit band and its pointwise 95 % band
        (linear propagation of the parameter covariance); NaN when the fit failed.
    band_hz : tuple of float
        Fit band (low, high), Hz.
    f_a_hz, f_r_hz : float
        Anti-resonance and resonance of the fitted model, Hz.
    H_phase_deg : ndarray
        Measured phase of H at ``f_hz``, degrees (the backward difference's response is already divided out of
        H, :func:`analysis.frf.estimate_frf`).
    model_phase_deg : ndarray
        The fitted model's phase at ``model_f_hz``, degrees.
    phase_valid : bool
        The clocks were aligned to within the residual a complex fit accepts, so the measured phase is the
        plant's (False: unaligned or poorly aligned streams, the phase carries the clock offset).
    misfit_band_hz : tuple of float
        The band where the verdict says the two-mass model misses |H| (:attr:`analysis.quality.Quality.misfit_band_hz`),
        Hz; (NaN, NaN) when it names none.
    third_mode_hz : float
        The third mode the verdict names (:attr:`analysis.quality.Quality.third_mode_hz`), Hz; NaN when none.
    misfit_pct : ndarray
        How far the fitted model misses the measured |H| at ``f_hz``: 100 · (|H_model| / |H| − 1), %, the sign of
        the verdict's "misses by +5.9 %" — the misfit test's own per-bin misfit (:attr:`analysis.quality.Quality.
        misfit_bins`: the model as the Welch estimator sees it, so a sharp resonance blurred by the window is no
        misfit), a misfit a log axis hides (6 % is 0.025 decades); NaN where the test judged no bin (outside its
        band, a failed fit, no test made). Empty: not computed (figure data made before it was).
    misfit_windows : ndarray, shape (n, 4)
        The windows the verdict's misfit test judged (:attr:`analysis.quality.Quality.misfit_windows`): first and
        last bin (Hz), mean ln|H_model| − ln|H| and the most it may be before the window is missed (ln); no rows
        when the test was not made.
    """

    t_s: np.ndarray
    torque_Nm: np.ndarray
    speed_rad_s: np.ndarray
    f_hz: np.ndarray
    H_abs: np.ndarray
    coherence: np.ndarray
    model_f_hz: np.ndarray
    model_abs: np.ndarray
    model_low: np.ndarray
    model_high: np.ndarray
    band_hz: tuple[float, float]
    f_a_hz: float
    f_r_hz: float
    H_phase_deg: np.ndarray
    model_phase_deg: np.ndarray
    phase_valid: bool
    misfit_band_hz: tuple[float, float] = (math.nan, math.nan)
    third_mode_hz: float = math.nan
    misfit_pct: np.ndarray = field(default_factory=lambda: np.empty(0))
    misfit_windows: np.ndarray = field(default_factory=lambda: np.empty((0, 4)))


def decimate_trace(n: int, max_points: int = MAX_TRACE_POINTS) -> slice:
    """A slice taking every k-th of ``n`` samples so that at most ``max_points`` remain."""
    return slice(None, None, max(1, -(-n // max_points)))


def model_band(fit: FitResult, f_hz: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The fitted model's |H| and its pointwise 95 % band.

    σ²(f) = gᵀ Σ g with g = ∂ln|H(f)|/∂ln θ over the fitted parameters (central differences) and Σ
    the covariance of their logarithms.

    Parameters
    ----------
    fit : FitResult
        The fit.
    f_hz : ndarray
        Frequencies, Hz.

    Returns
    -------
    abs_H, low, high : ndarray
        |H| and its 95 % band, (rad/s)/(N·m).
    """
    log_abs = np.log(np.abs(frequency_response(fit.values, f_hz)))
    grads = []
    for name in fit.fitted:
        value = getattr(fit.values, name)
        up = replace(fit.values, **{name: value * np.exp(_LOG_STEP)})
        down = replace(fit.values, **{name: value * np.exp(-_LOG_STEP)})
        grads.append((np.log(np.abs(frequency_response(up, f_hz)))
                      - np.log(np.abs(frequency_response(down, f_hz)))) / (2.0 * _LOG_STEP))
    g = np.array(grads)
    sigma = np.sqrt(np.clip(np.einsum("if,ij,jf->f", g, fit.covariance, g), 0.0, None))
    with np.errstate(over="ignore"):  # a failed fit's band may be wider than a float holds: unbounded (inf) there
        return np.exp(log_abs), np.exp(log_abs - Z95 * sigma), np.exp(log_abs + Z95 * sigma)


def figure_data(
    t_s: np.ndarray, torque_Nm: np.ndarray, speed_rad_s: np.ndarray, frf: FrequencyResponse, fit: FitResult,
    *, phase_valid: bool = False, misfit_band_hz: tuple[float, float] | None = None, third_mode_hz: float | None = None,
    misfit_windows: Sequence[tuple[float, float, float, float]] = (),
    misfit_bins: Sequence[tuple[float, float]] = ()
) -> FigureData:
    """Assemble the report's figure data.

    Parameters
    ----------
    t_s, torque_Nm, speed_rad_s : ndarray
        The prepared signals: time (s), torque (N·m), motor speed (rad/s).
    frf : FrequencyResponse
        The measured frequency response.
    fit : FitResult
        The model fitted to it.
    phase_valid : bool, optional
        The clocks are aligned well enough to show the phase (see :attr:`FigureData.phase_valid`).
    misfit_band_hz : tuple of float, optional
        The misfit band the verdict names, Hz (None: none).
    third_mode_hz : float, optional
        The third mode the verdict names, Hz (None: none).
    misfit_windows : sequence of (float, float, float, float), optional
        The windows the verdict's misfit test judged (:attr:`analysis.quality.Quality.misfit_windows`).
    misfit_bins : sequence of (float, float), optional
        The bins it judged, (Hz, ln|H_model| − ln|H|) (:attr:`analysis.quality.Quality.misfit_bins`).

    Returns
    -------
    FigureData
    """
    keep = decimate_trace(len(t_s))
    f_model = np.geomspace(fit.band[0], fit.band[1], MODEL_POINTS)
    abs_h, low, high = model_band(fit, f_model)
    misfit = np.full(frf.f_hz.shape, np.nan)
    judged = np.asarray(misfit_bins, dtype=float).reshape(-1, 2)
    misfit[np.isin(frf.f_hz, judged[:, 0])] = 100.0 * np.expm1(judged[np.isin(judged[:, 0], frf.f_hz), 1])
    return FigureData(
        t_s=np.asarray(t_s)[keep], torque_Nm=np.asarray(torque_Nm)[keep], speed_rad_s=np.asarray(speed_rad_s)[keep],
        f_hz=frf.f_hz, H_abs=np.abs(frf.H), coherence=frf.coherence,
        model_f_hz=f_model, model_abs=abs_h, model_low=low, model_high=high,
        band_hz=fit.band, f_a_hz=fit.f_a, f_r_hz=fit.f_r,
        H_phase_deg=np.degrees(np.angle(frf.H)),
        model_phase_deg=np.degrees(np.angle(frequency_response(fit.values, f_model))),
        phase_valid=phase_valid,
        misfit_band_hz=(math.nan, math.nan) if misfit_band_hz is None else misfit_band_hz,
        third_mode_hz=math.nan if third_mode_hz is None else third_mode_hz,
        misfit_pct=misfit,
        misfit_windows=np.asarray(misfit_windows, dtype=float).reshape(-1, 4),
    )
