"""The simulated bench against analytic truth: plant, speed loop, PMSM currents, encoder, clocks, streams."""

from __future__ import annotations

import itertools
import threading
import time
import tomllib
from pathlib import Path

import numpy as np
import pytest
from scipy import signal
from scipy.linalg import expm

from drivers.base import CurrentSource, Drive
from drivers.config import Bench, Profile
from drivers.motion import RPM_TO_RAD_S
from drivers.sim.bench import SimBench
from drivers.sim.daq import open_current_source
from drivers.sim.drive import open_drive
from drivers.sim.physics import Gravity
from drivers.sim.plant import closed_loop_poles, pole_frequency_damping, tune_speed_pi

SIM_TOML = Path(__file__).resolve().parent.parent / "configs" / "benches" / "sim.toml"
PROFILE = Profile(kind="triangle", top_speed_rpm=1000.0, accel_time_s=0.2, decel_time_s=0.2, duration_s=10.0)


def make_bench(**sim_updates: object) -> Bench:
    """The default simulated bench with some ``[sim]`` values replaced."""
    with SIM_TOML.open("rb") as f:
        bench = Bench.model_validate(tomllib.load(f))
    assert bench.sim is not None
    return bench.model_copy(update={"sim": bench.sim.model_copy(update=sim_updates)})


def make_sim(keep_history: bool = True, channels: list[str] | None = None, **sim_updates: object) -> SimBench:
    bench = make_bench(**sim_updates)
    if channels is not None:
        bench = bench.model_copy(update={"daq": bench.daq.model_copy(update={"channels": channels})})
    return SimBench(bench, realtime=False, keep_history=keep_history)


@pytest.fixture(scope="module")
def moving() -> SimBench:
    """A bench with full history whose triangle starts at t = 0.2 s, simulated to 4.2 s."""
    sim = make_sim()
    sim.start_motion(PROFILE, 0.2)
    sim.true_state_at(4.2)
    return sim


# ---- plant and speed loop ------------------------------------------------------------------------------

def test_open_loop_plant_resonances_match_formulas_and_transfer_function() -> None:
    sim = make_sim()
    p = sim.plant
    A, _ = p.state_space()
    Am = A[:4, :4]                                     # mechanics only, input T_e on ω_m
    b = np.array([0.0, 1.0 / p.Jm_kgm2, 0.0, 0.0])
    f = np.linspace(20.0, 200.0, 18001)
    s = 2j * np.pi * f
    H_ss = np.array([np.linalg.solve(si * np.eye(4) - Am, b)[1] for si in s])
    K, Jm, Jl, C, bm, bl = p.K_Nm_per_rad, p.Jm_kgm2, p.Jl_kgm2, p.C_Nms_per_rad, p.bm_Nms_per_rad, p.bl_Nms_per_rad
    H_tf = (Jl * s**2 + (C + bl) * s + K) / (
        Jm * Jl * s**3 + ((Jm + Jl) * C + Jl * bm + Jm * bl) * s**2 + ((Jm + Jl) * K + (bm + bl) * C + bm * bl) * s
        + K * (bm + bl))
    np.testing.assert_allclose(H_ss, H_tf, rtol=1e-9)
    f_a, f_r = p.resonances_hz()
    assert f_a == pytest.approx(np.sqrt(891.0 / 0.00748) / (2 * np.pi)) and f_a == pytest.approx(54.93, abs=0.01)
    assert f_r == pytest.approx(102.34, abs=0.01)
    mag = np.abs(H_ss)
    assert f[np.argmin(mag)] == pytest.approx(f_a, rel=0.005)
    assert f[np.argmax(mag)] == pytest.approx(f_r, rel=0.005)


@pytest.mark.parametrize("scale", list(itertools.product((0.5, 1.0, 2.0), repeat=3)),
                         ids=lambda s: "K{}_Jm{}_Jl{}".format(*s))
