"""A robot window whose misfit came from the one-phase torque estimate, not the joint (the trial's 11 of 112 poor
windows of configs/benches/sim_robot.toml, which has no friction, backlash or third mass): the motor holds and then
steps its torque at an electrical angle where i_a shows little of it (7.3–7.8 s of the window: |sin| 0.06, then a
step at |sin| 0.014, where the estimate missed the 4 N·m step by 5 N·m). Of the segments the selection keeps (the
robot moves on its own), those where the estimate's own error is an outlying share of the torque are left out, and
the window is ok with the truth inside its intervals (on the code before: poor, |H| +15.9 % at 42…56 Hz, C ×2) —
C's too, though C still reads high: its interval allows for the estimate's remaining error; the same window recorded
with two phases (Park, no angle) is ok as well.

Session 13: the windows of seed 2 at 420 and 540 s, whose misfit the one-phase estimate's error explained, were poor
through their clock (drift 27 and 82 ppm, truth 40): aligned with the host stamps' drift they read as with the
simulator's true clock (tests/test_clock_drift_prior.py), and no window of seeds 0–6 × 60…600 s is poor any more."""

from __future__ import annotations

from pathlib import Path

import pytest

from acq.config import load_bench
from acq.offline.analyze import analyze_session
from acq.recording.recorder import Recorder
from drivers.registry import open_bench

ROBOT = Path(__file__).resolve().parents[1] / "configs" / "benches" / "sim_robot.toml"
WINDOW_S, ELAPSED_S = 10.0, 180.0  # the monitor's fourth window (--window 10 --every 60), seed 0


def recorded_window(tmp_path: Path, channels: list[str], seed: int = 0, elapsed_s: float = ELAPSED_S,
                    window_s: float = WINDOW_S) -> Path:
    """A passive ``window_s`` recording of sim_robot.toml (``seed``, the robot program ``elapsed_s`` into its shift),
    recorded as ``acq record --fast`` does: its session file."""
    bench = load_bench(ROBOT)
    bench = bench.model_copy(update={"sim": bench.sim.model_copy(update={"elapsed_s": elapsed_s, "seed": seed}),
                                     "daq": bench.daq.model_copy(update={"channels": channels})})
    current, drive = open_bench(bench, fast=True)
    return Recorder(bench, None, current, drive, tmp_path, window_s).run().path


def _window(tmp_path: Path, channels: list[str], seed: int = 0, elapsed_s: float = ELAPSED_S) -> dict:
    return analyze_session(recorded_window(tmp_path, channels, seed, elapsed_s), write=False).json_dict


def test_segments_where_one_phase_does_not_show_the_torque_are_left_out_and_the_window_is_ok(tmp_path: Path) -> None:
    doc = _window(tmp_path / "one", ["i_a"])
    # session 13: the drift the host stamps give (43.5 ppm; the angle stage's 14 stretches of motion had read 13.5,
    # truth 40) aligns the phase to 132.5 µs (162.4 µs before): the clock's part of the misfit is gone, and of the
    # segments left out (4.81–5.31, 7.06–7.56, 7.31–7.81 s before) only the hold and step at 7.3–7.8 s remains
    assert doc["clock"]["residual_s"] == pytest.approx(132.5e-6, abs=1e-6)
    notes = [r for r in doc["quality"]["reasons"] if r.startswith("note: torque: ")]
    assert notes == ["note: torque: 1 of 38 Welch segments left out (7.06–7.56 s): there the one-phase estimate's own "
                     "error is an outlying share of the torque — the motor holds or changes its torque at an electrical "
                     "angle where i_a shows little of it"]
    assert doc["quality"]["verdict"] == "ok", doc["quality"]["reasons"]
    exc = doc["excitation"]  # the segments that excite, and those averaged: less the one left out
    assert (exc["segments"], exc["segments_used"], exc["segments_averaged"]) == (38, 33, 32)
    truth = doc["simulated_truth"]
    assert doc["K_Nm_per_rad"] == pytest.approx(truth["K_Nm_per_rad"], rel=0.01)  # 890.6 against 891 (before 893.8)
    for p in ("K_Nm_per_rad", "Jm_kgm2", "Jl_kgm2", "C_Nms_per_rad"):
        assert doc["ci95"][p][0] <= truth[p] <= doc["ci95"][p][1], p
    # the damping from one phase: 0.108 [0.091, 0.128] against 0.1 — it read 0.171 [0.087, 0.337] with the drift
    # 27 ppm off, whose misalignment was the noise on the FRF's input that flattened the resonance's peak
    assert doc["C_Nms_per_rad"] == pytest.approx(truth["C_Nms_per_rad"], rel=0.15)
    assert not any(r.startswith("note: C's") for r in doc["quality"]["reasons"])
    two = _window(tmp_path / "two", ["i_a", "i_b"])
    assert two["clock"]["offset_s"] == pytest.approx(doc["clock"]["offset_s"], abs=5e-6)  # the same clock
    assert not any(r.startswith("note: torque: ") for r in two["quality"]["reasons"])  # Park needs no such care
    assert two["quality"]["verdict"] == "ok", two["quality"]["reasons"]
    assert two["C_Nms_per_rad"] == pytest.approx(truth["C_Nms_per_rad"], rel=0.15)
    assert two["ci95"]["C_Nms_per_rad"][0] <= truth["C_Nms_per_rad"] <= two["ci95"]["C_Nms_per_rad"][1]  # ±15 %
    assert two["ci95"]["K_Nm_per_rad"][0] <= truth["K_Nm_per_rad"] <= two["ci95"]["K_Nm_per_rad"][1]


def test_the_one_phase_estimates_noise_sets_the_floor_of_the_misfit_tests_scatter_no_false_third_mode(
        tmp_path: Path) -> None:
    # the monitor's healthy window of seed 0 at 160 s (no third mass in the simulator): the one-phase estimate's error
    # leaves |H| 3.2 % below the model at 178…192 Hz in every block (+0.5 % with two phases), and the jackknife of that
    # window read 0.49 % — less than the 0.71 % the estimate's modelled noise alone gives its mean with the 27 segments
    # averaged — so the misfit passed as "a third mode … check the coupling, the arm, the tool" (t 4.5, level 4.3)
    done = analyze_session(recorded_window(tmp_path, ["i_a"], seed=0, elapsed_s=160.0), write=False)
    doc, quality = done.json_dict, done.result.quality
    assert doc["quality"]["verdict"] == "ok", doc["quality"]["reasons"]
    truth = doc["simulated_truth"]
    for p in ("K_Nm_per_rad", "Jm_kgm2", "Jl_kgm2", "C_Nms_per_rad"):
        assert doc["ci95"][p][0] <= truth[p] <= doc["ci95"][p][1], p
    window = next(w for w in quality.misfit_windows if w[:2] == (178.0, 192.0))
    assert window[2] == pytest.approx(0.0324, abs=5e-4)  # the misfit, as before
    # its allowance, bound + t·√(scatter² + systematic²): 0.63 % + 4.27 × √(0.71² + 0.30²) % (main: 0.49 % → 3.1 %)
    assert window[3] == pytest.approx(0.039, abs=1e-3)
