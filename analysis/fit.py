"""Fit the two-mass model to a measured frequency response (design §5 steps 5–6).

Residuals are log-amplitude differences ln|H_model| − ln|H_meas| (``kind="amplitude"``, the
paper's clock-immune criterion) or the complex log ratio ln(H_model/H_meas), split into amplitude
and phase (``kind="complex"``), at the FRF bins of the band 10 Hz … min(0.4·f_enc, 500 Hz). Each bin
is weighted by γ²/(1−γ²) — the inverse of the variance of ln|H1| up to a constant — with γ²
clipped to 0.99 so that no handful of bins rules the fit.

Parameters are fitted as logarithms (positive, well scaled) with Levenberg–Marquardt
(``scipy.optimize.least_squares(method="lm")``) from a few starts built from the FRF itself
(:func:`initial_guess`); the lowest cost wins. The joint damping C is always fitted: fixing C = 0
biases K by about 20 %. The viscous frictions b_m, b_l are fixed at 0: they only shape |H| below
(b_m+b_l)/(2π(J_m+J_l)), a fraction of a hertz for any joint, far below the 10 Hz band edge, so
they are not identifiable from the band and fitting them would only make JᵀJ singular.

Confidence intervals come from the session's own scatter when the FRF carries delete-one-block
replicates (:attr:`analysis.frf.FrequencyResponse.replicates`): each replicate is refitted from the
optimum and the jackknife covariance (B−1)/B Σ (x_b − x̄)(x_b − x̄)ᵀ of the log parameters is the
statistical part, with Student's t for B − 1 degrees of freedom. It sees everything that varies
along the record — sensor noise, torque-estimate noise, the plant's response to what the motion
does not repeat, nonlinear distortion that changes from period to period — and on 10 s simulated
sessions matches the spread of the errors over seeds (0.04…0.2 %), where the Jacobian's
s²·(JᵀJ)⁻¹ with correlation inflation was 3…10× wider. Without replicates (records too short for
four blocks) that Jacobian covariance is used, with the normal 1.96. Then the misfit's share is added:
what the residual leaves unexplained, propagated to the parameters with its own size and correlation along
frequency (:func:`analysis.adequacy.misfit_covariance`, a HAC sandwich) — the part no scatter between
blocks shows because every period repeats it (the chain's small errors, a mode or a nonlinearity the
two-mass model lacks). Where that share is below the pull of the systematic errors no scatter shows, the latter is
taken instead: the share of the encoder's quantisation error that repeats with the motion
(:func:`analysis.adequacy.quantisation_pull` times :attr:`FitOptions.quantisation_repeating_share`: the part the fit
absorbed leaves no residual) and the smooth errors of the chain and of the speed loop's feedback of the rest of the
quantisation (:func:`analysis.adequacy.chain_pull`) — computed from the session's own spectra and the encoder's
resolution (:attr:`FitOptions.speed_lsb_rad`); without the resolution, the constant :data:`CHAIN_REL_STD`. Last, the
bias an error on the torque estimate may leave (noise on the FRF's input flattens the resonance peak of H1, and C
reads high): the shift of the parameters when the resonance is read from H2 instead (:mod:`analysis.input_noise`),
the truth lying between the two readings. The 95 % interval is exp(ln θ ± half-width) on each value.

The model is compared with the measurement as the Welch estimator sees it: H convolved with the
Hann window's spectral kernel |W(ν)|², weighted by the finely resolved torque spectrum
(:func:`analysis.frf.window_kernel`). At 0.5 s segments (2 Hz bins) the resonance peak is only a
few bins wide; fitting the raw H there biased J_l by −1 % and C by +3 %.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Literal

import numpy as np
from scipy import optimize, sparse, stats
from scipy.ndimage import median_filter

from analysis.adequacy import chain_pull, lines_per_bin, misfit_covariance, quantisation_pull, systematic_std
from analysis.encoder import quantisation_bound
from analysis.frf import KERNEL_PER_BIN, FrequencyResponse, window_kernel
from analysis.input_noise import h2_at_resonance
from analysis.model import TwoMassParams, antiresonance_hz, frequency_response, resonance_hz

FitKind = Literal["amplitude", "complex"]
FitParams = Literal["K", "K,Jm,Jl"]
FitStatus = Literal["converged", "max_evaluations", "failed"]
FitWeighting = Literal["coherence", "uniform"]

PARAM_NAMES: tuple[str, ...] = ("K_Nm_per_rad", "Jm_kgm2", "Jl_kgm2", "C_Nms_per_rad")
BAND_LOW_HZ = 10.0
BAND_HIGH_MAX_HZ = 500.0
BAND_HIGH_FRACTION_OF_FENC = 0.4
COHERENCE_CLIP = 0.99
Z95 = 1.959963984540054
# 1σ relative floor of the systematic part of an interval, used only when the fit is not given the encoder's
# resolution (a direct call of fit_two_mass; the pipeline always gives it). Where it comes from: on the simulated
# bench (8 plants with K, J_m, J_l scaled 0.5…2, 10 seeds each, 10 s sessions) every seed of a plant shares an
# error, −0.6…+0.6 % — which session 5 traced to the 2^17 counts/rev encoder's quantisation pulling the fit
# (bench/chain_bias.py; with 2^20 counts the shared error is ≤ 0.1 %): what analysis.adequacy.quantisation_pull
# now computes from each session's own spectra (0.35…0.71 % on those plants, 0.17…0.20 % at 2^20 counts). A
# torque scale error (k_t, a sensor gain) multiplies K, J_m, J_l, C alike and no session can show it: it is a bench
# constant (acq selftest checks k_t against a known inertia), not part of these intervals.
CHAIN_REL_STD = 0.004
_START_DAMPING_RATIOS = (0.01, 0.05, 0.2)


class FitInputError(ValueError):
    """The fit cannot start: bad band, too few usable bins, or missing nominal inertias."""


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
        on the parameters (:func:`analysis.adequacy.quantisation_pull`) instead of :data:`CHAIN_REL_STD`.
    quantisation_repeating_share : float
        Share (0…1) of the quantisation error that repeats with the motion
        (:func:`analysis.quantisation_lock.locked_share`): only that share is a bias the jackknife cannot see; the
        rest scatters from period to period and is in the jackknife's spread. 1 (all of it) when not measured.
    """

    params: FitParams = "K,Jm,Jl"
    kind: FitKind = "amplitude"
    band_hz: tuple[float, float] | None = None
    weighting: FitWeighting = "coherence"
    speed_lsb_rad: float | None = None
    quantisation_repeating_share: float = 1.0


