"""analyze(): a simulated-bench recording → K, J_m, J_l, C with intervals, clock, verdict and JSON."""

from __future__ import annotations

import json
import tomllib
from pathlib import Path

import numpy as np
import pytest

from analysis.fit import FitInputError
from analysis.limits import band_problem
from analysis.model import TwoMassParams
from analysis import AnalysisRequest, analyze
from analysis.recording import CommandedProfile, Recording
from drivers.config import Bench, Profile
from drivers.sim.bench import SimBench

SIM_TOML = Path(__file__).resolve().parent.parent / "configs" / "benches" / "sim.toml"
NAMES = ("K_Nm_per_rad", "Jm_kgm2", "Jl_kgm2", "C_Nms_per_rad")


def sim_recording(accel_time_s: float = 0.2, duration_s: float = 10.0, daq_rate_hz: float | None = None,
                  speed_dither: float = 0.0, **sim: object) -> tuple[Recording, dict, TwoMassParams]:
    """A recording of the simulated bench (blocks of 0.1 s, host stamps with jitter), its truth, nominal; a motion
    that repeats exactly, or one dithered by ``speed_dither`` as the shipped profiles are (its seed the bench's)."""
    with SIM_TOML.open("rb") as f:
        bench = Bench.model_validate(tomllib.load(f))
    bench = bench.model_copy(update={"sim": bench.sim.model_copy(update=sim)})
    if daq_rate_hz is not None:
        bench = bench.model_copy(update={"daq": bench.daq.model_copy(update={"rate_hz": daq_rate_hz})})
    bench_sim = SimBench(bench, realtime=False)
    bench_sim.start_motion(Profile(kind="triangle", top_speed_rpm=1000.0, accel_time_s=accel_time_s,
                                   decel_time_s=accel_time_s, duration_s=duration_s, speed_dither=speed_dither,
                                   dither_seed=bench.sim.seed if speed_dither else None), 0.0)
    n, m, blk = int(duration_s * bench_sim.daq_rate_hz), int(duration_s / bench_sim.drive_period_s), 2560
    first = np.arange(0, n, blk)
    count = np.minimum(blk, n - first)
    current = np.concatenate([bench_sim.current_samples(int(a), int(c)) for a, c in zip(first, count)], axis=1)
    index = np.arange(m)
    rec = Recording(
        current_a={c: current[i] for i, c in enumerate(bench_sim.channels)}, rate_hz=bench_sim.daq_rate_hz,
        encoder_index=index, position_counts=bench_sim.encoder_counts(0, m), period_s=bench_sim.drive_period_s,
        counts_per_rev=bench_sim.counts_per_rev, pole_pairs=bench.motor.pole_pairs,
        k_t_Nm_per_A=bench.motor.torque_constant_Nm_per_A, block_first_index=first, block_count=count,
        block_host_ns=bench_sim.host_ns_at(bench_sim.daq_time_s(first + count - 1),
                                           bench_sim.host_jitter_s("daq_host", 0, first.size)),
        encoder_host_ns=bench_sim.host_ns_at(index * bench_sim.drive_period_s,
                                             bench_sim.host_jitter_s("drive_host", 0, m)),
        profile=CommandedProfile(accel_time_s, accel_time_s),
    )
    nominal = TwoMassParams(bench.nominal.K_Nm_per_rad, bench.nominal.Jm_kgm2, bench.nominal.Jl_kgm2, 0.0)
    return rec, bench_sim.truth, nominal


@pytest.fixture(scope="module")
def paper_session() -> tuple[Recording, dict, TwoMassParams]:
    return sim_recording(seed=2, daq_offset_s=-0.045, daq_drift_ppm=-30.0)


def test_default_analysis_of_a_simulated_session_is_accurate_and_ok(paper_session):
    rec, truth, nominal = paper_session
    res = analyze(rec, AnalysisRequest(nominal=nominal))
    for name, tol in zip(NAMES[:3], (0.01, 0.02, 0.02)):
        assert getattr(res.fit.values, name) == pytest.approx(truth[name], rel=tol)
        low, high = res.fit.ci95[name]
        assert low <= truth[name] <= high
    assert res.clock.offset_s == pytest.approx(truth["daq_offset_s"], abs=50e-6)
    assert res.quality.verdict == "ok"


