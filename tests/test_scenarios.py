"""A fast subset of the scenario family (bench/scenarios.py): one seed each, recorded through the real
recorder from the simulated drivers (``--fast``), analysed as ``acq analyze`` does. Each must be ``ok``
within its tolerance with the truth inside the intervals, or not ``ok`` at all: zero confident wrong.
Scenarios that today's analysis gets confidently wrong are strict xfails naming what is wrong, so they
flip when the analysis is fixed."""

from __future__ import annotations

from pathlib import Path

import pytest

from bench.scenarios import SCENARIOS, analyse, clock_for, confident_wrong, errors_pct, interval_holds, record

BY_NAME = {sc.name: (i, sc) for i, sc in enumerate(SCENARIOS)}


def _xfail(reason: str) -> pytest.MarkDecorator:
    return pytest.mark.xfail(strict=True, reason=reason)


CASES = [
    pytest.param("paper plant", 0),
    pytest.param("load friction Coulomb 0.3 + Stribeck 0.2 N·m", 0),
    pytest.param("third mass 800 Hz (above band), J_3 = 0.2 J_l", 0),
    pytest.param("DAQ 10 kS/s, no AA filter, ripple folds to 4 kHz", 0),
    pytest.param("encoder gap of 50 frames (with index)", 0),
    pytest.param("clock offset −2 s", 0),
    pytest.param("backlash 0.2 mrad", 0),
    pytest.param("third mass 150 Hz (inside band), J_3 = 0.5 J_l", 0, marks=_xfail(
        "third mode in the band: K −3.8 %, J_l +49 % (vs J_l alone) under an ok verdict; its +7…+8 % dipole of |H| at "
        "170–184 Hz is within what the 2^17 counts/rev encoder's quantisation, repeating with the motion, can do per "
        "bin there (5 %): the misfit test sees it at 3.2–3.6 σ, critical 4.3 (with 2^20 counts/rev it is named)")),
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
    if sc.must_not_be_ok and "misfit" in sc.reason:  # declined for the right reason, naming where
        assert any(r.startswith("the two-mass model does not fit |H| between") for r in res.quality.reasons), \
            res.quality.reasons
    if sc.expect == "ok" and res.quality.verdict == "ok":
        assert abs(res.clock.offset_s - truth["daq_offset_s"]) < 50e-6
