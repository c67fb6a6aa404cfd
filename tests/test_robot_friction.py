"""Robot windows with friction in the joint (configs/benches/sim_robot.toml, one phase i_a, Coulomb 0.3 N·m + Stribeck 0.2
N·m — the accuracy family's friction law): acq must not give a confident wrong result, verdict ``ok`` with the truth
outside a 95 % interval.

On the load side (seed 5 at 300 s; measured on main at 6edb9f7) it did: ok, J_l 0.007396 [0.007316, 0.007476] against
0.00748. Since the intervals hold the fit with b_v free too (analysis.fit, session 14) J_l's interval holds the truth by
a hair — J_l 0.007390 [0.007296, 0.007485] — the bias itself unchanged. The friction's torque, correlated with the motion, lifts |H| by 0.5–5 % at 10–52 Hz — bins the
fit trusts (weights 22–88) — which reads J_l 1.1 % low and C 19 % high; the misfit test sees the anti-resonance's −4.8 %
against its 12.6 % limit (the jackknife's scatter there grows with the friction), the misfit's HAC share of J_l's
interval (±0.40 %) stays under the quantisation floor (±0.56 %), and the jackknife (±0.92 %) cannot show a bias every
block shares. bench/friction_robot.py counts such windows.

On the motor side, the reducer's input (seed 1 at 540 s), it did until the fit was made again with the motor-side
damping of the vibration b_v free beside C, and the intervals widened to hold that fit's (analysis.fit): before, ok, C
0.1390 [0.1166, 0.1657] against 0.1 (the same window without the friction: 0.0941 [0.0849, 0.1043]). The friction
damps the resonance — |H| at 98–106 Hz 28 % lower than without it, at f_a (52–58 Hz) 0.9 % higher — and with C the
model's one damping, C took it. bench/effects_robot.py counts such windows."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from acq.config import load_bench
from acq.offline.analyze import analyze_session
from acq.recording.recorder import Recorder
from drivers.registry import open_bench

ROBOT = Path(__file__).resolve().parents[1] / "configs" / "benches" / "sim_robot.toml"
PARAMS = ("K_Nm_per_rad", "Jm_kgm2", "Jl_kgm2", "C_Nms_per_rad")
LOAD = {"elapsed_s": 300.0, "seed": 5, "load_coulomb_Nm": 0.3, "load_stribeck_Nm": 0.2}
MOTOR = {"elapsed_s": 540.0, "seed": 1, "motor_coulomb_Nm": 0.3, "motor_stribeck_Nm": 0.2}


def _window(sim: dict[str, Any], folder: Path) -> dict[str, Any]:
    """The ``--json`` result of one 10 s window of the robot, i_a only, with the ``[sim]`` values ``sim``."""
    bench = load_bench(ROBOT)
    bench = bench.model_copy(update={"sim": bench.sim.model_copy(update=sim),
                                     "daq": bench.daq.model_copy(update={"channels": ["i_a"]})})
    current, drive = open_bench(bench, fast=True)
    return analyze_session(Recorder(bench, None, current, drive, folder, 10.0).run().path, write=False).json_dict


def test_load_friction_on_the_robot_is_not_a_confident_wrong_result(tmp_path: Path) -> None:
    """Measured at session 14: ok, J_l 0.007390 [0.007296, 0.007485] (truth 0.00748: 0.07 % inside the upper end), K 887.2
    [877.6, 896.9], C 0.115 [0.074, 0.179]; b_v −0.033 [−0.077, 0.012] N·m·s/rad. Since session 15 the excess incoherence
    floor (analysis/excess_incoherence.py) tops J_l's interval up to −7.3…+5.3 % around −1.20 % (10–40 and 74–88 Hz
    stand out of the replicates' scatter), still ok."""
    doc = _window(LOAD, tmp_path)
    truth = doc["simulated_truth"]
    outside = [p for p in PARAMS if not doc["ci95"][p][0] <= truth[p] <= doc["ci95"][p][1]]
    if doc["quality"]["verdict"] == "ok":
        assert outside == [], {p: (doc[p], doc["ci95"][p], truth[p]) for p in outside}
    else:  # not ok: then for the friction's reason
        assert any("friction" in r for r in doc["quality"]["reasons"]), doc["quality"]["reasons"]


def test_motor_friction_on_the_robot_is_held_by_cs_interval_and_read_as_b_v(tmp_path: Path) -> None:
    """C alone still reads the friction's damping (the values and the verdict are C alone's), but C's interval now holds
    the anti-resonance's reading too, and with it the truth; the resonance's extra damping is b_v's.

    Measured: ok, C 0.1390 [0.0773, 0.2499] (C alone's interval [0.1166, 0.1657]; the fit with b_v: C 0.105), b_v 0.052
    [−0.011, 0.115] N·m·s/rad, K, J_m, J_l within 0.3 % and their intervals holding the truth."""
    doc = _window(MOTOR, tmp_path)
    truth, ci = doc["simulated_truth"], doc["ci95"]
    assert doc["quality"]["verdict"] == "ok", doc["quality"]["reasons"]
    assert {p: ci[p][0] <= truth[p] <= ci[p][1] for p in PARAMS} == dict.fromkeys(PARAMS, True), (
        {p: (doc[p], ci[p], truth[p]) for p in PARAMS})
    assert doc["C_Nms_per_rad"] == pytest.approx(0.1390, rel=0.02)  # C alone's value, as before
    assert ci["C_Nms_per_rad"][0] < 0.9 * truth["C_Nms_per_rad"] and ci["C_Nms_per_rad"][1] > 0.2
    # the damping that C alone took, (J_m+J_l)/J_l·(0.1390 − 0.1) = 0.055 N·m·s/rad, is b_v's reading
    taken = (truth["Jm_kgm2"] + truth["Jl_kgm2"]) / truth["Jl_kgm2"] * (0.1390 - truth["C_Nms_per_rad"])
    assert ci["bv_Nms_per_rad"][0] < taken < ci["bv_Nms_per_rad"][1], (doc["bv_Nms_per_rad"], ci["bv_Nms_per_rad"])
    assert doc["bv_Nms_per_rad"] == pytest.approx(taken, rel=0.25)


MOTOR_TWICE = {"elapsed_s": 300.0, "seed": 2, "motor_coulomb_Nm": 0.6, "motor_stribeck_Nm": 0.4}


def test_twice_the_motor_friction_is_not_a_confident_wrong_result(tmp_path: Path) -> None:
    """Seed 2 at 300 s with twice the motor friction: the model lies above |H| where the friction also costs coherence.
    A window test that forgave a one-phase estimate −ln γ² of the coherence there (session 15, reverted after an
    independent review) called it ok with C 0.165 [0.106, 0.256] against 0.1 (also with the excess-incoherence floor);
    the misfit must keep it from ``ok`` unless every interval holds the truth."""
    doc = _window(MOTOR_TWICE, tmp_path)
    truth = doc["simulated_truth"]
    outside = [p for p in PARAMS if not doc["ci95"][p][0] <= truth[p] <= doc["ci95"][p][1]]
    if doc["quality"]["verdict"] == "ok":
        assert outside == [], {p: (doc[p], doc["ci95"][p], truth[p]) for p in outside}