@dataclass(frozen=True)
class FitResult:
    """The fitted two-mass model with its uncertainty.

    Attributes
    ----------
    values : TwoMassParams
        Best-fit parameters (b_m = b_l = 0).
    ci95 : dict of str to (float, float)
        95 % confidence interval (low, high) per parameter name of :data:`PARAM_NAMES`, SI units;
        a fixed parameter has a zero-width interval.
    fitted : tuple of str
        Names of the fitted parameters, the order of ``covariance``.
    covariance : ndarray, shape (p, p)
        Covariance of the natural logarithms of the fitted parameters (the jackknife's scaled by
        (t/1.96)², so that ±1.96 σ is the 95 % interval in either case), with the misfit's or the systematic pull's
        share and the input-noise bound d dᵀ/3 (:mod:`analysis.input_noise`) added.
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


def default_band_hz(period_s: float) -> tuple[float, float]:
    """Default fit band (10 Hz, min(0.4·f_enc, 500 Hz)) for an encoder period ``period_s`` (s)."""
    return BAND_LOW_HZ, min(BAND_HIGH_FRACTION_OF_FENC / period_s, BAND_HIGH_MAX_HZ)


def judged_fit(frf: FrequencyResponse, fit: FitResult) -> FitResult:
    """``fit`` with its band widened up to the default band's top (:func:`default_band_hz`) where it ends below:
    the fitted model is judged against all of the FRF the encoder resolves. A band chosen to end below a mode does
    not remove the mode's pull on K (a third mass at 160–190 Hz with the band ending at 150 Hz: K −3 % with an
    interval of ±0.5 %), so the misfit tests look there too."""
    top = default_band_hz(frf.period_s)[1]
    return fit if fit.band[1] >= top else replace(fit, band=(fit.band[0], top))


def band_mask(f_hz: np.ndarray, band: tuple[float, float]) -> np.ndarray:
    """Boolean mask of the frequencies ``f_hz`` (Hz) inside the closed band (low, high) Hz."""
    return (f_hz >= band[0]) & (f_hz <= band[1])


def fitted_bins(frf: FrequencyResponse, band: tuple[float, float]) -> np.ndarray:
    """Boolean mask of the bins a fit in ``band`` (Hz) uses: inside it, with a finite, non-zero H."""
    return band_mask(frf.f_hz, band) & np.isfinite(frf.H) & (np.abs(frf.H) > 0)


def initial_guess(frf: FrequencyResponse, band: tuple[float, float]) -> TwoMassParams:
    """Estimate K, J_m, J_l from the FRF alone, without any nominal value.

    The compensated amplitude m(f) = |H|·2πf is 1/(J_m+J_l) well below the anti-resonance and
    1/J_m well above the resonance; its minimum marks f_a, its maximum above f_a marks f_r. The
    total inertia is the median over the band of shape(f)/m(f), with shape the undamped model's
    |1 − (f/f_a)²| / |1 − (f/f_r)²| and the bins within 15 % of f_a or f_r left out. Then
    J_m = J_tot (f_a/f_r)², J_l = J_tot − J_m, K = J_l (2π f_a)². C is set for a damping ratio of
    5 % at the resonance.

    Parameters
    ----------
    frf : FrequencyResponse
        Measured frequency response.
    band : tuple of float
        Band (low, high), Hz, to look in.

    Returns
    -------
    TwoMassParams
    """
    sel = band_mask(frf.f_hz, band) & np.isfinite(frf.H) & (frf.H != 0)
    f = frf.f_hz[sel]
    log_m = median_filter(np.log(np.abs(frf.H[sel]) * 2.0 * np.pi * f), size=3, mode="nearest")
    i_r = int(np.argmax(log_m[1:])) + 1
    i_a = int(np.argmin(log_m[:i_r]))
    fa, fr = f[i_a], f[i_r]
    keep = (np.abs(f / fa - 1.0) > 0.15) & (np.abs(f / fr - 1.0) > 0.15)
    if not np.any(keep):
        keep = np.ones_like(f, dtype=bool)
    shape = np.abs(1.0 - (f[keep] / fa) ** 2) / np.abs(1.0 - (f[keep] / fr) ** 2)
    j_tot = float(np.median(shape / np.exp(log_m[keep])))
    jm = j_tot * (fa / fr) ** 2
    jl = j_tot - jm
    k = jl * (2.0 * np.pi * fa) ** 2
    return TwoMassParams(k, jm, jl, _damping_for_ratio(k, jm, jl, 0.05))


def _damping_for_ratio(k: float, jm: float, jl: float, zeta: float) -> float:
    """Joint damping C, N·m·s/rad, giving damping ratio ``zeta`` at the resonance."""
    return 2.0 * zeta * k / (2.0 * np.pi * resonance_hz(k, jm, jl))


def _free_params(options: FitOptions) -> tuple[str, ...]:
    """Names of the parameters a fit with ``options`` adjusts."""
    return ("K_Nm_per_rad", "C_Nms_per_rad") if options.params == "K" else PARAM_NAMES


class _Problem:
    """Residuals of one fit: which parameters are free, the data, the weights."""

    def __init__(self, frf: FrequencyResponse, band: tuple[float, float], options: FitOptions,
                 fixed: TwoMassParams) -> None:
        sel = fitted_bins(frf, band)
        self.f = frf.f_hz[sel]
        self.log_h = np.log(frf.H[sel])
        g2 = np.clip(frf.coherence[sel], 0.0, COHERENCE_CLIP)
        self.w = g2 / (1.0 - g2) if options.weighting == "coherence" else np.ones_like(g2)
        self.sqrt_w = np.sqrt(self.w)
        self.kind = options.kind
        self.free = _free_params(options)
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

    def params(self, x: np.ndarray) -> TwoMassParams:
        """Model parameters from the log vector ``x`` of the free ones."""
        return replace(self.fixed, **dict(zip(self.free, np.exp(x).tolist())))

    def x0(self, p: TwoMassParams) -> np.ndarray:
        """Log vector of the free parameters of ``p``."""
        return np.log([getattr(p, n) for n in self.free])

    def response(self, x: np.ndarray, f_hz: np.ndarray) -> np.ndarray:
        """The model's torque → motor speed response, (rad/s)/(N·m), at ``f_hz`` (Hz) for the log vector ``x``
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


