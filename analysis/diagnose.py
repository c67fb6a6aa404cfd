"""Bench-config faults read from the data, as the analysis's verdict uses them.

A wrong ``pole_pairs`` or ``counts_per_rev`` (:mod:`analysis.speed_ratio`) or a reversed phase sequence
(:mod:`analysis.bench_checks`) found in a recording (:func:`recording_diagnosis`) replaces a poor or failed verdict's
reasons (:func:`with_fault`); an identified K, J_m or J_l an order of magnitude off the bench's nominal
(:func:`nominal_fault`: a unit or scale mistake), or J_m + J_l outside the tolerance of an inertia the bench knows
(:func:`inertia_fault`: the torque's scale), leads them (:func:`with_nominal_fault`).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import replace

import numpy as np

from analysis.bench_checks import phase_sequence_agreement, sequence_fault
from analysis.fit import Z95, FitResult
from analysis.model import PARAM_LABELS, TwoMassParams
from analysis.quality import Quality
from analysis.recording import Recording
from analysis.speed_ratio import electrical_speed_ratio, ratio_doubt, ratio_fault

#: An identified K, J_m or J_l this many times the bench's nominal value, or 1/this, is a unit or scale mistake,
#: not the joint: such mistakes are powers of ten (a current in mA read as A, a sensor's A/V off by a decade, a
#: load-side value where a motor-side one belongs is ratio² off), while wear changes K by percent and real joints
#: differ from their datasheet by tens of percent. The scenario family's plants, scaled ×0.5…×2 against the
#: unchanged nominal, stay 5× inside it; its "heavy arm 20 kg" adds only the arm's weight (gravity torque), not
#: inertia, in the simulator: fitted J_l 0.998× nominal (seed 0). A real arm left out of [nominal] Jl_kgm2 can come
#: closer: 20 kg as a 0.75 m rod about its end is 0.0375 kg·m² motor-side at ratio 10, J_l 6× the paper's.
NOMINAL_FACTOR = 10.0
#: The widest a real joint's K, J_m or J_l is known to stray from a correct [nominal]: the 20 kg arm above, J_l 6×
#: (datasheet scatter, wear and the scenario family's ×0.5…×2 are well inside it).
PLAUSIBLE_SPREAD = 6.0
#: A fitted value is a unit or scale mistake when its whole 95 % interval lies this many times off its nominal (or
#: 1/this): the midway on a log scale between the plausible spread and the decade mistakes come in,
#: √(6 × 10) = 7.7×, 1.29× from each. Deciding at 10× itself made a mistake of exactly a decade a coin flip: the
#: trial's [sim] K 8910 on a nominal 891 fitted 8904 (8621–9197, ok), 8944 and 8933 (poor) in three recordings.
MISTAKE_THRESHOLD = math.sqrt(PLAUSIBLE_SPREAD * NOMINAL_FACTOR)


def recording_diagnosis(rec: Recording) -> tuple[str | None, str | None]:
    """(fault, doubt) of a raw recording: :func:`ratio_fault` of its phase i_a and encoder, then (2–3 phases)
    :func:`sequence_fault`; and :func:`ratio_doubt` when a mismatched ratio is no evidence. (None, None) if all
    match or it cannot tell."""
    r = electrical_speed_ratio(rec.current_a["i_a"], rec.rate_hz, rec.encoder_index, rec.position_counts,
                               rec.period_s, rec.counts_per_rev, rec.pole_pairs)
    if r is None:
        return None, None
    doubt = ratio_doubt(r, rec.pole_pairs)
    if doubt is not None:  # acq selftest's slow move turns the motor through many electrical turns ...
        doubt += ("; check the constants with acq selftest" if rec.profile is not None
                  # ... on a bench acq commands; on a listening bench it commands none and leaves them unchecked too
                  else "; acq selftest cannot check them on a listening bench either: take them from the motor's and "
                       "the encoder's data sheets")
    fault = ratio_fault(r, rec.pole_pairs, rec.counts_per_rev)
    if fault is None and doubt is None and len(rec.current_a) >= 2:
        agreement = phase_sequence_agreement(rec.current_a, rec.rate_hz, rec.encoder_index, rec.position_counts,
                                             rec.period_s, r.lag_s)
        fault = sequence_fault(agreement, list(rec.current_a))
    return fault, doubt


def recording_fault(rec: Recording) -> str | None:
    """The fault of :func:`recording_diagnosis`: a bench constant named, or None."""
    return recording_diagnosis(rec)[0]


def with_fault(quality: Quality, diagnosis: Callable[[], tuple[str | None, str | None]]) -> Quality:
    """A poor / failed ``quality`` becomes failed with the fault ``diagnosis()`` finds as its only reason, so it says
    why instead of a bare failed. The other findings (low coherence, wide intervals, misfit, clock residual) follow
    from the wrong constant, and their advice ("shorten the acceleration time", "try --band") would send the
    technician after the motion instead of the bench config. No fault but a doubt (a mismatch the data do not
    support, :func:`ratio_doubt`): the doubt becomes the first reason, the others stay. An ``ok`` verdict (the data
    hold together: clocks aligned, model fits) or neither: unchanged — the diagnosis explains failures, it never
    overrules a consistent identification, so for an ``ok`` verdict ``diagnosis`` is not called
    (:func:`recording_diagnosis` is ~5 % of a 60 s session's analysis)."""
    if quality.verdict == "ok":
        return quality
    fault, doubt = diagnosis()
    if fault is not None:
        return replace(quality, verdict="failed", reasons=(fault,), faults=(fault,))
    if doubt is not None:
        return replace(quality, reasons=(doubt, *quality.reasons))
    return quality


def nominal_fault(values: TwoMassParams, nominal: TwoMassParams | None, fitted: tuple[str, ...],
                  ci95: dict[str, tuple[float, float]] | None = None) -> str | None:
    """The words for fitted K, J_m, J_l off the bench's ``nominal`` by a unit or scale mistake (None if none is):
    :data:`MISTAKE_THRESHOLD` (7.7×) or more, and with ``ci95`` (the fit's 95 % intervals) its whole interval too.
    A value the data hardly determine is no evidence of a mistake; one they pin down about a decade off is, on
    either side of 10× (K 8904, interval 8621…9197, on a nominal of 891: 9.99×, 9.68…10.32×).

    When every fitted one of them is off by about the same factor (within 2×), the torque is scaled — the
    current's unit or sensor scale, or k_t — because H = speed/torque scales K, J_m and J_l alike; otherwise the
    nominal values themselves are suspect (a load-side value, another unit).
    """
    if nominal is None:
        return None
    names = [n for n in ("K_Nm_per_rad", "Jm_kgm2", "Jl_kgm2") if n in fitted]
    factors = {n: getattr(values, n) / getattr(nominal, n) for n in names}
    off = [n for n, f in factors.items() if _side(f) != 0
           and all(_side(b / getattr(nominal, n)) == _side(f) for b in (ci95 or {}).get(n, ()) if math.isfinite(b))]
    if not off:
        return None
    first, rest = off[0], off[1:]
    label, unit = PARAM_LABELS[first]
    text = f"{label} is {_times(factors[first])} the bench's nominal {getattr(nominal, first):.4g} {unit}"
    if rest:
        text += f" ({', '.join(f'{PARAM_LABELS[n][0]} {_times(factors[n])}' for n in rest)})"
    if off == names and max(factors[n] for n in off) / min(factors[n] for n in off) < 2.0:
        return (text + ": the torque is scaled — check the current's unit and scale (amperes: [daq] sensor_A_per_V "
                "or sensor_A_per_A; an imported current column in A) and the torque constant ([motor] "
                "torque_constant_Nm_per_A)")
    return (text + ": check the [nominal] values (motor-side, SI units: a load-side value is [gear] ratio² larger) "
            "and that the bench file is this joint's")


def inertia_fault(fit: FitResult, nominal: TwoMassParams | None, tolerance: float | None) -> str | None:
    """The words for a fitted J_m + J_l off a known nominal J_m + J_l by more than ``tolerance`` (a fraction; None: the
    bench knows no inertia, no check), or None.

    H = speed/torque: a torque read ×q (a wrong k_t or current-sensor gain) gives K, J_m, J_l and C all ×q, so the
    fitted inertia against one known from a datasheet or CAD shows q. It counts only when the 95 % interval of the
    sum (from the log parameters' covariance, delta method) lies wholly outside (1 ± ``tolerance``) × nominal: an
    interval overlapping the band is no evidence. Needs J_m and J_l both fitted (``params="K"`` fixes them).
    """
    if tolerance is None or nominal is None or not {"Jm_kgm2", "Jl_kgm2"} <= set(fit.fitted):
        return None
    jm, jl = fit.values.Jm_kgm2, fit.values.Jl_kgm2
    i, j = fit.fitted.index("Jm_kgm2"), fit.fitted.index("Jl_kgm2")
    grad = np.array([jm, jl])  # d(J_m + J_l)/d(ln J_m, ln J_l)
    cov = np.asarray(fit.covariance)[np.ix_([i, j], [i, j])]
    total, known = jm + jl, nominal.Jm_kgm2 + nominal.Jl_kgm2
    sigma_log = math.sqrt(max(float(grad @ cov @ grad), 0.0)) / total if np.all(np.isfinite(cov)) else math.inf
    if not (math.isfinite(total) and total > 0.0 and math.isfinite(sigma_log)):
        return None
    low, high = total * math.exp(-Z95 * sigma_log), total * math.exp(Z95 * sigma_log)
    if (1.0 - tolerance) * known <= high and low <= (1.0 + tolerance) * known:
        return None
    q = total / known
    return (f"J_m + J_l is {q:.2f}× [nominal] Jm_kgm2 + Jl_kgm2 = {known:.4g} kg·m² (95 % interval "
            f"{low / known:.2f}–{high / known:.2f}×, [nominal] inertia_tolerance ±{tolerance * 100:g} %): the torque's "
            "scale — [motor] torque_constant_Nm_per_A or the current sensor's gain — is off by that factor; K, J_m, "
            "J_l, C all carry it — unless [nominal] Jm_kgm2 + Jl_kgm2 miss part of the joint's inertia")


def _side(factor: float, limit: float = MISTAKE_THRESHOLD) -> int:
    """+1 for a factor ≥ ``limit``, −1 for ≤ its inverse, 0 between (or not a positive number)."""
    if not (math.isfinite(factor) and factor > 0):
        return 0
    return 1 if factor >= limit else -1 if factor <= 1.0 / limit else 0


def _times(factor: float) -> str:
    """``1002×`` for a factor above 1, ``1/1002 of`` below."""
    return f"{factor:.0f}×" if factor >= 1.0 else f"1/{1.0 / factor:.0f} of"


def with_nominal_fault(quality: Quality, fault: str | None) -> Quality:
    """``quality`` at least poor with ``fault`` (:func:`nominal_fault`, :func:`inertia_fault`) as its first reason: a
    value an order of magnitude off, or a torque scaled against a known inertia, is a mistake however well the data
    hold together. A failed ``quality``: unchanged — its reasons say why the numbers cannot be trusted, and a value
    far off follows from them (20 µs of SYNC jitter gave J_m 1/14 of nominal)."""
    if fault is None or quality.verdict == "failed":
        return quality
    # not a fault in :attr:`Quality.faults`: the value is the fit's, and a fit of data that did not excite the joint
    # may be that far off — such a record stays "not excited" (an idle robot window's junk fit read J_m 11× nominal)
    return replace(quality, verdict="poor", reasons=(fault, *quality.reasons))