@pytest.mark.parametrize(("band", "message"), [
    ((10.0, 450.0), "fit band 10…450 Hz ends above 400 Hz, the highest frequency the analysis can judge with this "
                    "recording's 1000 Hz encoder (0.4 × its rate, the anti-alias filter's pass edge: above it the "
                    "filter and the encoder's sampling, not the joint, shape the FRF); end the band at 400 Hz or below"),
    # the fit said "Geometric sequence cannot include zero"; from 0.5 to 8 Hz it failed with "no start gave a finite cost"
    ((0.0, 200.0), "fit band 0…200 Hz starts at or below 8 Hz: with 0.5 s Welch segments the fit takes each FRF bin as "
                   "the joint averaged over ±8 Hz, which must stay above 0 Hz; start the band above 8 Hz"),
    ((float("nan"), 200.0), "fit band nan…200 Hz is empty"),
    # the default band with 0.4 s segments: its 10 Hz bin reaches 0 Hz ("the fit did not converge" before)
    (None, "fit band 10…400 Hz starts at or below 10 Hz: with 0.4 s Welch segments the fit takes each FRF bin as "
           "the joint averaged over ±10 Hz, which must stay above 0 Hz; start the band above 10 Hz"),
])
def test_the_analysis_refuses_a_band_it_cannot_judge_in_one_line(paper_session, band, message):
    rec, _, nominal = paper_session
    with pytest.raises(FitInputError) as exc:
        analyze(rec, AnalysisRequest(nominal=nominal, band_hz=band, segment_s=0.5 if band else 0.4))
    assert str(exc.value) == message


def test_band_limits_are_the_pass_edge_and_the_fit_kernel_reaching_0_hz_and_take_a_limit_typed_as_printed():
    assert band_problem((10.0, 200.0), 0.002, 0.5) is None
    assert band_problem((10.0, 200.01), 0.002, 0.5) is not None
    assert band_problem((8.5, 200.0), 0.002, 0.5) is None  # the lowest bin, 10 Hz, averages 2…18 Hz
    assert band_problem((8.0, 200.0), 0.002, 0.5) is not None  # the 8 Hz bin reaches 0 Hz
    assert band_problem((4.5, 200.0), 0.002, 1.0) is None and band_problem((4.0, 200.0), 0.002, 1.0) is not None
    assert "end the band at 266.667 Hz or below" in band_problem((10.0, 300.0), 0.0015, 0.5)
    assert band_problem((10.0, 266.667), 0.0015, 0.5) is None  # 0.4 / 0.0015 s = 266.66666… Hz
    assert band_problem((10.0, 266.67), 0.0015, 0.5) is not None


def test_json_has_exactly_the_documented_keys_and_is_valid_json(paper_session):
    rec, _, nominal = paper_session
    d = analyze(rec, AnalysisRequest(nominal=nominal, params="K")).to_json_dict()
    # acq's chain fits the motor-side damping of the vibration b_v beside C (analysis.fit)
    assert set(d) == {*NAMES, "bv_Nms_per_rad", "ci95", "antiresonance_hz", "resonance_hz", "clock", "quality",
                      "options"}
    assert set(d["ci95"]) == {*NAMES, "bv_Nms_per_rad"} and all(len(v) == 2 for v in d["ci95"].values())
    assert set(d["clock"]) == {"offset_s", "drift_ppm", "residual_s", "ambiguous_by_s", "failure"}
    assert set(d["quality"]) == {"verdict", "mean_coherence", "excitation_coherence", "reasons", "faults",
                                 "encoder_jitter_us", "encoder_time_stamps"}
    assert d["options"]["params"] == "K" and d["options"]["band_hz"] == [10.0, 400.0]
    assert d["Jm_kgm2"] == nominal.Jm_kgm2
    json.loads(json.dumps(d, allow_nan=False))


def test_figure_data_brackets_the_measurement_with_the_model_band(paper_session):
    rec, _, nominal = paper_session
    fig = analyze(rec, AnalysisRequest(nominal=nominal)).figures
    assert fig.t_s.size <= 5000 and fig.t_s.size == fig.torque_Nm.size == fig.speed_rad_s.size
    assert np.all(fig.model_low <= fig.model_abs) and np.all(fig.model_abs <= fig.model_high)
    assert fig.band_hz[0] <= fig.f_a_hz < fig.f_r_hz <= fig.band_hz[1]


def test_the_papers_slow_profile_is_not_reported_as_ok():
    rec, _, nominal = sim_recording(accel_time_s=0.5, seed=1)
    q = analyze(rec, AnalysisRequest(nominal=nominal)).quality
    assert q.verdict in ("poor", "failed")
    assert "shorten accel_time_s and decel_time_s in the profile to ≈ 0." in q.reasons[0]
