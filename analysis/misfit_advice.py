"""What a misfit of the two-mass model is said to point to, in words: the reasons' causes and advice.

The verdict (:mod:`analysis.quality`) names a missed band or a third mode (:mod:`analysis.misfit_band`); the
sentences here say where the misfit lies against the fit's band, f_a and f_r, what in the joint or in the torque
estimate it points to, and what to do about it.
"""

from __future__ import annotations

import numpy as np

from analysis.adequacy import BandMisfit
from analysis.fit_problem import FitResult
from analysis.input_noise import EstimateError
from analysis.third_mode import ThirdMode
from analysis.verdict_limits import Thresholds, phase_is_meaningful

#: J_3/J_l up to which a third mode's first-order pull on K is given as a figure (:func:`first_order_pull`).
FIRST_ORDER_MASS_RATIO = 0.3


def first_order_pull(mode: ThirdMode) -> str:
    """The mode's pull on K as a figure, where its first-order estimate holds: the pull's second-order term is ~â
    relative, so up to â = :data:`FIRST_ORDER_MASS_RATIO` the figure is within ~30 %; a larger mass (0.6–1.2 for
    the simulated third mass, whose first-order figure read 1.1–1.8× the real error) is named without one."""
    if mode.mass_ratio > FIRST_ORDER_MASS_RATIO:
        return ""
    return f"; by roughly {100 * mode.k_shift:+.1f} %"


def beyond_band(f_hz: float, fit: FitResult, mode: bool) -> str:
    """Said of a misfit at ``f_hz`` beyond the band the fit matched (the tests judge up to the default band's top,
    :func:`analysis.fit.judged_fit`): a mode there still moves K; a window there is not described by the model
    fitted below it."""
    if f_hz <= fit.band[1]:
        return ""
    if mode:
        return f", beyond the band fitted (up to {fit.band[1]:g} Hz): narrowing --band does not remove its effect on K"
    return f", beyond the band fitted (up to {fit.band[1]:g} Hz), which the model fitted below it does not describe"


def one_phase_doubt(clock_residual_s: float | None, th: Thresholds) -> str:
    """The one-phase torque estimate named as a cause of a misfit band before the joint, when the clock alignment's
    residual exceeds the limit below which a phase is shown (:func:`analysis.verdict_limits.phase_is_meaningful`);
    "" otherwise.

    One phase current i_a gives the torque only through the electrical angle, i_q ∝ i_a / sin(θ_e + θ_0), so an error
    δ in that angle moves the estimate by δ·cot(θ_e + θ_0) — without bound where the motor holds torque at an angle
    at which i_a carries little of it, as a robot's pauses do. The angle stage's residual is how loosely the current's
    phase follows the encoder's angle. Measured on the simulated robot (configs/benches/sim_robot.toml, seeds 0 and 5,
    the trial's poor windows, residuals 107–315 µs): fed the true clock the estimate still read |H| at f_r 47 % low
    (the true torque: 0.6 %), the fit doubled C and missed f_a by +15…24 %; the same windows recorded with two
    phases (Park, no angle) were ok with the same clock errors. A second phase tells the estimate from the joint.
    The residual is evidence, not a bound: a window of seed 2 (at 420 s) with the same cause had 45 µs. Where the
    session's own coherence at the resonance says the estimate's error explains the whole misfit
    (:func:`analysis.misfit_band.missed_band`, :func:`estimate_explains`; that window among them) the reason names
    the estimate instead, without the joint's advice; this weaker doubt serves where it does not explain all of it."""
    if clock_residual_s is None or phase_is_meaningful(clock_residual_s, th):
        return ""
    return (f"the torque estimate from one phase current may bend |H| alike: the clock alignment's residual of "
            f"{1e6 * clock_residual_s:.0f} µs (above {1e6 * th.clock_residual_complex_s:.0f} µs) says that phase "
            "follows the encoder's electrical angle only loosely, and where the motor holds torque at an angle at "
            "which the phase carries little of it the estimate errs — record a second phase current ([daq] channels; "
            "Park needs no angle); if the misfit stays with two phases: ")


def estimate_explains(estimate: EstimateError, worst: BandMisfit, bins: tuple[tuple[float, float], ...]) -> str:
    """The one-phase torque estimate's own error named as what the misfit is (:func:`analysis.misfit_band.missed_band`),
    with its share of the torque at the resonance and what it leaves in the worst window, and the advice: a second
    phase."""
    f = np.array([b[0] for b in bins])
    there = float(np.mean(estimate.misfit[(f >= worst.low_hz) & (f <= worst.high_hz)]))
    return (f"the one-phase torque estimate's own error explains it: at the resonance it is "
            f"{100 * estimate.resonance_share:.0f} % of the torque's power (the coherence lost there, "
            f"{estimate.scale:.0f}× what white noise on i_a gives), which flattens |H|'s peak, and the fit bent to it "
            f"misses by {100 * there:+.1f} % there; less that, the model fits within noise — the motor holds or steps "
            f"its torque at electrical angles where i_a shows little of it: record a second phase current (i_b, [daq] "
            f"channels) for a Park torque, which needs no angle; until then K, J_m, J_l are the two-mass model's "
            f"compromise, not the joint's, and C reads high")


def misfit_cause(worst: BandMisfit, fit: FitResult) -> str:
    """What the worst window's misfit points to, by where it lies against the fit's anti-resonance and resonance:
    friction and backlash on the load side damp and bend the anti-resonance; a compliant or loose part adds a mode
    above the resonance; elsewhere any of them — or, with the inertias held at their nominal values, those values."""
    if not {"Jm_kgm2", "Jl_kgm2"} <= set(fit.fitted):
        return ("the inertias held at their nominal values may not be the joint's (fit them too: --params "
                "K,Jm,Jl), or " + _joint_cause(worst, fit))
    return _joint_cause(worst, fit)


def _joint_cause(worst: BandMisfit, fit: FitResult) -> str:
    """What in the joint a misfit points to, by where it lies (:func:`misfit_cause`)."""
    if worst.low_hz <= fit.f_a <= worst.high_hz:
        return (f"at the anti-resonance (f_a = {fit.f_a:.0f} Hz), which friction and backlash on the load side damp "
                "and bend: check the load side for friction and the gear and the coupling for play")
    if worst.low_hz > fit.f_r:
        return (f"above the resonance (f_r = {fit.f_r:.0f} Hz): a third mode — a compliant or loose part (the "
                "coupling, the arm, the tool or their mountings): check them")
    return ("a third mode, backlash or friction in the joint: check the gear and the coupling for play and for a loose "
            "part and the load side for friction")
