"""The verdict's grades and the limits that set them: ok / poor / failed, and where each check's value crosses over.

:mod:`analysis.quality` judges an identification against these limits; :mod:`analysis.misfit_advice` and the
pipeline ask of them whether a measured phase is the plant's (:func:`phase_is_meaningful`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

Verdict = Literal["ok", "poor", "failed"]
RANK: dict[Verdict, int] = {"ok": 0, "poor": 1, "failed": 2}


@dataclass(frozen=True)
class Thresholds:
    """Limits of the verdict; a value past ``*_poor`` makes it poor, past ``*_failed`` failed.

    Attributes
    ----------
    excitation_poor, excitation_failed : float
        Mean coherence γ² between f_a and f_r below which the joint counts as weakly / not excited.
    coherence_poor, coherence_failed : float
        Mean coherence in the whole fit band. On 10 s simulated sessions the paper's 0.5 s profile
        gives 0.63…0.66, the 0.2 s triangle 0.78…0.96 over plants scaled 0.5…2; the limit is midway.
    misfit_ratio_poor : float
        Ratio of the fit's residual to the residual the coherence explains, above which the model
        counts as missing the data. Noise alone is judged by the coherence checks, not here.
    residual_poor, residual_failed : float
        Weighted RMS misfit of ln|H| (≈ relative misfit of |H|) that makes such a misfit poor /
        failed.
    ci_K_poor, ci_K_failed : float
        Relative half-width of the 95 % interval of K. The interval comes from the session's own
        scatter (jackknife over blocks of Welch segments), the fit's misfit (HAC) and the encoder
        quantisation's pull on the fit (:func:`analysis.systematic_errors.quantisation_pull`), so its width is the
        precision; 10 s simulated
        sessions of plants scaled 0.5…2 give ±0.5…1.7 % on K, J_m, J_l. These limits remain
        constants: what precision is "ok" is the user's requirement (K to a few % to see wear), not
        something the data can tell.
    ci_J_poor, ci_J_failed : float
        Relative half-width of the 95 % intervals of J_m and J_l (when fitted).
    clock_residual_amplitude_s, clock_residual_complex_s : float
        Clock-alignment residual, s, above which the result is poor, for an amplitude fit (a delay
        of a small fraction of a Welch segment does not bias |H|) and for a complex fit (a delay
        τ turns the phase by 2π f τ).
    """

    excitation_poor: float = 0.7
    excitation_failed: float = 0.4
    coherence_poor: float = 0.72
    coherence_failed: float = 0.3
    misfit_ratio_poor: float = 3.0
    residual_poor: float = 0.08
    residual_failed: float = 0.30
    ci_K_poor: float = 0.05
    ci_K_failed: float = 0.20
    ci_J_poor: float = 0.08
    ci_J_failed: float = 0.30
    clock_residual_amplitude_s: float = 1e-3
    clock_residual_complex_s: float = 1e-4


def phase_is_meaningful(clock_residual_s: float | None, thresholds: Thresholds = Thresholds()) -> bool:
    """True when the clocks were aligned to within the residual a complex fit accepts, so a measured phase is
    the plant's and not the clock offset's (None: not aligned)."""
    return clock_residual_s is not None and clock_residual_s <= thresholds.clock_residual_complex_s



def grade(value: float, poor_below: float, failed_below: float) -> Verdict:
    """ok / poor / failed for a value that is good when high (NaN counts as failed)."""
    if not value >= failed_below:
        return "failed"
    return "poor" if value < poor_below else "ok"