def test_speed_loop_is_stable_and_damped_for_plants_scaled_half_to_double(scale: tuple[float, float, float]) -> None:
    sim = make_sim()
    plant = sim.plant.scaled(*scale)
    z = closed_loop_poles(plant, sim.speed_pi)
    f_hz, zeta = pole_frequency_damping(z, sim.speed_pi.period_s)
    A, _ = plant.state_space()
    ev = np.linalg.eigvals(A[:4, :4])
    zeta_open = float(np.min(-ev.real[np.abs(ev.imag) > 1] / np.abs(ev[np.abs(ev.imag) > 1])))
    resonance = np.abs(f_hz - plant.resonances_hz()[1]) < 0.5 * plant.resonances_hz()[1]
    slow = (f_hz < 20.0) & (np.abs(z.imag) > 1e-9)
    if scale == (1.0, 1.0, 1.0):
        poles = [(round(float(a), 1), round(float(b), 3)) for a, b in sorted(zip(f_hz, zeta))]
        print("\nclosed-loop poles (Hz, zeta):", poles)
    assert len(z) == 6 and np.max(np.abs(z)) < 0.995
    assert np.all(zeta > 0.05)
    assert np.all(zeta[slow] > 0.6)
    assert resonance.sum() == 2 and np.all(zeta[resonance] > 2.0 * zeta_open)


def test_speed_pi_is_tuned_on_the_nominal_total_inertia() -> None:
    sim = make_sim(Jm_kgm2=0.006)                      # the truth differs from the nominal
    J = 0.003027 + 0.00748
    pi = tune_speed_pi(J, 15.0, 1 / 4000)
    assert sim.speed_pi == pi
    assert pi.kp_Nms_per_rad == pytest.approx(J * 2 * np.pi * 15.0)


def test_fine_grid_states_equal_the_exact_zoh_solution_between_control_instants(moving: SimBench) -> None:
    phys = moving._physics
    A, B = phys.A, phys.B
    M = np.zeros((7, 7))
    M[:5, :5], M[:5, 5:] = A, B
    T = phys.pi.period_s
    rng = np.random.default_rng(1)
    for k in rng.integers(800, 16000, size=20):     # control steps inside the motion
        x_k = phys.states_at(np.array([k * T]))[0]
        u_k = phys._steps.view[k - phys._k0][5:]
        tau = rng.uniform(0.0, T)
        exact = (expm(M * tau) @ np.concatenate([x_k, u_k]))[:5]
        got = phys.states_at(np.array([k * T + tau]))[0]
        scale = np.array([1e-3, 1.0, 1e-3, 1.0, 1.0])   # rad, rad/s, rad, rad/s, A
        assert np.all(np.abs(got - exact) < 1e-6 * scale), (k, tau, got - exact)


def test_closed_loop_follows_the_triangle_with_a_rectangular_torque(moving: SimBench) -> None:
    t = np.arange(1.0, 4.2, 1e-4)
    st = moving.true_state_at(t)
    ref, accel = moving.schedule.reference(t)
    err = st["omega_m_rad_s"] - ref
    top = 1000 * RPM_TO_RAD_S
    rms, peak = float(np.sqrt(np.mean(err**2))), float(np.max(np.abs(err)))
    print(f"\nspeed error: rms {rms:.3f} rad/s ({100 * rms / top:.2f} % of top), peak {peak:.2f} rad/s")
    assert rms < 0.01 * top and peak < 0.05 * top
    s = moving.sim
    g = Gravity(s.arm_mass_kg, s.arm_com_distance_m, np.radians(s.arm_start_deg), moving.bench.gear.ratio)
    t_g = np.array([g.torque_Nm(th) for th in st["theta_l_rad"]])
    j_total = s.Jm_kgm2 + s.Jl_kgm2
    phase = np.mod(t - 0.2, 0.2)
    settled = (phase > 0.05) & (phase < 0.15)           # away from the corners of the rectangle
    inertial = st["torque_Nm"] - t_g
    for sign in (1.0, -1.0):
        sel = settled & (np.sign(accel) == sign)
        assert np.median(inertial[sel]) == pytest.approx(sign * j_total * top / 0.2, rel=0.03)
    assert np.ptp(st["theta_l_rad"]) / moving.bench.gear.ratio == pytest.approx(np.radians(120.0), rel=0.01)