def fit_two_mass(
    frf: FrequencyResponse,
    options: FitOptions = FitOptions(),
    nominal: TwoMassParams | None = None,
) -> FitResult:
    """Fit the two-mass model to a measured FRF by Levenberg–Marquardt from a few starts.

    Parameters
    ----------
    frf : FrequencyResponse
        Measured frequency response torque → motor speed.
    options : FitOptions, optional
        Free parameters, residual kind and band.
    nominal : TwoMassParams or None, optional
        The bench's nominal values. Required for ``params="K"`` (J_m, J_l are fixed to them);
        otherwise only one extra start among those built from the FRF (the best cost wins, so
        wrong nominal values cannot pull the result).

    Returns
    -------
    FitResult
        A failed fit comes back with ``status="failed"`` and NaN intervals, not an exception.

    Raises
    ------
    FitInputError
        If the band is empty or holds fewer usable bins than three per free parameter, or
        ``params="K"`` is asked without nominal inertias.
    """
    band = options.band_hz or default_band_hz(frf.period_s)
    band = (float(band[0]), float(min(band[1], frf.f_hz[-1])))
    if not band[0] < band[1]:
        raise FitInputError(f"fit band {band[0]:g}…{band[1]:g} Hz is empty")
    if options.params == "K" and nominal is None:
        raise FitInputError("--params K needs the bench's nominal J_m and J_l")
    n_bins, n_free = int(np.count_nonzero(fitted_bins(frf, band))), len(_free_params(options))
    if n_bins < 3 * n_free:  # also before the initial guess, whose search needs bins
        raise FitInputError(
            f"fit band {band[0]:g}…{band[1]:g} Hz holds {n_bins} FRF bin{'' if n_bins == 1 else 's'} (the "
            f"{frf.segment_s:g} s segments give {1.0 / frf.segment_s:g} Hz bins); need at least {3 * n_free}"
        )
    guess = initial_guess(frf, band)
    if options.params == "K":
        starts = _starts_inertias_fixed(guess, nominal)
    else:
        starts = [replace(guess, C_Nms_per_rad=_damping_for_ratio(guess.K_Nm_per_rad, guess.Jm_kgm2,
                                                                    guess.Jl_kgm2, z))
                  for z in _START_DAMPING_RATIOS]
        if nominal is not None:
            starts.append(replace(nominal, C_Nms_per_rad=_damping_for_ratio(
                nominal.K_Nm_per_rad, nominal.Jm_kgm2, nominal.Jl_kgm2, 0.05), bm_Nms_per_rad=0.0,
                bl_Nms_per_rad=0.0))
    problem = _Problem(frf, band, options, starts[0])
    n_res = problem.f.size * (1 if options.kind == "amplitude" else 2)
    # a start or a jackknife replicate may wander to log-parameters whose exp overflows: such a solution has a
    # non-finite cost or spread and is judged by that, so numpy's warnings about it would only reach the user
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
        best = None
        for start in starts:
            try:
                res = optimize.least_squares(problem.residuals, problem.x0(start), method="lm", x_scale=1.0)
            except (ValueError, FloatingPointError):
                continue
            # a finite cost at a parameter that under- or overflowed (an inertia of exactly 0 on a far-off FRF,
            # seen with an analytic Jacobian) is no solution: f_a, f_r and the intervals divide by it
            physical = bool(np.all(np.isfinite(np.exp(res.x))) and np.all(np.exp(res.x) > 0.0))
            if np.isfinite(res.cost) and physical and (best is None or res.cost < best.cost):
                best = res
        if best is None:
            return _failed(problem, band, options, "no start gave a finite cost")
        return _result(problem, best, band, options, n_res, _quantisation_floor(frf, problem, best.x, options),
                       _input_noise_shift(frf, problem, best.x, options))


