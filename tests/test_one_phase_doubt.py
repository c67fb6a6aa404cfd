"""A robot window whose misfit came from the one-phase torque estimate, not the joint (the trial's 11 of 112 poor
windows of configs/benches/sim_robot.toml, which has no friction, backlash or third mass): the motor holds and then
steps its torque at an electrical angle where i_a shows little of it (7.3–7.8 s of the window: |sin| 0.06, then a
step at |sin| 0.014, where the estimate missed the 4 N·m step by 5 N·m). Of the segments the selection keeps (the
robot moves on its own), those where the estimate's own error is an outlying share of the torque are left out, and
the window is ok with the truth inside its intervals (on the code before: poor, |H| +15.9 % at 42…56 Hz, C ×2) —
C's too, though C still reads high: its interval allows for the estimate's remaining error; the same window recorded
with two phases (Park, no angle) is ok as well."""

from __future__ import annotations

from pathlib import Path

import pytest

from acq.config import load_bench
from acq.offline.analyze import analyze_session
from acq.recording.recorder import Recorder
from drivers.registry import open_bench

ROBOT = Path(__file__).resolve().parents[1] / "configs" / "benches" / "sim_robot.toml"
WINDOW_S, ELAPSED_S = 10.0, 180.0  # the monitor's fourth window (--window 10 --every 60), seed 0


def _window(tmp_path: Path, channels: list[str], seed: int = 0, elapsed_s: float = ELAPSED_S) -> dict:
    bench = load_bench(ROBOT)
    bench = bench.model_copy(update={"sim": bench.sim.model_copy(update={"elapsed_s": elapsed_s, "seed": seed}),
                                     "daq": bench.daq.model_copy(update={"channels": channels})})
    current, drive = open_bench(bench, fast=True)
    path = Recorder(bench, None, current, drive, tmp_path, WINDOW_S).run().path
    return analyze_session(path, write=False).json_dict


def test_segments_where_one_phase_does_not_show_the_torque_are_left_out_and_the_window_is_ok(tmp_path: Path) -> None:
    doc = _window(tmp_path / "one", ["i_a"])
    assert doc["clock"]["residual_s"] == pytest.approx(162.4e-6, abs=1e-6)  # the same loosely aligned phase as before
    notes = [r for r in doc["quality"]["reasons"] if r.startswith("note: torque: ")]
    assert notes == ["note: torque: 3 of 38 Welch segments left out (4.81–5.31 s, 7.06–7.56 s, 7.31–7.81 s): there the "
                     "one-phase estimate's own error is an outlying share of the torque — the motor holds or changes "
                     "its torque at an electrical angle where i_a shows little of it"]
    assert doc["quality"]["verdict"] == "ok", doc["quality"]["reasons"]
    exc = doc["excitation"]  # the segments that excite, and those averaged: less the 3 left out
    assert (exc["segments"], exc["segments_used"], exc["segments_averaged"]) == (38, 33, 30)
    truth = doc["simulated_truth"]
    assert doc["K_Nm_per_rad"] == pytest.approx(truth["K_Nm_per_rad"], rel=0.01)  # 893.8 against 891 (before 896.4)
    for p in ("K_Nm_per_rad", "Jm_kgm2", "Jl_kgm2"):
        assert doc["ci95"][p][0] <= truth[p] <= doc["ci95"][p][1], p
    # the damping is still read high from one phase (0.171 against 0.1; before 0.197): the estimate's error in the
    # segments kept is noise on the FRF's input, which lowers the resonance's peak (H1 by γ²: the true torque gives
    # 0.108) — but C's interval now holds the H2 reading of the resonance (0.105) and the truth: [0.087, 0.337],
    # where it was [0.109, 0.267] (analysis.input_noise)
    c, (c_low, c_high) = doc["C_Nms_per_rad"], doc["ci95"]["C_Nms_per_rad"]
    assert 1.5 * truth["C_Nms_per_rad"] < c < 1.8 * truth["C_Nms_per_rad"]
    assert c_low < 0.9 * truth["C_Nms_per_rad"] and c_high > truth["C_Nms_per_rad"]
    assert c_high / c_low < 4.5  # ×3.9: wide, as the data leave it, not unbounded
    assert [r for r in doc["quality"]["reasons"] if r.startswith("note: C's")] == [  # and a note says why
        "note: C's interval [0.0866, 0.337] N·m·s/rad allows for an error on the torque estimate (noise, hum, the "
        "one-phase estimate's own error): at the resonance (102 Hz) the coherence lost is 27.8 %, of which the Welch "
        "window's own spreading of the peak takes 2.3 %; the rest is noise on the torque, which flattens H1's peak and "
        "reads C high — from H2 = H1/γ² there C is 0.108 (-37 %), and the truth lies between the two readings; "
        "without that allowance the interval would be [0.109, 0.267], 1.5× narrower on a log scale"]
    two = _window(tmp_path / "two", ["i_a", "i_b"])
    assert two["clock"]["offset_s"] == pytest.approx(doc["clock"]["offset_s"], abs=5e-6)  # the same clock error
    assert not any(r.startswith("note: torque: ") for r in two["quality"]["reasons"])  # Park needs no such care
    assert two["quality"]["verdict"] == "ok", two["quality"]["reasons"]
    assert two["C_Nms_per_rad"] == pytest.approx(truth["C_Nms_per_rad"], rel=0.15)
    assert two["ci95"]["C_Nms_per_rad"][0] <= truth["C_Nms_per_rad"] <= two["ci95"]["C_Nms_per_rad"][1]  # ±15 %
    assert two["ci95"]["K_Nm_per_rad"][0] <= truth["K_Nm_per_rad"] <= two["ci95"]["K_Nm_per_rad"][1]