def test_frf_from_true_torque_to_motor_speed_in_closed_loop_is_the_stated_plant(moving: SimBench) -> None:
    fs = 20000.0                                      # well above the 4 kHz control images
    t = np.arange(0.5, 8.5, 1 / fs)
    st = moving.true_state_at(t)
    x, y = st["torque_Nm"], st["omega_m_rad_s"]
    f, g_xy = signal.csd(x, y, fs=fs, nperseg=int(0.5 * fs))
    _, g_xx = signal.welch(x, fs=fs, nperseg=int(0.5 * fs))
    A, _ = moving.plant.state_space()
    b = np.array([0.0, 1.0 / moving.plant.Jm_kgm2, 0.0, 0.0])
    ratio = {}
    for band in ((20.0, 45.0), (150.0, 500.0)):
        sel = (f >= band[0]) & (f <= band[1])
        model = np.array([np.linalg.solve(2j * np.pi * fi * np.eye(4) - A[:4, :4], b)[1] for fi in f[sel]])
        ratio[band] = (g_xy[sel] / g_xx[sel]) / model
    print("\n|H1|/|H| 20-45 Hz: {:.4f}..{:.4f}; 150-500 Hz: {:.4f}..{:.4f}".format(
        *(v for r in ratio.values() for v in (np.abs(r).min(), np.abs(r).max()))))
    assert np.median(np.abs(ratio[(20.0, 45.0)])) == pytest.approx(1.0, abs=0.02)   # leakage of the harmonics
    assert np.all(np.abs(np.abs(ratio[(150.0, 500.0)]) - 1) < 0.01)
    assert np.all(np.abs(np.angle(ratio[(150.0, 500.0)])) < np.radians(1.0))


def test_stop_ramps_the_reference_to_rest_without_a_step() -> None:
    sim = make_sim()
    sim.start_motion(PROFILE, 0.1)
    sim.true_state_at(0.35)                           # stop during the deceleration of the first half
    t_rest = sim.stop_motion(0.35)
    assert t_rest is not None
    T = sim.speed_pi.period_s
    t = np.arange(0.3, t_rest + 0.6, T)
    ref, _ = sim.schedule.reference(t)
    decel = 1000 * RPM_TO_RAD_S / 0.2
    assert np.max(np.abs(np.diff(ref))) <= decel * T * (1 + 1e-9)
    assert ref[t >= t_rest].max() == 0.0
    assert np.abs(sim.true_state_at(t_rest + 0.5)["omega_m_rad_s"]) < 0.5


# ---- measurement chain ---------------------------------------------------------------------------------

def test_daq_sample_times_follow_offset_and_drift_exactly() -> None:
    sim = make_sim(daq_offset_s=-0.25, daq_drift_ppm=-80.0)
    n = np.array([0, 1, 25600, 10**7])
    np.testing.assert_array_equal(sim.daq_time_s(n), -0.25 + n / 25600.0 * (1 - 80e-6))


def test_samples_before_the_drive_clock_starts_are_the_joint_at_rest() -> None:
    sim = make_sim(daq_offset_s=-0.25, current_noise_A=0.0)
    i = sim.current_samples(0, 6400)                  # 0.25 s before t = 0
    rest = sim.true_state_at(-1.0)
    theta_e = 4 * rest["theta_m_rad"] + sim.sim.theta0_rad
    np.testing.assert_allclose(i[0], -rest["iq_A"] * np.sin(theta_e) + 0.005, rtol=0, atol=1e-12)
    assert rest["torque_Nm"] == pytest.approx(5.0 * 9.80665 * 0.375 * np.cos(np.radians(-60)) / 10, rel=1e-3)