def _input_noise_shift(frf: FrequencyResponse, problem: _Problem, x: np.ndarray, options: FitOptions) -> np.ndarray:
    """How far the free log parameters move when the resonance is read from H2 instead of H1
    (:func:`analysis.input_noise.h2_at_resonance`, one Levenberg–Marquardt run from the optimum ``x``): the bias an
    error on the torque estimate may leave (zero when the band holds no resonance peak; infinite when the refit
    fails, stops without converging or ends off the finite numbers: the fit is not stable under it)."""
    h2 = h2_at_resonance(frf, problem.params(x), problem.band)
    if h2 is None:
        return np.zeros_like(x)
    try:
        refit = optimize.least_squares(_Problem(h2, problem.band, options, problem.fixed).residuals, x, method="lm",
                                       x_scale=1.0)
    except (ValueError, FloatingPointError):
        return np.full_like(x, np.inf)
    if refit.status <= 0 or not np.all(np.isfinite(refit.x)):  # 0: the evaluation budget ran out; < 0: failed
        return np.full_like(x, np.inf)
    return refit.x - x


def _quantisation_floor(frf: FrequencyResponse, problem: _Problem, x: np.ndarray,
                        options: FitOptions) -> np.ndarray | None:
    """Variance of each free log parameter that the systematic errors no scatter shows may pull it by: the encoder's
    quantisation (:func:`analysis.adequacy.quantisation_pull`, times the share of the error that repeats with the
    motion) and the smooth systematic errors of the chain and of the loop's feedback of the rest of the quantisation
    (:func:`analysis.adequacy.chain_pull`); None without the encoder's resolution.

    Always with K, J_m, J_l and C free: with the inertias held at nominal values (``params="K"``) the pull on K alone
    would be a fraction of what the data can tell K to, and the interval would lean on inertias known exactly.
    """
    if not options.speed_lsb_rad:
        return None
    bound, lines = quantisation_terms(frf, problem.band, options.speed_lsb_rad)
    values = problem.params(x)
    full = _Problem(frf, problem.band, replace(options, params="K,Jm,Jl"), values)
    jac = _jacobian(full, full.x0(values))
    share = options.quantisation_repeating_share
    pull = share * np.diag(quantisation_pull(bound, lines, jac, full.sqrt_w))
    pull = pull + np.diag(chain_pull(jac, full.sqrt_w, systematic_std(bound, share)))
    return pull[[full.free.index(name) for name in problem.free]]


