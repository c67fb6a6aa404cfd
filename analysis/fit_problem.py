"""The fit's terms and its residuals: the options and the result of a two-mass fit, its band and bins, and the model
as the Welch estimate sees it (:class:`_Problem`: window kernel, torque-noise gain, fold-over terms) with the log
ratio and weighted residuals that :mod:`analysis.fit` minimises and :mod:`analysis.fit_judging` judges."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import Literal

import numpy as np
from scipy import sparse

from analysis.frf import KERNEL_PER_BIN, FrequencyResponse, window_kernel
from analysis.model import TwoMassParams, frequency_response

FitKind = Literal["amplitude", "complex"]
FitParams = Literal["K", "K,Jm,Jl"]
FitStatus = Literal["converged", "max_evaluations", "failed"]
FitWeighting = Literal["coherence", "uniform"]

PARAM_NAMES: tuple[str, ...] = ("K_Nm_per_rad", "Jm_kgm2", "Jl_kgm2", "C_Nms_per_rad")
#: The motor-side damping of the vibration alone (analysis.model's b_v), free beside C in acq's second fit
#: (:attr:`FitOptions.vibration_damping`): the resonance's damping beyond C's share, so that C is read where it alone sets
#: the response, the anti-resonance. Fitted as the ratio r = J_l b_v/((J_m+J_l) C) of the two shares, not as a logarithm:
#: 0 (no such damping) is an ordinary value, and the data may put r a little below it.
VIBRATION_DAMPING = "bv_Nms_per_rad"
BAND_LOW_HZ = 10.0
BAND_HIGH_MAX_HZ = 500.0
BAND_HIGH_FRACTION_OF_FENC = 0.4
COHERENCE_CLIP = 0.99


@dataclass(frozen=True)
class FitOptions:
    """How to fit.

    Attributes
    ----------
    params : {"K,Jm,Jl", "K"}
        Free parameters besides C: all three (default) or K only, with J_m, J_l fixed to the
        nominal values given to :func:`fit_two_mass`.
    kind : {"amplitude", "complex"}
        Fit |H| only (immune to a clock offset) or the complex H.
    band_hz : tuple of float or None
        Fit band (low, high), Hz; None for 10 Hz … min(0.4·f_enc, 500 Hz).
    weighting : {"coherence", "uniform"}
        Bin weights γ²/(1−γ²) (ours) or all 1 (the paper's).
    speed_lsb_rad : float or None
        The encoder's resolution, rad (2π/counts per rev): the intervals then allow for the quantisation's pull
        on the parameters (:func:`analysis.systematic_errors.quantisation_pull`) instead of :data:`CHAIN_REL_STD`.
    quantisation_repeating_share : float
        Share (0…1) of the quantisation error that repeats with the motion
        (:func:`analysis.quantisation_lock.locked_share`): only that share is a bias the jackknife cannot see; the
        rest scatters from period to period and is in the jackknife's spread. 1 (all of it) when not measured.
    vibration_damping : bool
        Fit the model again with the motor-side damping of the vibration b_v (:data:`VIBRATION_DAMPING`) free beside C
        and widen the intervals to hold that reading's too (acq's chain), or not (the paper's: C its model's one
        damping).
    """

    params: FitParams = "K,Jm,Jl"
    kind: FitKind = "amplitude"
    band_hz: tuple[float, float] | None = None
    weighting: FitWeighting = "coherence"
    speed_lsb_rad: float | None = None
    quantisation_repeating_share: float = 1.0
    vibration_damping: bool = True


@dataclass(frozen=True)
class FitResult:
    """The fitted two-mass model with its uncertainty.

    Attributes
    ----------
    values : TwoMassParams
        Best-fit parameters (b_m = b_l = b_v = 0: C the model's one damping).
    ci95 : dict of str to (float, float)
        95 % confidence interval (low, high) per parameter name of :data:`PARAM_NAMES`, SI units;
        a fixed parameter has a zero-width interval.
    fitted : tuple of str
        Names of the fitted parameters, the order of ``covariance``.
    covariance : ndarray, shape (p, p)
        Covariance of the natural logarithms of the fitted parameters (the jackknife's scaled by
        (t/1.96)², so that ±1.96 σ is the 95 % interval in either case), with the misfit's or the systematic pull's
        share and the input-noise bound d dᵀ/3 (:mod:`analysis.input_noise`) added, then each parameter's variance
        widened (its correlations kept) until ±1.96 σ holds the interval of the fit with b_v free too
        (:attr:`vibration_damping`).
    cost : float
        Final cost ½ Σ r² of the weighted residuals.
    residual_rms : float
        Weighted RMS of the log-amplitude residual, ≈ relative misfit of |H| (0.01 = 1 %).
    status : {"converged", "max_evaluations", "failed"}
        Outcome of the best start.
    message : str
        The optimiser's message for the best start.
    band : tuple of float
        Band actually used (low, high), Hz.
    options : FitOptions
        Options as given.
    f_a, f_r : float
        Anti-resonance and resonance of the fitted model, Hz.
    n_points : int
        FRF bins in the band.
    input_noise_shift : dict of str to float
        How far each free log parameter moves when the resonance is read from H2 instead of H1
        (:mod:`analysis.input_noise`; empty when not computed): the bias an error on the torque estimate may leave.
    ci95_without_input_noise : dict of str to (float, float)
        The 95 % intervals without the allowance for that bias (empty when none was made): what it widened.
    vibration_damping : tuple of float or None
        The fit with b_v free beside C (:attr:`FitOptions.vibration_damping`): b_v, N·m·s/rad, and its 95 % interval
        (low, high), each clipped at 0 (a damping is passive), and that fit's C; None when not made, or when it or its intervals did not come out finite (the
        intervals are then C alone's).
    ci95_c_alone : dict of str to (float, float)
        The 95 % intervals before they were widened to hold the b_v fit's (empty when not widened).
    """

    values: TwoMassParams
    ci95: dict[str, tuple[float, float]]
    fitted: tuple[str, ...]
    covariance: np.ndarray
    cost: float
    residual_rms: float
    status: FitStatus
    message: str
    band: tuple[float, float]
    options: FitOptions
    f_a: float
    f_r: float
    n_points: int
    input_noise_shift: dict[str, float] = field(default_factory=dict)
    ci95_without_input_noise: dict[str, tuple[float, float]] = field(default_factory=dict)
    vibration_damping: tuple[float, float, float, float] | None = None
    ci95_c_alone: dict[str, tuple[float, float]] = field(default_factory=dict)


def rel_halfwidth(fit: FitResult, name: str) -> float:
    """Half-width of the 95 % interval of ``name`` relative to its value (NaN if unknown)."""
    low, high = fit.ci95[name]
    return float(0.5 * (high - low) / getattr(fit.values, name))


#: How :func:`unbracketed_note` begins: a note of the fit's intervals, dropped where the numbers are
#: (:func:`acq.offline.excitation_judge.judged`).
UNBRACKETED_NOTE_START = "the intervals are the fit's with C alone"


def unbracketed_note(fit: FitResult) -> str | None:
    """Why the intervals allow for no motor-side damping of the vibration, when acq's second fit (b_v free beside C,
    :attr:`FitOptions.vibration_damping`) was made but gave no finite reading (:attr:`FitResult.vibration_damping`
    None): the intervals are then C alone's, which hold the truth only if the resonance's damping is the shaft's. They
    are kept, not widened to infinity: the values are C alone's either way, and b_v's interval held 0 in 84 of 85 ``ok``
    robot windows (with motor friction or without, bench/effects_robot.py) — an unknown bracket is a caveat on C's
    reading, not an unknown joint. None when the bracket was made, not asked for, or the fit failed."""
    if not fit.options.vibration_damping or fit.status == "failed" or fit.vibration_damping is not None:
        return None
    low, high = fit.ci95.get("C_Nms_per_rad", (float("nan"), float("nan")))
    return (f"{UNBRACKETED_NOTE_START}: the second fit, with a motor-side damping of the vibration "
            f"(b_v) free beside C, gave no finite interval, so they do not allow for one — friction on the motor "
            f"side damps the resonance and reads C high, beyond its interval [{low:.3g}, {high:.3g}] N·m·s/rad")


def default_band_hz(period_s: float) -> tuple[float, float]:
    """Default fit band (10 Hz, min(0.4·f_enc, 500 Hz)) for an encoder period ``period_s`` (s)."""
    return BAND_LOW_HZ, min(BAND_HIGH_FRACTION_OF_FENC / period_s, BAND_HIGH_MAX_HZ)


def band_mask(f_hz: np.ndarray, band: tuple[float, float]) -> np.ndarray:
    """Boolean mask of the frequencies ``f_hz`` (Hz) inside the closed band (low, high) Hz."""
    return (f_hz >= band[0]) & (f_hz <= band[1])


def fitted_bins(frf: FrequencyResponse, band: tuple[float, float]) -> np.ndarray:
    """Boolean mask of the bins a fit in ``band`` (Hz) uses: inside it, with a finite, non-zero H."""
    return band_mask(frf.f_hz, band) & np.isfinite(frf.H) & (np.abs(frf.H) > 0)


def _free_params(options: FitOptions, vibration: bool = False) -> tuple[str, ...]:
    """Names of the parameters a fit with ``options`` adjusts (``vibration``: b_v too, :data:`VIBRATION_DAMPING`)."""
    names = ("K_Nm_per_rad", "C_Nms_per_rad") if options.params == "K" else PARAM_NAMES
    return (*names, VIBRATION_DAMPING) if vibration else names


def free_vector(p: TwoMassParams, free: tuple[str, ...]) -> np.ndarray:
    """The vector a fit adjusts for the parameters ``free`` of ``p``: each one's natural logarithm, b_v
    (:data:`VIBRATION_DAMPING`) as r = J_l b_v/((J_m+J_l) C)."""
    return np.array([_vibration_ratio(p) if n == VIBRATION_DAMPING else np.log(getattr(p, n)) for n in free])


def with_free(fixed: TwoMassParams, free: tuple[str, ...], x: np.ndarray) -> TwoMassParams:
    """``fixed`` with the parameters ``free`` set from the vector ``x`` (:func:`free_vector`'s inverse)."""
    named = dict(zip(free, np.asarray(x, dtype=float).tolist()))
    r = named.pop(VIBRATION_DAMPING, None)
    p = replace(fixed, **{n: float(np.exp(v)) for n, v in named.items()})
    return p if r is None else replace(p, bv_Nms_per_rad=r * _vibration_share(p))


def free_is_finite(free: tuple[str, ...], x: np.ndarray) -> bool:
    """Whether the vector ``x`` of ``free`` names positive finite parameters (no logarithm's exp under- or overflowed)
    and a finite b_v ratio."""
    logs = np.array([v for n, v in zip(free, x) if n != VIBRATION_DAMPING])
    return bool(np.all(np.isfinite(x)) and np.all(np.isfinite(np.exp(logs))) and np.all(np.exp(logs) > 0.0))


def _vibration_share(p: TwoMassParams) -> float:
    """(J_m+J_l) C/J_l, N·m·s/rad: the b_v that doubles the resonance's damping (r = 1). In numpy's arithmetic: an
    inertia whose logarithm's exp underflowed to 0 (a far-off step of Levenberg–Marquardt) gives inf or NaN, judged
    by the fit as any other overflow (:func:`free_is_finite`, a non-finite cost), not a ZeroDivisionError."""
    return float((np.float64(p.Jm_kgm2) + p.Jl_kgm2) * p.C_Nms_per_rad / np.float64(p.Jl_kgm2))


def _vibration_ratio(p: TwoMassParams) -> float:
    """r = b_v/((J_m+J_l) C/J_l) of ``p``."""
    return p.bv_Nms_per_rad / _vibration_share(p)


class _Problem:
    """Residuals of one fit: which parameters are free, the data, the weights."""

    def __init__(self, frf: FrequencyResponse, band: tuple[float, float], options: FitOptions,
                 fixed: TwoMassParams, vibration: bool = False) -> None:
        sel = fitted_bins(frf, band)
        self.f = frf.f_hz[sel]
        self.log_h = np.log(frf.H[sel])
        g2 = np.clip(frf.coherence[sel], 0.0, COHERENCE_CLIP)
        self.w = g2 / (1.0 - g2) if options.weighting == "coherence" else np.ones_like(g2)
        self.sqrt_w = np.sqrt(self.w)
        self.kind = options.kind
        self.vibration = vibration  # b_v free beside the others (analysis.fit's bracketing fit)
        self.free = _free_params(options, vibration)
        self.fixed = fixed
        self.band = band
        self.replicates = frf.replicates or ()
        offsets, kernel = window_kernel(frf)
        f_fine, self.smooth = _kernel_operator(self.f, offsets, kernel[sel], frf.segment_s)
        self.gain = 1.0 - (frf.noise_ratio[sel] if frf.noise_ratio is not None else 0.0)
        self.fold = []  # (factor·A_k, factor·B_k) of the fold-over terms, H at f + k/T and k/T − f
        fold_f = []
        if frf.alias is not None:
            for k, (a, b) in enumerate(frf.alias[:, :, sel], start=1):
                up, down = k / frf.period_s + self.f, k / frf.period_s - self.f
                self.fold.append((self.f / up * a, -self.f / down * b))
                fold_f += [up, down]
        # every frequency the model is evaluated at, in one array (one call instead of 1 + 2 per order): the fine
        # ones, then per order f + k/T and k/T − f
        self.f_eval = np.concatenate((f_fine, *fold_f))
        self.n_fine = f_fine.size
        self.load_factor: Callable[[np.ndarray], np.ndarray] | None = None  # the fit's model: a rigid load

    def replicate_problems(self, options: FitOptions) -> list[_Problem]:
        """This problem on each delete-one-block replicate (:attr:`replicates`, ``options`` as this one's), those with
        the same bins only: a replicate with an empty (non-finite or zero) bin the full record has would misalign the
        rows of anything compared row by row with this one's."""
        reps = (_Problem(r, self.band, options, self.fixed, self.vibration) for r in self.replicates)
        return [p for p in reps if np.array_equal(p.f, self.f)]

    def params(self, x: np.ndarray) -> TwoMassParams:
        """Model parameters from the vector ``x`` of the free ones (:func:`with_free`)."""
        return with_free(self.fixed, self.free, x)

    def x0(self, p: TwoMassParams) -> np.ndarray:
        """The vector of the free parameters of ``p`` (:func:`free_vector`)."""
        return free_vector(p, self.free)

    def response(self, x: np.ndarray, f_hz: np.ndarray) -> np.ndarray:
        """The model's torque → motor speed response, (rad/s)/(N·m), at ``f_hz`` (Hz) for the free vector ``x``
        (with the load inertia's factor :attr:`load_factor` of f_hz when one is set)."""
        factor = None if self.load_factor is None else self.load_factor(f_hz)
        return frequency_response(self.params(x), f_hz, factor)

    def log_ratio(self, x: np.ndarray) -> np.ndarray:
        """ln(H_model/H_meas) at the band's bins (complex).

        The model as H1 sees it: the plant's H through the Welch window kernel, scaled by the torque
        noise's 1 − G_nn/G_xx, plus the encoder's fold-over terms (:mod:`analysis.frf`).
        """
        h_all = self.response(x, self.f_eval)
        h = self.gain * (self.smooth @ h_all[:self.n_fine])
        n = self.f.size
        for k, (a, b) in enumerate(self.fold):
            up = self.n_fine + 2 * k * n
            h = h + h_all[up:up + n] * a + np.conj(h_all[up + n:up + 2 * n]) * b
        return np.log(h) - self.log_h

    def residuals(self, x: np.ndarray) -> np.ndarray:
        """Weighted residual vector for ``least_squares``."""
        z = self.log_ratio(x)
        if self.kind == "amplitude":
            return self.sqrt_w * z.real
        return np.concatenate([self.sqrt_w * z.real, self.sqrt_w * wrapped(z).imag])


def wrapped(log_h: np.ndarray) -> np.ndarray:
    """A complex ln H (or a ratio of two) with its phase wrapped to ±π."""
    return log_h.real + 1j * np.angle(np.exp(1j * log_h.imag))


def _kernel_operator(f_hz: np.ndarray, offsets_hz: np.ndarray, kernel: np.ndarray,
                     segment_s: float) -> tuple[np.ndarray, sparse.csr_array]:
    """The distinct fine frequencies f + ν, Hz, of all bins and the sparse matrix that applies each bin's
    kernel to the model's H there: Σ_ν H(f+ν)·kernel(f, ν) = (matrix @ H(fine))[bin].

    The bins and the kernel's offsets lie on one grid of spacing 1/(``KERNEL_PER_BIN``·segment), so neighbouring
    bins share most of their fine frequencies: ~1 600 distinct ones instead of bins × offsets (~12 700), and the
    fit evaluates the model ~300 times. When every sum f + ν is within 1e-9 of a grid point (a rounding difference
    of a few ulp) the grid points are taken; an FRF off that grid keeps its exact distinct sums.
    """
    fine = f_hz[:, None] + offsets_hz[None, :]
    step = 1.0 / (KERNEL_PER_BIN * segment_s)
    grid = np.round(fine / step)
    if np.all(np.abs(fine - grid * step) <= 1e-9 * np.maximum(np.abs(grid * step), step)):
        first = grid.min()
        values, where = np.arange(first, grid.max() + 1.0) * step, (grid - first).astype(np.intp)
    else:
        values, where = np.unique(fine, return_inverse=True)
    # each row's offsets are distinct and increasing, so are its columns: the CSR arrays directly
    indptr = np.arange(f_hz.size + 1) * offsets_hz.size
    return values, sparse.csr_array((kernel.ravel(), where.ravel(), indptr), shape=(f_hz.size, values.size))


def _jacobian(problem: _Problem, x: np.ndarray) -> np.ndarray:
    """Jacobian of ``problem``'s weighted residuals at the free vector ``x`` by central differences."""
    return _central_differences(problem.residuals, x)


def _central_differences(func: Callable[[np.ndarray], np.ndarray], x: np.ndarray) -> np.ndarray:
    """d func/d x at the free vector ``x``, one column per parameter."""
    step = 1e-6  # in ln(parameter) a 1 ppm change (in b_v's ratio r a 1e-6 share of C's damping), far above rounding
    # (the residuals are ~1e-3…1) and far below the curvature's scale (the cost changes by ≪ 1 % of its value over it);
    # central differences, error O(step²)
    return np.stack([(func(x + step * e) - func(x - step * e)) / (2.0 * step) for e in np.eye(x.size)], axis=1)
