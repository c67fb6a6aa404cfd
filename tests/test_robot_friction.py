"""A robot window with load friction (configs/benches/sim_robot.toml, seed 5 at 300 s, one phase i_a, Coulomb 0.3 N·m
+ Stribeck 0.2 N·m on the load — the accuracy family's friction scenario): acq must not give a confident wrong result,
verdict ``ok`` with the truth outside a 95 % interval. It does (the defect this test pins, measured on main at
6edb9f7): ok, J_l 0.007396 [0.007316, 0.007476] against 0.00748. The friction's torque, correlated with the motion,
lifts |H| by 0.5–5 % at 10–52 Hz — bins the fit trusts (weights 22–88) — which reads J_l 1.1 % low and C 19 % high;
the misfit test sees the anti-resonance's −4.8 % against its 12.6 % limit (the jackknife's scatter there grows with
the friction), the misfit's HAC share of J_l's interval (±0.40 %) stays under the quantisation floor (±0.56 %), and
the jackknife (±0.92 %) cannot show a bias every block shares. bench/friction_robot.py counts such windows."""

from __future__ import annotations

from pathlib import Path

import pytest

from acq.config import load_bench
from acq.offline.analyze import analyze_session
from acq.recording.recorder import Recorder
from drivers.registry import open_bench

ROBOT = Path(__file__).resolve().parents[1] / "configs" / "benches" / "sim_robot.toml"
PARAMS = ("K_Nm_per_rad", "Jm_kgm2", "Jl_kgm2", "C_Nms_per_rad")


@pytest.mark.xfail(strict=True, reason="known defect: ok with J_l 0.007396 [0.007316, 0.007476], truth 0.00748")
def test_load_friction_on_the_robot_is_not_a_confident_wrong_result(tmp_path: Path) -> None:
    bench = load_bench(ROBOT)
    sim = bench.sim.model_copy(update={"elapsed_s": 300.0, "seed": 5, "load_coulomb_Nm": 0.3,
                                       "load_stribeck_Nm": 0.2})
    bench = bench.model_copy(update={"sim": sim, "daq": bench.daq.model_copy(update={"channels": ["i_a"]})})
    current, drive = open_bench(bench, fast=True)
    doc = analyze_session(Recorder(bench, None, current, drive, tmp_path, 10.0).run().path, write=False).json_dict
    truth = doc["simulated_truth"]
    outside = [p for p in PARAMS if not doc["ci95"][p][0] <= truth[p] <= doc["ci95"][p][1]]
    if doc["quality"]["verdict"] == "ok":
        assert outside == [], {p: (doc[p], doc["ci95"][p], truth[p]) for p in outside}
    else:  # not ok: then for the friction's reason
        assert any("friction" in r for r in doc["quality"]["reasons"]), doc["quality"]["reasons"]