def test_phase_currents_are_minus_iq_sin_electrical_angle_plus_offset_and_noise() -> None:
    offsets = {"i_a": 0.005, "i_b": -0.02, "i_c": 0.01}
    sim = make_sim(channels=["i_a", "i_b", "i_c"], current_dc_offsets_A={"i_b": -0.02, "i_c": 0.01})
    sim.start_motion(PROFILE, 0.2)
    n0, count = 30000, 40000
    measured = sim.current_samples(n0, count)
    st = sim.true_state_at(sim.daq_time_s(np.arange(n0, n0 + count)))
    theta_e = 4 * st["theta_m_rad"] + 0.3
    for row, (name, shift) in enumerate((("i_a", 0.0), ("i_b", -2 * np.pi / 3), ("i_c", 2 * np.pi / 3))):
        clean = -st["iq_A"] * np.sin(theta_e + shift) + offsets[name]
        residual = measured[row] - clean
        assert np.mean(residual) == pytest.approx(0.0, abs=5 * 0.01 / np.sqrt(count))
        assert np.std(residual) == pytest.approx(0.01, rel=0.03)
    assert sim.truth["current_dc_offset_A"] == offsets


def test_encoder_counts_are_floored_angle_and_the_register_wraps_like_int32() -> None:
    start = 2**31 - 200_000
    sim = make_sim(encoder_start_counts=start)
    sim.start_motion(PROFILE, 0.0)
    k = np.arange(0, 800)
    counts = sim.encoder_counts(0, 800)
    theta = sim.true_state_at(k * 1e-3)["theta_m_rad"]
    np.testing.assert_array_equal(counts, np.floor(theta / (2 * np.pi) * 131072).astype(np.int64) + start)
    assert counts.max() > 2**31 - 1                  # the swing crosses the int32 limit
    reg = sim.encoder_register(0, 800)
    assert reg.dtype == np.int32 and reg.min() < 0
    steps = (np.diff(reg.astype(np.int64)) + 2**31) % 2**32 - 2**31
    np.testing.assert_array_equal(counts[0] + np.concatenate([[0], np.cumsum(steps)]), counts)


def test_same_seed_gives_identical_samples_whatever_the_read_pattern() -> None:
    a, b, c = make_sim(), make_sim(), make_sim(seed=1)
    for sim in (a, b, c):
        sim.start_motion(PROFILE, 0.1)
    whole = a.current_samples(0, 30000)
    parts = np.concatenate([b.current_samples(0, 12345), b.current_samples(12345, 17655)], axis=1)
    np.testing.assert_array_equal(whole, parts)
    assert not np.array_equal(whole, c.current_samples(0, 30000))


# ---- streams -------------------------------------------------------------------------------------------

def test_daq_stream_delivers_contiguous_blocks_stamped_at_their_last_sample() -> None:
    sim = make_sim(keep_history=False)
    daq = open_current_source(sim.bench, sim, True)
    assert isinstance(daq, CurrentSource)
    info = daq.start()
    assert (info.rate_hz, info.channels, info.device) == (25600.0, ("i_a",), "sim-daq")
    blocks = [daq.read(0.1) for _ in range(20)]
    assert all(b is not None and b.count == 2560 for b in blocks)
    assert [b.first_index for b in blocks] == list(range(0, 20 * 2560, 2560))
    host = np.array([b.host_ns for b in blocks])
    nominal = sim.host_ns_at(sim.daq_time_s([b.first_index + 2559 for b in blocks]))
    assert np.all(np.diff(host) >= 0) and np.all(host >= nominal)
    assert np.max(host - nominal) < 5 * 0.0002 * 1e9
    daq.stop()
    assert daq.read(0.1) is None and daq.events() == []