def quantisation_terms(frf: FrequencyResponse, band: tuple[float, float],
                       lsb_rad: float) -> tuple[np.ndarray, np.ndarray]:
    """At a fit's bins in ``band`` (Hz): the white-quantisation bound of |H| for the encoder's resolution ``lsb_rad``
    (:func:`analysis.encoder.quantisation_bound`; inf where there is no signal) and the motion's lines per bin
    (:func:`analysis.adequacy.lines_per_bin`) — what the intervals' floor and the misfit test carry through the fit."""
    sel = fitted_bins(frf, band)
    f = frf.f_hz[sel]
    bound = quantisation_bound(f, frf.H[sel], frf.torque_psd[sel], frf.period_s, lsb_rad)
    return bound, lines_per_bin(frf.torque_psd_fine, frf.f_hz[1] / KERNEL_PER_BIN, f, frf.f_hz[1])


def _starts_inertias_fixed(guess: TwoMassParams, nominal: TwoMassParams) -> list[TwoMassParams]:
    """Starts for ``params="K"``: K from the FRF's f_a and from its f_r, with the nominal inertias."""
    jm, jl = nominal.Jm_kgm2, nominal.Jl_kgm2
    k_from_fa = jl * (2.0 * np.pi * guess.antiresonance_hz) ** 2
    k_from_fr = (2.0 * np.pi * guess.resonance_hz) ** 2 * jm * jl / (jm + jl)
    return [TwoMassParams(k, jm, jl, _damping_for_ratio(k, jm, jl, z))
            for k in (k_from_fa, k_from_fr) for z in (0.02, 0.1)]


