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


def _window(tmp_path: Path, channels: list[str]) -> dict:
    bench = load_bench(ROBOT)
    bench = bench.model_copy(update={"sim": bench.sim.model_copy(update={"elapsed_s": ELAPSED_S}),
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
    two = _window(tmp_path / "two", ["i_a", "i_b"])
    assert two["clock"]["offset_s"] == pytest.approx(doc["clock"]["offset_s"], abs=5e-6)  # the same clock error
    assert not any(r.startswith("note: torque: ") for r in two["quality"]["reasons"])  # Park needs no such care
    assert two["quality"]["verdict"] == "ok", two["quality"]["reasons"]
    assert two["C_Nms_per_rad"] == pytest.approx(truth["C_Nms_per_rad"], rel=0.15)
    assert two["ci95"]["C_Nms_per_rad"][0] <= truth["C_Nms_per_rad"] <= two["ci95"]["C_Nms_per_rad"][1]  # ±15 %
    assert two["ci95"]["K_Nm_per_rad"][0] <= truth["K_Nm_per_rad"] <= two["ci95"]["K_Nm_per_rad"][1]