@pytest.mark.parametrize(("elapsed_s", "misfit", "scale", "share", "there"), [
    # clock residual 45 µs: below the limit at which the residual alone named the estimate (the window kept the
    # joint's advice alone: "check the load side for friction")
    (420.0, "between 50 and 64 Hz: it misses by +19.3 % at 50…64 Hz, 5 σ", 13, 27, "+9.9"),
    (540.0, "between 42 and 64 Hz: it misses by +25.3 % at 42…56 Hz, 11 σ", 31, 43, "+15.3"),
])
def test_a_misfit_the_one_phase_estimate_explains_names_it_not_the_joint(
        tmp_path: Path, elapsed_s: float, misfit: str, scale: int, share: int, there: str) -> None:
    """Two windows of seed 2 (the bench has no friction, backlash or third mass) whose one-phase estimate errs at the
    resonance 13× and 31× its white-noise model (the coherence lost there): the fit, bending to the flattened peak,
    misses at the anti-resonance. Less what that error leaves after the fit (its share of the torque from the
    coherence, carried through the fit) no window is missed, so the reason names the estimate and asks for a second
    phase — still poor: the parameters are the compromise, C reads twice the truth — where it blamed the joint."""
    doc = _window(tmp_path, ["i_a"], seed=2, elapsed_s=elapsed_s)
    assert doc["quality"]["verdict"] == "poor"
    reason = doc["quality"]["reasons"][0]
    assert reason == (
        f"the two-mass model does not fit |H| {misfit} beyond what noise, the chain and the encoder's quantisation "
        f"explain — the one-phase torque estimate's own error explains it: at the resonance it is {share} % of the "
        f"torque's power (the coherence lost there, {scale}× what white noise on i_a gives), which flattens |H|'s peak, "
        f"and the fit bent to it misses by {there} % there; less that, the model fits within noise — the motor holds "
        "or steps its torque at electrical angles where i_a shows little of it: record a second phase current (i_b, "
        "[daq] channels) for a Park torque, which needs no angle; until then K, J_m, J_l are the two-mass model's "
        "compromise, not the joint's, and C reads high")
    assert not any("friction" in r for r in doc["quality"]["reasons"])
    truth = doc["simulated_truth"]
    for p in ("K_Nm_per_rad", "Jm_kgm2", "Jl_kgm2", "C_Nms_per_rad"):
        assert doc["ci95"][p][0] <= truth[p] <= doc["ci95"][p][1], p
    assert doc["C_Nms_per_rad"] > 2.0 * truth["C_Nms_per_rad"]  # 0.203 and 0.225 against 0.1