def _result(problem: _Problem, res: optimize.OptimizeResult, band: tuple[float, float],
            options: FitOptions, n_res: int, quantisation_floor: np.ndarray | None = None,
            input_noise_shift: np.ndarray | None = None) -> FitResult:
    """Package the best least-squares solution with its covariance and intervals (``input_noise_shift``: the log
    parameters' shift from H1 to H2 at the resonance, :func:`_input_noise_shift`; None: none)."""
    values = problem.params(res.x)
    n_free = res.x.size
    dof = max(n_res - n_free, 1)
    s2 = 2.0 * res.cost / dof * _correlation_inflation(res.fun[: problem.f.size])
    jac = np.asarray(res.jac)
    cov = s2 * np.linalg.pinv(jac.T @ jac)
    quantile = Z95
    if problem.replicates:
        cov, quantile = _jackknife(problem, res.x, options)
    cov = cov * (quantile / Z95) ** 2  # the interval below is ±1.96 σ of this covariance
    misfit = misfit_covariance(res.fun, jac, problem.f.size)
    # at least the quantisation's pull on the parameters (what the fit absorbed of an error no scatter and no residual
    # shows), or without the encoder's resolution the chain's accuracy: each stands for the systematic error as a
    # whole, the part a residual shows included, so it only tops up what the misfit leaves below it
    floor = (quantisation_floor if quantisation_floor is not None
             else np.full(n_free, np.log1p(CHAIN_REL_STD) ** 2))
    cov += misfit + np.diag(np.clip(floor - np.diag(misfit), 0.0, None))
    if input_noise_shift is not None:
        # the truth lies between the H1 and the H2 reading of the resonance (analysis.input_noise): a bias bounded by
        # the shift d, of unknown size within it, carried as a rectangular distribution of half-width |d| (GUM:
        # variance d²/3, so the 95 % interval holds the whole bracket, 1.96/√3 = 1.13 |d|), along d (a joint shift)
        cov += np.outer(input_noise_shift, input_noise_shift) / 3.0
    sigma = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    ci = {n: (getattr(values, n), getattr(values, n)) for n in PARAM_NAMES}
    for name, x, s in zip(problem.free, res.x, sigma):
        ci[name] = (float(np.exp(x - Z95 * s)), float(np.exp(x + Z95 * s)))
    amp = problem.log_ratio(res.x).real
    rms = float(np.sqrt(np.sum(problem.w * amp**2) / np.sum(problem.w)))
    status: FitStatus = "converged" if res.status > 0 else ("max_evaluations" if res.status == 0 else "failed")
    cov.setflags(write=False)
    return FitResult(
        values=values, ci95=ci, fitted=problem.free, covariance=cov, cost=float(res.cost),
        residual_rms=rms, status=status, message=str(res.message), band=band, options=options,
        f_a=antiresonance_hz(values.K_Nm_per_rad, values.Jl_kgm2),
        f_r=resonance_hz(values.K_Nm_per_rad, values.Jm_kgm2, values.Jl_kgm2),
        n_points=int(problem.f.size),
    )