def test_drive_stream_leaves_dropped_frames_out_of_the_indices() -> None:
    drops = [(100, 5), (1000, 30)]
    sim = make_sim(keep_history=True, drop_encoder_frames=drops)
    drive = open_drive(sim.bench, sim, True)
    assert isinstance(drive, Drive)
    info = drive.start()
    assert (info.period_s, info.counts_per_rev, info.transport) == (0.001, 131072, "sim")
    assert info.timestamp_kind == "drive_cycle"
    drive.start_motion(PROFILE)
    blocks = [b for b in (drive.read(0.1) for _ in range(200)) if b is not None]
    index = np.concatenate([b.index for b in blocks])
    expected = np.setdiff1d(np.arange(2000), np.r_[100:105, 1000:1030])
    np.testing.assert_array_equal(index, expected)
    host = np.concatenate([b.host_ns for b in blocks])
    assert np.all(np.diff(host) >= 0)
    np.testing.assert_array_equal(np.concatenate([b.drive_time_s for b in blocks]), index * 1e-3)
    position = np.concatenate([b.position_counts for b in blocks])
    np.testing.assert_array_equal(position, sim.encoder_counts(0, 2000)[index])
    assert sim.truth["motions"][0]["t_start_s"] == pytest.approx(0.2)   # pre-roll after cycle 0
    drive.stop()
    assert drive.read(0.1) is None and np.isfinite(sim.truth["motions"][0]["t_stop_s"])


def test_streams_read_from_two_threads_equal_a_sequential_read_and_history_stays_bounded() -> None:
    def session(threaded: bool) -> tuple[np.ndarray, np.ndarray, SimBench]:
        sim = make_sim(keep_history=False)
        daq, drive = open_current_source(sim.bench, sim, True), open_drive(sim.bench, sim, True)
        daq.start(), drive.start()
        drive.start_motion(PROFILE)
        out: dict[str, list[np.ndarray]] = {"daq": [], "drive": []}

        def read_daq() -> None:
            out["daq"] += [daq.read(0.1).current_a for _ in range(30)]

        def read_drive() -> None:
            out["drive"] += [drive.read(0.1).position_counts for _ in range(300)]

        if threaded:
            threads = [threading.Thread(target=read_daq), threading.Thread(target=read_drive)]
            [th.start() for th in threads]
            [th.join() for th in threads]
        else:
            read_daq(), read_drive()
        return np.concatenate(out["daq"], axis=1), np.concatenate(out["drive"]), sim

    cur_t, pos_t, sim = session(True)
    cur_s, pos_s, _ = session(False)
    np.testing.assert_array_equal(cur_t, cur_s)
    np.testing.assert_array_equal(pos_t, pos_s)
    assert sim._physics.held_s < 0.2                              # both cursors are at ~3 s: only the tail is kept


def test_fast_mode_never_sleeps_and_realtime_read_respects_its_timeout(monkeypatch: pytest.MonkeyPatch) -> None:
    slept: list[float] = []
    monkeypatch.setattr(time, "sleep", slept.append)
    fast = make_sim(keep_history=False)
    daq = open_current_source(fast.bench, fast, True)
    daq.start()
    assert all(daq.read(0.0) is not None for _ in range(5)) and slept == []
    rt = SimBench(make_bench(), realtime=True)
    daq = open_current_source(rt.bench, rt, False)
    daq.start()
    assert daq.read(0.05) is None                      # the first block arrives ~0.14 s after construction
    assert len(slept) == 1 and 0.0 <= slept[0] <= 0.05


def test_a_ten_second_fast_session_costs_little_cpu() -> None:
    t0 = time.process_time()
    sim = make_sim(keep_history=False)
    daq, drive = open_current_source(sim.bench, sim, True), open_drive(sim.bench, sim, True)
    daq.start(), drive.start()
    drive.start_motion(PROFILE)
    n_cur = sum(daq.read(0.1).count for _ in range(100))
    n_enc = sum(drive.read(0.1).count for _ in range(1000))
    cpu_s = time.process_time() - t0
    print(f"\n10 s fast session ({n_cur} current samples, {n_enc} encoder frames): {cpu_s:.2f} s CPU")
    assert (n_cur, n_enc) == (256000, 10000)
    assert cpu_s < 5.0
