"""A robot window read by an eccentric encoder (configs/benches/sim_robot.toml, seed 1 at 540 s, one phase i_a, a
once-per-revolution error of 3 mrad ≈ 10′ — a magnetic or kit encoder's, a disc 50 µm off-centre on 16 mm): acq must
not give a confident wrong result, verdict ``ok`` with the truth outside a 95 % interval. It does (the defect this
test pins, measured at 02c4682, analysis/ as on main 3d6370f): ok, K 905.06 [894.56, 915.69] against 891 and J_m
0.0030877 [0.0030377, 0.0031385] against 0.003027 (J_l +1.3 %, its interval just holding it; without the error the
same window reads K 888.24 [882.70, 893.82]). The error enters through the streamed position, not through the motion:
with it in the stream alone K 907.5, J_m +2.5 %; in the drive's speed loop alone K 890.5 and every interval holds the
truth. |H| reads ~1 % lower below f_a, 2–4 % above it and 12 % lower at f_r (98–106 Hz, coherence 0.955 → 0.838), and
the fit scales K, J_m, J_l up together; the misfit test's worst window is at 0.66 of its allowance.
bench/effects_robot.py counts such windows."""

from __future__ import annotations

from pathlib import Path

import pytest

from acq.config import load_bench
from acq.offline.analyze import analyze_session
from acq.recording.recorder import Recorder
from drivers.registry import open_bench

ROBOT = Path(__file__).resolve().parents[1] / "configs" / "benches" / "sim_robot.toml"
PARAMS = ("K_Nm_per_rad", "Jm_kgm2", "Jl_kgm2", "C_Nms_per_rad")


@pytest.mark.xfail(strict=True, reason="known defect: ok with K 905.06 [894.56, 915.69], truth 891")
def test_an_eccentric_encoder_on_the_robot_is_not_a_confident_wrong_result(tmp_path: Path) -> None:
    bench = load_bench(ROBOT)
    sim = bench.sim.model_copy(update={"elapsed_s": 540.0, "seed": 1, "encoder_eccentricity_rad": 3e-3})
    bench = bench.model_copy(update={"sim": sim, "daq": bench.daq.model_copy(update={"channels": ["i_a"]})})
    current, drive = open_bench(bench, fast=True)
    doc = analyze_session(Recorder(bench, None, current, drive, tmp_path, 10.0).run().path, write=False).json_dict
    truth = doc["simulated_truth"]
    outside = [p for p in PARAMS if not doc["ci95"][p][0] <= truth[p] <= doc["ci95"][p][1]]
    if doc["quality"]["verdict"] == "ok":
        assert outside == [], {p: (doc[p], doc["ci95"][p], truth[p]) for p in outside}
    else:  # not ok: then naming the encoder
        assert any("encoder" in r for r in doc["quality"]["reasons"]), doc["quality"]["reasons"]