def _jackknife(problem: _Problem, x_best: np.ndarray, options: FitOptions) -> tuple[np.ndarray, float]:
    """Delete-one-block jackknife covariance of the log parameters and its 95 % t quantile.

    Each replicate FRF is refitted by one Levenberg–Marquardt run from the full fit's optimum
    (the replicates differ from the full record by one block, so the optimum is close).
    """
    xs = []
    for rep in problem.replicates:
        sub = _Problem(rep, problem.band, options, problem.fixed)
        try:
            xs.append(optimize.least_squares(sub.residuals, x_best, method="lm", x_scale=1.0).x)
        except (ValueError, FloatingPointError):
            continue
    b = len(xs)
    if b < 2 or not np.all(np.isfinite(xs)):  # a replicate that diverged: the fit is not stable under the data
        return np.full((x_best.size, x_best.size), np.inf), Z95
    d = np.asarray(xs) - np.mean(xs, axis=0)
    return (b - 1) / b * (d.T @ d), float(stats.t.ppf(0.975, b - 1))


def _correlation_inflation(r: np.ndarray, max_lag: int = 3) -> float:
    """Variance inflation 1 + 2 Σ ρ_k for residuals correlated between neighbouring bins.

    Welch bins overlap (Hann: adjacent bins share much of their window), and a model misfit is
    smooth in frequency, so neighbouring residuals are not independent; the effective number of
    points is N / (1 + 2 Σ ρ_k) with ρ_k the lag-k autocorrelation (positive lags up to
    ``max_lag``, negative values ignored).
    """
    r = r - r.mean()
    denom = float(r @ r)
    if denom <= 0.0 or r.size <= max_lag + 1:
        return 1.0
    rho = [float(r[:-k] @ r[k:]) / denom for k in range(1, max_lag + 1)]
    return 1.0 + 2.0 * sum(max(v, 0.0) for v in rho)


def _failed(problem: _Problem, band: tuple[float, float], options: FitOptions, message: str) -> FitResult:
    """A FitResult saying that no start converged to a finite cost."""
    nan = float("nan")
    values = TwoMassParams(nan, nan, nan, nan)
    n = len(problem.free)
    cov = np.full((n, n), nan)
    cov.setflags(write=False)
    return FitResult(
        values=values, ci95={k: (nan, nan) for k in PARAM_NAMES}, fitted=problem.free, covariance=cov,
        cost=nan, residual_rms=nan, status="failed", message=message, band=band, options=options,
        f_a=nan, f_r=nan, n_points=int(problem.f.size),
    )


def log_ratio_jacobian(frf: FrequencyResponse, fit: FitResult) -> tuple[np.ndarray, np.ndarray]:
    """d ln(H_model/H_meas)/d x of a fit at its optimum, x its free log parameters (central differences, step 1e-6;
    the model as the fit sees the Welch estimate), and the square roots of its bin weights.

    Returns
    -------
    jac : ndarray of complex, shape (n, p)
        At the band's bins: the real part moves ln|H|, the imaginary part the phase.
    sqrt_w : ndarray, shape (n,)
    """
    problem = _Problem(frf, fit.band, fit.options, fit.values)
    return _central_differences(problem.log_ratio, problem.x0(fit.values)), problem.sqrt_w


