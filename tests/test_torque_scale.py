"""A torque read at the wrong scale (a wrong k_t or current-sensor gain) scales K, J_m, J_l and C alike, so the data
alone hold together and the verdict was ``ok``; a bench that knows its inertia (``[nominal] inertia_known``) shows it:
the fitted J_m + J_l against the stated one (:func:`analysis.diagnose.inertia_fault`). Real ``--fast`` recordings of
the simulated bench with its ``[sim] current_sensor_gain``, analysed as ``acq analyze`` does."""

from __future__ import annotations

import re
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from acq.config import DEFAULT_BENCH
from acq.offline.analyze import SessionResult, analyze_session, recording_from_session, request_for
from acq.recording.reader import load
from analysis.diagnose import inertia_fault
from tests.helpers import run_cli, seeded_profile
from tests.test_selftest import INERTIA_KNOWN

GAIN_125 = re.compile(r"J_m \+ J_l is 1\.2[4-6]× \[nominal\] Jm_kgm2 \+ Jl_kgm2 = 0\.01051 kg·m² \(95 % interval "
                      r"1\.2\d–1\.2\d×, \[nominal\] inertia_tolerance ±15 %\): the torque's scale — \[motor\] "
                      r"torque_constant_Nm_per_A or the current sensor's gain — is off by that factor; K, J_m, J_l, C "
                      r"all carry it — unless \[nominal\] Jm_kgm2 \+ Jl_kgm2 miss part of the joint's inertia")


def recorded(capsys: pytest.CaptureFixture[str], folder: Path, gain: float, *, inertia_known: bool = True) -> Path:
    """A 10 s ``acq record --fast`` (dither seed 0) of the shipped simulated bench whose current sensor reads ``gain``×
    the current; ``inertia_known=False``: the bench without its ``[nominal] inertia_known = true``."""
    folder.mkdir()
    text = DEFAULT_BENCH.read_text()
    if not inertia_known:
        text = text.replace(INERTIA_KNOWN, "", 1)
    bench = folder / "bench.toml"
    bench.write_text(text + f"\ncurrent_sensor_gain = {gain}\n")  # [sim] is the bench's last table
    run = run_cli(capsys, "record", "--profile", str(seeded_profile(folder)), "--bench", str(bench), "--fast",
                  "--duration", "10", "--no-analyze", "--out", str(folder / "s"))
    assert run.code == 0, run.err
    (path,) = (folder / "s").glob("*.h5")
    return path


def analysed(path: Path) -> SessionResult:
    return analyze_session(path, write=False)


def test_a_current_read_25_percent_high_is_poor_naming_the_torque_scale(capsys: pytest.CaptureFixture[str],
                                                                        tmp_path: Path) -> None:
    done = analysed(recorded(capsys, tmp_path / "g", 1.25))
    quality, fit = done.json_dict["quality"], done.result.fit
    assert fit.values.K_Nm_per_rad / 891.0 == pytest.approx(1.25, abs=0.02)  # before: this K and verdict ok
    assert quality["verdict"] == "poor"
    assert GAIN_125.fullmatch(quality["reasons"][0]), quality["reasons"][0]
    # a finding of the fit, not a fault found in the data whatever the motion (quality.faults: a window that did not
    # excite the joint stays "not excited" whatever its junk fit reads)
    assert quality["faults"] == []
    assert done.json_dict["options"]["inertia_tolerance"] == 0.15


def test_a_correct_current_and_a_bench_without_a_known_inertia_are_not_flagged(capsys: pytest.CaptureFixture[str],
                                                                               tmp_path: Path) -> None:
    right = analysed(recorded(capsys, tmp_path / "right", 1.0))
    assert right.json_dict["quality"]["verdict"] == "ok", right.json_dict["quality"]["reasons"]
    assert right.result.fit.values.K_Nm_per_rad == pytest.approx(891.0, rel=0.02)
    unknown = analysed(recorded(capsys, tmp_path / "unknown", 1.25, inertia_known=False))
    assert unknown.json_dict["options"]["inertia_tolerance"] is None
    assert unknown.json_dict["quality"]["verdict"] == "ok"  # nothing to hold the scale against: K 1.25× passes
    assert not any("J_m + J_l is" in r for r in unknown.json_dict["quality"]["reasons"])


def test_an_interval_reaching_into_the_tolerance_band_is_no_evidence(capsys: pytest.CaptureFixture[str],
                                                                     tmp_path: Path) -> None:
    """The 1.25× fit of a real recording, its covariance widened until the 95 % interval of J_m + J_l reaches 1.15×
    nominal: no flag; a tolerance of 0.3 takes in the 1.25× itself: no flag either."""
    session = load(recorded(capsys, tmp_path / "g", 1.25))
    request = request_for(session)
    from analysis import analyze

    fit = analyze(recording_from_session(session), request).fit
    nominal = request.nominal
    assert GAIN_125.fullmatch(inertia_fault(fit, nominal, 0.15) or "")
    assert inertia_fault(fit, nominal, 0.3) is None
    assert inertia_fault(fit, nominal, None) is None
    total = fit.values.Jm_kgm2 + fit.values.Jl_kgm2
    reach = np.log(total / (1.15 * (nominal.Jm_kgm2 + nominal.Jl_kgm2)))  # ln of the sum down to the band's edge
    i = [fit.fitted.index(n) for n in ("Jm_kgm2", "Jl_kgm2")]
    grad = np.array([fit.values.Jm_kgm2, fit.values.Jl_kgm2]) / total  # d ln(J_m + J_l) / d(ln J_m, ln J_l)
    sigma = float(np.sqrt(grad @ fit.covariance[np.ix_(i, i)] @ grad))
    assert 1.96 * sigma < reach / 5.0  # as fitted: the interval a fifth of the way to the band or less
    wide = reach / 1.96 / sigma * 1.01
    assert inertia_fault(replace(fit, covariance=fit.covariance * wide**2), nominal, 0.15) is None
    assert inertia_fault(replace(fit, covariance=fit.covariance * (wide / 1.02)**2), nominal, 0.15) is not None
