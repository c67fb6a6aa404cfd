"""Robot windows with friction in the joint (configs/benches/sim_robot.toml, one phase i_a, Coulomb 0.3 N·m + Stribeck 0.2
N·m — the accuracy family's friction law): acq must not give a confident wrong result, verdict ``ok`` with the truth
outside a 95 % interval. It does, on either side of the joint (the defects these tests pin, each a strict xfail).

On the load side (seed 5 at 300 s; measured on main at 6edb9f7): ok, J_l 0.007396 [0.007316, 0.007476] against 0.00748.
The friction's torque, correlated with the motion, lifts |H| by 0.5–5 % at 10–52 Hz — bins the fit trusts (weights
22–88) — which reads J_l 1.1 % low and C 19 % high; the misfit test sees the anti-resonance's −4.8 % against its 12.6 %
limit (the jackknife's scatter there grows with the friction), the misfit's HAC share of J_l's interval (±0.40 %) stays
under the quantisation floor (±0.56 %), and the jackknife (±0.92 %) cannot show a bias every block shares.
bench/friction_robot.py counts such windows.

On the motor side, the reducer's input (seed 1 at 540 s; measured at 8cc3595, analysis/ as on main 3d6370f): ok, C
0.1390 [0.1166, 0.1657] against 0.1 (the same window without it: 0.0941 [0.0849, 0.1043]); K, J_m, J_l move by ≤ 0.2 %
and keep the truth. The friction damps the resonance — |H| at 98–106 Hz 28 % lower than without it, at f_a (52–58 Hz)
0.9 % higher — and the two-mass model's one damping, C in the shaft, takes it: the fit's compromise leaves the model
+6.0 % above |H| at 50–64 Hz and +6.3 % at 90–104 Hz, against the misfit test's allowances of 6.1 % and 6.5 % there
(ratio 0.98 each). bench/effects_robot.py counts such windows."""

from __future__ import annotations

from pathlib import Path

import pytest

from acq.config import load_bench
from acq.offline.analyze import analyze_session
from acq.recording.recorder import Recorder
from drivers.registry import open_bench

ROBOT = Path(__file__).resolve().parents[1] / "configs" / "benches" / "sim_robot.toml"
PARAMS = ("K_Nm_per_rad", "Jm_kgm2", "Jl_kgm2", "C_Nms_per_rad")
LOAD = {"elapsed_s": 300.0, "seed": 5, "load_coulomb_Nm": 0.3, "load_stribeck_Nm": 0.2}
MOTOR = {"elapsed_s": 540.0, "seed": 1, "motor_coulomb_Nm": 0.3, "motor_stribeck_Nm": 0.2}


@pytest.mark.parametrize("sim", [
    pytest.param(LOAD, id="load", marks=pytest.mark.xfail(
        strict=True, reason="known defect: ok with J_l 0.007396 [0.007316, 0.007476], truth 0.00748")),
    pytest.param(MOTOR, id="motor", marks=pytest.mark.xfail(
        strict=True, reason="known defect: ok with C 0.1390 [0.1166, 0.1657], truth 0.1")),
])
def test_friction_on_the_robot_is_not_a_confident_wrong_result(sim: dict, tmp_path: Path) -> None:
    bench = load_bench(ROBOT)
    bench = bench.model_copy(update={"sim": bench.sim.model_copy(update=sim),
                                     "daq": bench.daq.model_copy(update={"channels": ["i_a"]})})
    current, drive = open_bench(bench, fast=True)
    doc = analyze_session(Recorder(bench, None, current, drive, tmp_path, 10.0).run().path, write=False).json_dict
    truth = doc["simulated_truth"]
    outside = [p for p in PARAMS if not doc["ci95"][p][0] <= truth[p] <= doc["ci95"][p][1]]
    if doc["quality"]["verdict"] == "ok":
        assert outside == [], {p: (doc[p], doc["ci95"][p], truth[p]) for p in outside}
    else:  # not ok: then for the friction's reason
        assert any("friction" in r for r in doc["quality"]["reasons"]), doc["quality"]["reasons"]