def weighted_jacobian(jac: np.ndarray, sqrt_w: np.ndarray, kind: FitKind) -> np.ndarray:
    """The Jacobian of a fit's weighted residuals from :func:`log_ratio_jacobian`: amplitude rows, then (a complex
    fit) phase rows, each bin times its weight's square root; shape (n, p) or (2n, p)."""
    rows = [sqrt_w[:, None] * jac.real]
    if kind == "complex":
        rows.append(sqrt_w[:, None] * jac.imag)
    return np.concatenate(rows, axis=0)


def _jacobian(problem: _Problem, x: np.ndarray) -> np.ndarray:
    """Jacobian of ``problem``'s weighted residuals at the log parameters ``x`` by central differences."""
    return _central_differences(problem.residuals, x)


def _central_differences(func: Callable[[np.ndarray], np.ndarray], x: np.ndarray) -> np.ndarray:
    """d func/d x at the log parameters ``x``, one column per parameter."""
    step = 1e-6  # in ln(parameter): a 1 ppm change, far above rounding (the residuals are ~1e-3…1) and far below
    # the curvature's scale (the cost changes by ≪ 1 % of its value over it); central differences, error O(step²)
    return np.stack([(func(x + step * e) - func(x - step * e)) / (2.0 * step) for e in np.eye(x.size)], axis=1)


def kernel_model_log_ratio(frf: FrequencyResponse, fit: FitResult) -> np.ndarray:
    """ln(H_model/H_meas) of a fit's values against ``frf`` (complex, at the fit band's bins of ``frf``), the model as
    the fit sees the Welch estimate (:meth:`_Problem.log_ratio`)."""
    return model_log_ratios(frf, fit)(None)


def model_log_ratios(frf: FrequencyResponse,
                     fit: FitResult) -> Callable[[Callable[[np.ndarray], np.ndarray] | None], np.ndarray]:
    """ln(H_model/H_meas) of a fit's values against ``frf`` as the fit sees the Welch estimate, for any load: a
    function of the load inertia's factor (a function of f_hz, :func:`analysis.model.frequency_response`; None: the
    fit's rigid load) returning the complex log ratio at the fit band's bins. The fit's kernel and fold-over model is
    built once for all the loads asked for."""
    problem = _Problem(frf, fit.band, fit.options, fit.values)
    x = problem.x0(fit.values)

    def at(load_factor: Callable[[np.ndarray], np.ndarray] | None) -> np.ndarray:
        problem.load_factor = load_factor
        return problem.log_ratio(x)

    return at


def model_misfits(frf: FrequencyResponse, fit: FitResult) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """ln(H_model/H_measured) of a fit at its band's bins, for the full record and each replicate: the real part is
    ln|H_model| − ln|H_measured|, the imaginary part the phase difference (radians, wrapped to ±π).

    Parameters
    ----------
    frf : FrequencyResponse
        The measured response the fit was made to (its ``replicates`` give the second array).
    fit : FitResult
        A fit of ``frf`` that did not fail.

    Returns
    -------
    f_hz : ndarray, shape (n,)
        The band's bins, Hz.
    misfit : ndarray of complex, shape (n,)
        The full record's misfit (the model as the Welch estimator sees it, :class:`_Problem`).
    replicate_misfits : ndarray of complex, shape (B, n)
        The same model against each delete-one-block replicate (B = 0 without replicates).
    """
    problem = _Problem(frf, fit.band, fit.options, fit.values)
    x = problem.x0(fit.values)
    # a replicate with an empty (non-finite or zero) bin the full record has would misalign the rows: left out
    same_bins = [p for p in (_Problem(r, fit.band, fit.options, fit.values) for r in frf.replicates or ())
                 if np.array_equal(p.f, problem.f)]

    reps = [wrapped(p.log_ratio(x)) for p in same_bins]
    return problem.f, wrapped(problem.log_ratio(x)), np.asarray(reps, dtype=complex).reshape(len(reps), problem.f.size)
