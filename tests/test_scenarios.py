"""A fast subset of the scenario family (bench/scenarios.py): one seed each, recorded through the real
recorder from the simulated drivers (``--fast``), analysed as ``acq analyze`` does. Each must be ``ok``
within its tolerance with the truth inside the intervals, or not ``ok`` at all: zero confident wrong.
A scenario declined for a misfit must name the band."""

from __future__ import annotations

from pathlib import Path

import pytest

from bench.scenarios import SCENARIOS, analyse, clock_for, confident_wrong, errors_pct, interval_holds, record

BY_NAME = {sc.name: (i, sc) for i, sc in enumerate(SCENARIOS)}


CASES = [
    pytest.param("paper plant", 0),
    pytest.param("load friction Coulomb 0.3 + Stribeck 0.2 N·m", 0),
    pytest.param("third mass 800 Hz (above band), J_3 = 0.2 J_l", 0),
    pytest.param("DAQ 10 kS/s, no AA filter, ripple folds to 4 kHz", 0),
    pytest.param("encoder gap of 50 frames (with index)", 0),
    pytest.param("clock offset −2 s", 0),
    pytest.param("backlash 0.2 mrad", 0),
    # declined since the profile dithers the motion (the quantisation error no longer repeats with it): the misfit
    # is named at 162…192 Hz
    pytest.param("third mass 150 Hz (inside band), J_3 = 0.5 J_l", 0),
    pytest.param("backlash 0.05 mrad", 0),
    # the fit's model of the Welch estimator is +4.5…+6 % off at this plant's anti-resonance (estimator_check)
    pytest.param("J_m ×0.5, J_l ×2", 0),
    # the speed loop's feedback of the quantisation noise biases |H| by up to q² near 450 Hz (systematic_std)
    pytest.param("encoder 4 kHz", 0),
    pytest.param("third mass 150 Hz (inside band), encoder 2^20 counts/rev", 0),
    pytest.param("offset drift 40 mA, 20 s period", 1),
    pytest.param("mains hum 20 mA, 50 Hz + harmonics", 4),
    pytest.param("3 phases, gain errors +2 % / −2 % (park)", 0),
]


@pytest.mark.parametrize(("name", "seed"), CASES)
def test_scenario_is_ok_within_tolerance_or_not_ok(name: str, seed: int, tmp_path: Path) -> None:
    index, sc = BY_NAME[name]
    offset_s, drift_ppm = sc.clock if sc.clock is not None else clock_for(seed, index)
    path, truth = record(sc, seed, offset_s, drift_ppm, tmp_path)
    res = analyse(path)
    err = errors_pct(res, truth)
    wrong = confident_wrong(sc, res.quality.verdict, err, interval_holds(res, truth))
    assert not wrong, f"{name} seed {seed}: verdict ok but " + "; ".join(wrong)
    if sc.must_not_be_ok and "misfit" in sc.reason:  # declined for the right reason, naming where: the window test
        # or the mode test (with one phase the window test allows H1's input-noise bias, −ln γ², and the third mass's
        # windows lie within it: the mode test names it near 186 Hz at 9.7 σ, seed 0)
        assert any(r.startswith(("the two-mass model does not fit |H| between",
                                 "the two-mass model misses a third mode near")) for r in res.quality.reasons), \
            res.quality.reasons
    if sc.expect == "ok" and res.quality.verdict == "ok":
        assert abs(res.clock.offset_s - truth["daq_offset_s"]) < 50e-6


@pytest.mark.parametrize(("name", "cause"), [
    ("third mass 150 Hz (inside band), J_3 = 0.5 J_l",  # named by the mode test (one phase: see above)
     "— a compliant or loose part (the coupling, the arm, the tool or their mountings): check them; until then"),
    ("backlash 0.2 mrad", "at the anti-resonance (f_a = "),
    # one phase, like the robot windows whose misfit at f_a is the estimate's own error (test_one_phase_doubt): the
    # friction's misfit there has the other sign (−7.6 %), so the estimate's error (s = 3.2) does not explain it
    ("load friction Coulomb 0.3 + Stribeck 0.2 N·m", "at the anti-resonance (f_a = 55 Hz), which friction and "
     "backlash on the load side damp and bend: check the load side for friction"),
])
def test_a_misfit_names_what_its_place_points_to(name: str, cause: str, tmp_path: Path) -> None:
    index, sc = BY_NAME[name]
    path, _ = record(sc, 0, *clock_for(0, index), tmp_path)
    misfit = next(r for r in analyse(path).quality.reasons
                  if r.startswith(("the two-mass model does not fit", "the two-mass model misses a third mode")))
    assert cause in misfit, misfit


def test_a_fit_whose_jackknife_diverges_says_its_parameters_are_not_determined(tmp_path: Path) -> None:
    """The paper's chain on "trapezoid: 0.1 s cruise, 0.1 s dwell", seed 2 (bench/accuracy.py): a delete-one-block
    refit diverges, so the covariance is infinite and the intervals 0…∞. The misfit test's model spread beyond the
    fitted band multiplied that covariance by the fitted bins' zero rows (0·∞: "invalid value encountered in
    matmul"), and the reasons read "K is known only to ±inf % (95 %)" three times, C's not at all."""
    import warnings

    index, sc = BY_NAME["trapezoid: 0.1 s cruise, 0.1 s dwell"]
    path, truth = record(sc, 2, *clock_for(2, index), tmp_path)
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        res = analyse(path, pipeline="paper")
    assert res.fit.ci95["K_Nm_per_rad"] == (0.0, float("inf"))  # undetermined, not a finite interval
    assert res.quality.verdict == "failed"
    assert "K, J_m, J_l and C are not determined (95 % interval up to infinity): a refit on part of the data — the " \
           "record less one block (the jackknife behind the intervals) or the resonance read from H2 — diverged, so " \
           "the fit is not stable under the data" in res.quality.reasons
    assert not any("±inf" in r for r in res.quality.reasons)
    assert abs(errors_pct(res, truth)["K_Nm_per_rad"]) > 100  # K 3771, truth 891: a number only a failed verdict shows
