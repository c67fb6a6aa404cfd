"""The scenario family's simulator effects against theory: each off by default, each what its law says."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import signal

from drivers.config import Profile
from drivers.motion import RPM_TO_RAD_S, half_swing_rad, triangle_accel_rad_s2, triangle_speed_rad_s
from drivers.sim.daq import open_current_source
from drivers.sim.joint_effects import JointEffects
from drivers.sim.physics import Gravity
from drivers.sim.plant import closed_loop_poles, pole_frequency_damping
from drivers.sim.bench import SimBench
from tests.test_sim_bench import PROFILE, make_bench, make_sim

TOP = 1000 * RPM_TO_RAD_S


def _amplitude_at(x: np.ndarray, fs: float, f_hz: float) -> float:
    """Amplitude of the sinusoid at ``f_hz`` in ``x`` (an integer number of periods recommended)."""
    t = np.arange(x.size) / fs
    return float(2 * np.abs(np.mean((x - x.mean()) * np.exp(-2j * np.pi * f_hz * t))))


def _sim_at(rate_hz: float, **sim: object) -> SimBench:
    """A bench sampling at ``rate_hz`` without noise and drift (a line stays on its DFT bin)."""
    bench = make_bench(current_noise_A=0.0, daq_drift_ppm=0.0, **sim)
    return SimBench(bench.model_copy(update={"daq": bench.daq.model_copy(update={"rate_hz": rate_hz})}),
                    realtime=False)


# ---- defaults ------------------------------------------------------------------------------------------

def test_every_effect_is_off_by_default_and_the_measured_path_reproduces_the_ideal_one() -> None:
    sim = make_sim()
    assert sim.effects == JointEffects() and not sim.chain.active
    assert sim._physics.A.shape == (5, 5) and sim._physics.B.shape == (5, 2)
    assert sim.speed_pi.ff_inertia_kgm2 == pytest.approx(0.003027 + 0.00748)
    # the measurement chain's path with a 24-bit ADC (step 2.4 µA) equals the plain samples within a step
    fine = make_sim(daq_bits=24)
    for s in (sim, fine):
        s.start_motion(PROFILE, 0.1)
    q = fine.chain.quantum_A
    assert q == pytest.approx(40.0 / 2**24)
    np.testing.assert_allclose(fine.current_samples(0, 30000), sim.current_samples(0, 30000),
                               rtol=0, atol=q / 2 + 1e-12)


# ---- plant ---------------------------------------------------------------------------------------------

@pytest.mark.parametrize("side", ["load", "motor"])
@pytest.mark.parametrize("rpm", [10.0, 1000.0])
def test_friction_adds_the_coulomb_stribeck_torque_at_constant_speed(rpm: float, side: str) -> None:
    """In a long cruise the motor torque carries gravity and the friction law F(ω) exactly, of the load's
    or of the motor's speed (the two are equal in a cruise)."""
    profile = Profile(kind="triangle", top_speed_rpm=rpm, accel_time_s=0.2, decel_time_s=0.2, cruise_s=2.0,
                      duration_s=10.0)
    law = {f"{side}_coulomb_Nm": 0.3, f"{side}_stribeck_Nm": 0.2, f"{side}_stribeck_speed_rad_s": 2.0}
    with_f, without = make_sim(**law), make_sim()
    t = np.arange(1.2, 2.2, 1e-3)                      # cruise: 0.2 s ramp + 1 s settling
    torque = {}
    for name, sim in (("with", with_f), ("without", without)):
        sim.start_motion(profile, 0.0)
        st = sim.true_state_at(t)
        s = sim.sim
        g = Gravity(s.arm_mass_kg, s.arm_com_distance_m, np.radians(s.arm_start_deg), sim.bench.gear.ratio)
        torque[name] = st["torque_Nm"] - np.array([g.torque_Nm(x) for x in st["theta_l_rad"]])
        omega_l = st["omega_l_rad_s"]
    friction = with_f.effects.friction if side == "load" else with_f.effects.motor_friction
    expected = friction.torque_Nm(omega_l)
    assert np.mean(expected) == pytest.approx(0.3 + 0.2 * np.exp(-(rpm * RPM_TO_RAD_S / 2.0) ** 2), rel=0.05)
    assert np.mean(torque["with"] - torque["without"]) == pytest.approx(np.mean(expected), rel=0.02)


def test_cogging_is_the_motor_torque_the_current_does_not_carry_with_its_periods_per_revolution() -> None:
    """The motor's equation of motion, J_m·α_m = k_t·i_q − K·δ − C·δ̇ − b_m·ω_m − T_c, leaves T_c over the
    triangle's swing: A·sin(24·θ_m) at the last control instant (the torque is held over the 250 µs period) to
    2 % of A r.m.s. (measured 1.1 %; against A·sin(24·θ_m) of the same instant 15 %: the hold's lag at speed);
    without cogging the same residual is below 0.1 % of A (measured 0.07 %: the interpolated states' derivative)."""
    residual = {}
    for amplitude in (0.2, 0.0):
        sim = make_sim(cogging_Nm=amplitude, cogging_per_rev=24)
        sim.start_motion(PROFILE, 0.0)
        t = np.arange(0.5, 2.5, 2e-6)
        st = sim.true_state_at(t)
        p = sim.plant
        held = sim.true_state_at(np.floor(t * sim.sim.speed_loop_hz) / sim.sim.speed_loop_hz)["theta_m_rad"]
        twist, twist_rate = st["theta_m_rad"] - st["theta_l_rad"], st["omega_m_rad_s"] - st["omega_l_rad_s"]
        cogging = (st["torque_Nm"] - p.Jm_kgm2 * np.gradient(st["omega_m_rad_s"], t) - p.K_Nm_per_rad * twist
                   - p.C_Nms_per_rad * twist_rate - p.bm_Nms_per_rad * st["omega_m_rad_s"])
        residual[amplitude] = np.sqrt(np.mean((cogging - amplitude * np.sin(24 * held)) ** 2))
    assert residual[0.2] < 0.2 * 0.02
    assert residual[0.0] < 0.2 * 0.001


def test_an_eccentric_encoder_reads_its_once_per_revolution_error_and_the_loop_follows_it() -> None:
    """With e = 1 mrad the streamed position is θ_m + e·sin(θ_m) (its once-per-revolution line 1 mrad to 2 %), in a
    100 rpm cruise (1.7 Hz per revolution, far inside the 15 Hz speed loop) the loop holds the *read* speed: the true
    speed ripples by e·ω = 10.5 mrad/s (to 10 %) at once per revolution; and the phase current follows the read angle."""
    profile = Profile(kind="triangle", top_speed_rpm=100.0, accel_time_s=0.2, decel_time_s=0.2, cruise_s=4.0,
                      duration_s=10.0)
    sim = make_sim(encoder_eccentricity_rad=1e-3, current_noise_A=0.0)
    sim.start_motion(profile, 0.0)
    cycles = np.arange(1200, 4200)                                 # 1.2 … 4.2 s: the cruise, settled; 5 revolutions
    t = sim.latch_times_s(int(cycles[0]), cycles.size)
    st = sim.true_state_at(t)
    read = (sim.encoder_counts(int(cycles[0]), cycles.size) - sim.sim.encoder_start_counts) * 2 * np.pi / 131072
    theta = st["theta_m_rad"]
    assert 2 * abs(np.mean((read - theta) * np.exp(-1j * theta))) == pytest.approx(1e-3, rel=0.02)
    omega = 100.0 * RPM_TO_RAD_S
    ripple = 2 * abs(np.mean((st["omega_m_rad_s"] - np.mean(st["omega_m_rad_s"])) * np.exp(-1j * theta)))
    assert ripple == pytest.approx(1e-3 * omega, rel=0.1)
    # the drive commutates on what it reads: the phase current's angle is p·(θ_m + e·sin θ_m) + θ0
    n = np.arange(40000, 60000)                                    # DAQ samples in the cruise
    st = sim.true_state_at(sim.daq_time_s(n))
    i_a = sim.current_samples(int(n[0]), n.size)[0] - sim.dc_offset_A[0]
    for angle, error_A in ((st["theta_m_rad"] + 1e-3 * np.sin(st["theta_m_rad"]), 1e-9), (st["theta_m_rad"], None)):
        ideal = -st["iq_A"] * np.sin(4 * angle + sim.sim.theta0_rad)
        if error_A is not None:
            assert np.max(np.abs(i_a - ideal)) < error_A
        else:  # on the true angle it would differ by up to i_q·p·e
            assert np.max(np.abs(i_a - ideal)) > 0.5 * np.max(np.abs(st["iq_A"])) * 4e-3


@pytest.mark.parametrize("backlash_mrad", [0.05, 0.2])
def test_backlash_is_a_dead_zone_of_the_stated_width_in_the_shaft(backlash_mrad: float) -> None:
    """The shaft torque from the load's equation of motion against the twist: two branches of slope K
    whose twist intercepts are ±N·b/2 (motor side)."""
    sim = make_sim(backlash_load_rad=backlash_mrad * 1e-3)
    sim.start_motion(PROFILE, 0.0)
    t = np.arange(0.5, 4.5, 2e-5)
    st = sim.true_state_at(t)
    s, p = sim.sim, sim.plant
    g = Gravity(s.arm_mass_kg, s.arm_com_distance_m, np.radians(s.arm_start_deg), sim.bench.gear.ratio)
    alpha_l = np.gradient(st["omega_l_rad_s"], t)
    shaft = (p.Jl_kgm2 * alpha_l + p.bl_Nms_per_rad * st["omega_l_rad_s"]
             + np.array([g.torque_Nm(x) for x in st["theta_l_rad"]])
             - p.C_Nms_per_rad * (st["omega_m_rad_s"] - st["omega_l_rad_s"]))
    twist = st["theta_m_rad"] - st["theta_l_rad"]
    half = 0.5 * backlash_mrad * 1e-3 * sim.bench.gear.ratio
    for sign in (1.0, -1.0):
        sel = sign * twist > 1.5 * half
        slope, intercept = np.polyfit(twist[sel], shaft[sel], 1)
        assert slope == pytest.approx(p.K_Nm_per_rad, rel=0.01)
        assert -intercept / slope == pytest.approx(sign * half, rel=0.05)
    inside = np.abs(twist) < 0.5 * half
    assert inside.sum() > 20 and np.max(np.abs(shaft[inside])) < 0.05 * p.K_Nm_per_rad * half + 0.05


def test_third_mass_resonances_are_the_models_poles_and_in_the_frf_of_the_true_torque() -> None:
    sim = make_sim(third_mass_Jl_fraction=0.5, third_mass_hz=150.0)
    A = sim._physics.A
    assert A.shape == (7, 7)
    mech = [0, 1, 2, 3, 5, 6]
    Am = A[np.ix_(mech, mech)]
    ev = np.linalg.eigvals(Am)
    poles_hz = np.sort(np.abs(ev[ev.imag > 1.0]) / (2 * np.pi))
    assert poles_hz.size == 2
    sim.start_motion(PROFILE, 0.0)
    fs = 8000.0
    t = np.arange(0.5, 8.5, 1 / fs)
    st = sim.true_state_at(t)
    f, g_xy = signal.csd(st["torque_Nm"], st["omega_m_rad_s"], fs=fs, nperseg=int(0.5 * fs))
    _, g_xx = signal.welch(st["torque_Nm"], fs=fs, nperseg=int(0.5 * fs))
    f, mag = f[1:], np.abs(g_xy / g_xx)[1:]
    b = np.zeros(6)
    b[1] = 1.0 / sim.plant.Jm_kgm2
    model = np.abs([np.linalg.solve(2j * np.pi * fi * np.eye(6) - Am, b)[1] for fi in f])
    band = (f > 20) & (f < 400)
    peaks = f[band][signal.argrelmax(mag[band])[0]]
    assert peaks.size == 2                             # the FRF's local maxima are the lightly damped poles
    np.testing.assert_allclose(peaks, poles_hz, rtol=0.03)
    band = (f > 20) & (f < 600)
    assert np.median(np.abs(mag[band] / model[band] - 1)) < 0.02
    assert poles_hz[0] < 102.3 < poles_hz[1]          # the two-mass resonance splits around the third one


def test_a_stiff_third_mass_is_a_two_mass_joint_with_the_load_inertias_summed() -> None:
    sim = make_sim(third_mass_Jl_fraction=0.2, third_mass_hz=800.0)
    mech = [0, 1, 2, 3, 5, 6]
    Am = sim._physics.A[np.ix_(mech, mech)]
    b = np.zeros(6)
    b[1] = 1.0 / sim.plant.Jm_kgm2
    two = sim.plant.scaled(Jl=1.2)
    A2, _ = two.state_space()
    b2 = np.array([0.0, 1.0 / two.Jm_kgm2, 0.0, 0.0])
    f = np.linspace(10.0, 400.0, 391)
    h3 = np.abs([np.linalg.solve(2j * np.pi * x * np.eye(6) - Am, b)[1] for x in f])
    h2 = np.abs([np.linalg.solve(2j * np.pi * x * np.eye(4) - A2[:4, :4], b2)[1] for x in f])
    away = np.abs(f - two.resonances_hz()[1]) > 10        # the peak itself is the most sensitive
    assert np.max(np.abs(h3[away] / h2[away] - 1)) < 0.03


def test_speed_loop_without_feed_forward_is_stable_at_10_and_60_hz() -> None:
    for bw in (10.0, 60.0):
        sim = make_sim(speed_bandwidth_hz=bw, speed_accel_feedforward=False)
        assert sim.speed_pi.ff_inertia_kgm2 == 0.0
        z = closed_loop_poles(sim.plant, sim.speed_pi)
        _, zeta = pole_frequency_damping(z, sim.speed_pi.period_s)
        assert np.max(np.abs(z)) < 0.999 and np.all(zeta > 0.02)


# ---- motion profiles ------------------------------------------------------------------------------------

def test_s_curve_ramps_keep_duration_end_speeds_and_swing_with_the_jerk_limit() -> None:
    tj = 0.05
    p = Profile(kind="triangle", top_speed_rpm=1000.0, accel_time_s=0.2, decel_time_s=0.2, jerk_time_s=tj,
                duration_s=10.0)
    t = np.arange(0.0, 0.8, 1e-5)
    v, a = triangle_speed_rad_s(t, p), triangle_accel_rad_s2(t, p)
    a_max = TOP / (0.2 - tj)
    assert np.max(np.abs(a)) == pytest.approx(a_max, rel=1e-6)
    assert np.max(np.abs(np.diff(a) / 1e-5)) == pytest.approx(a_max / tj, rel=1e-3)   # the jerk limit
    assert v[np.searchsorted(t, 0.2)] == pytest.approx(TOP, rel=1e-6)
    np.testing.assert_allclose(np.gradient(v, t)[1:-1], a[1:-1], atol=a_max * 2e-3)
    half = t < 0.4
    assert np.trapezoid(v[half], t[half]) == pytest.approx(half_swing_rad(p), rel=1e-4)


def test_trapezoid_cruises_at_top_speed_and_dwells_at_rest() -> None:
    p = Profile(kind="triangle", top_speed_rpm=1000.0, accel_time_s=0.2, decel_time_s=0.2, cruise_s=0.1,
                dwell_s=0.1, duration_s=10.0)
    t = np.arange(0.0, 1.2, 1e-5)
    v = triangle_speed_rad_s(t, p)
    assert np.all(v[(t > 0.2) & (t < 0.3)] == pytest.approx(TOP))
    assert np.all(v[(t > 0.5) & (t < 0.6)] == 0.0) and v[np.searchsorted(t, 0.8)] == pytest.approx(-TOP)
    half = t < 0.6
    assert np.trapezoid(v[half], t[half]) == pytest.approx(half_swing_rad(p), rel=1e-4)
    assert half_swing_rad(p) == pytest.approx(TOP * 0.3)


# ---- measurement chain ----------------------------------------------------------------------------------

def test_mains_hum_is_on_one_phase_with_its_harmonics() -> None:
    sim = make_sim(channels=["i_a", "i_b", "i_c"], mains_hum_A=0.02, mains_hz=50.0, mains_harmonics=[0.3, 0.15],
                   current_noise_A=0.0)
    base = make_sim(channels=["i_a", "i_b", "i_c"], current_noise_A=0.0)
    hum = sim.current_samples(0, 25600) - base.current_samples(0, 25600)    # 1 s at rest
    for h, rel in ((1, 1.0), (2, 0.3), (3, 0.15)):
        assert _amplitude_at(hum[0], 25600.0, 50.0 * h) == pytest.approx(0.02 * rel, rel=1e-3)
    assert np.max(np.abs(hum[1:])) == 0.0


def test_adc_quantises_to_the_step_of_its_range_and_clips() -> None:
    sim = make_sim(daq_bits=16, daq_range_A=0.5, arm_mass_kg=20.0)
    i = sim.current_samples(0, 10000)
    q = 1.0 / 2**16
    assert sim.chain.quantum_A == q
    np.testing.assert_allclose(i / q, np.round(i / q), atol=1e-6)
    big = make_sim(daq_bits=12, daq_range_A=0.01, current_noise_A=0.0, arm_mass_kg=20.0)
    assert np.all(np.abs(big.current_samples(0, 100)) <= 0.01)


@pytest.mark.parametrize(("rate_hz", "antialias", "line_hz", "expected_A"), [
    (51200.0, False, 16000.0, 0.1 * 8 / np.pi**2),     # below Nyquist: the carrier itself
    (10000.0, False, 4000.0, 0.1 * 8 / np.pi**2),      # folded: |16 − 2·10| kHz
    (10000.0, True, 4000.0, 0.0),                      # removed by the anti-alias filter
])
def test_pwm_ripple_line_at_standstill_folds_without_and_vanishes_with_the_anti_alias_filter(
        rate_hz: float, antialias: bool, line_hz: float, expected_A: float) -> None:
    sim = _sim_at(rate_hz, pwm_ripple_A=0.1, pwm_hz=16000.0, daq_antialias=antialias)
    base = _sim_at(rate_hz)
    n = int(rate_hz)                                   # 1 s at rest: m = 0, a pure triangle
    ripple = sim.current_samples(0, n)[0] - base.current_samples(0, n)[0]
    amp = _amplitude_at(ripple, rate_hz, line_hz)
    if expected_A:
        assert amp == pytest.approx(expected_A, rel=0.01)
    else:
        assert amp < 1e-4 * 0.1 and np.std(ripple) < 1e-4


def test_pwm_ripple_envelope_shrinks_with_the_modulation_index_at_speed() -> None:
    """At top speed m = 0.8: the ripple of phase a is A·(1 − m²·sin²θ_e), mean envelope A·(1 − m²/2)."""
    sim, base = _sim_at(51200.0, pwm_ripple_A=0.1), _sim_at(51200.0)
    profile = Profile(kind="triangle", top_speed_rpm=1000.0, accel_time_s=0.2, decel_time_s=0.2, cruise_s=1.0,
                      duration_s=10.0)
    for s in (sim, base):
        s.start_motion(profile, 0.0)
    n0, n = int(0.5 * 51200), 25600                     # cruise
    ripple = sim.current_samples(n0, n)[0] - base.current_samples(n0, n)[0]
    carrier = _amplitude_at(ripple, 51200.0, 16000.0)
    assert carrier == pytest.approx(0.1 * 8 / np.pi**2 * (1 - 0.8**2 / 2), rel=0.02)


def test_anti_alias_filter_is_flat_to_045_rate_80_db_down_from_055_rate_and_delay_free() -> None:
    sim = _sim_at(25600.0, daq_antialias=True, mains_hum_A=0.02, mains_harmonics=[])
    chain = sim.chain
    f, h = signal.freqz(chain.taps, worN=1 << 16, fs=chain.oversampling * 25600.0)
    assert np.max(np.abs(np.abs(h[f <= 0.45 * 25600]) - 1)) < 1e-3
    assert np.max(np.abs(h[f >= 0.55 * 25600])) < 10 ** (-79 / 20)
    # a 50 Hz hum through the filter: amplitude and phase as the point samples (group delay compensated)
    plain = _sim_at(25600.0, mains_hum_A=0.02, mains_harmonics=[])
    base = _sim_at(25600.0)
    n = 25600
    t = np.arange(n) / 25600.0
    filtered, points = (2 * np.mean((s.current_samples(0, n)[0] - base.current_samples(0, n)[0])
                                    * np.exp(-2j * np.pi * 50.0 * t)) for s in (sim, plain))
    assert np.abs(filtered - points) < 1e-4 * 0.02


def test_offset_drift_and_gain_errors_at_rest() -> None:
    gains = {"i_b": 0.02, "i_c": -0.03}
    sim = make_sim(channels=["i_a", "i_b", "i_c"], current_noise_A=0.0, current_gain_errors=gains,
                   offset_drift_A=0.04, offset_drift_period_s=2.0, current_dc_offset_A=0.0, arm_mass_kg=20.0)
    base = make_sim(channels=["i_a", "i_b", "i_c"], current_noise_A=0.0, current_dc_offset_A=0.0, arm_mass_kg=20.0)
    n = 2 * 25600
    t = sim.daq_time_s(np.arange(n))
    got, ideal = sim.current_samples(0, n), base.current_samples(0, n)
    for row, name in enumerate(("i_a", "i_b", "i_c")):
        drift = got[row] - (1 + gains.get(name, 0.0)) * ideal[row]
        phase = sim.chain.drift_phases_rad[row, 0]
        np.testing.assert_allclose(drift, 0.04 * np.sin(2 * np.pi * t / 2.0 + phase), atol=1e-12)


def test_streamed_blocks_with_the_anti_alias_filter_equal_one_read_and_history_suffices() -> None:
    streamed = make_sim(keep_history=False, daq_antialias=True, pwm_ripple_A=0.05)
    whole = make_sim(daq_antialias=True, pwm_ripple_A=0.05)
    for s in (streamed, whole):
        s.start_motion(PROFILE, 0.0)
    daq = open_current_source(streamed.bench, streamed, True)
    daq.start()
    blocks = np.concatenate([daq.read(0.1).current_a for _ in range(20)], axis=1)
    # equal to rounding: the FFT convolution's last bits depend on the block length
    np.testing.assert_allclose(blocks, whole.current_samples(0, blocks.shape[1]), rtol=0, atol=1e-12)


def test_drives_that_cannot_carry_an_s_curve_or_a_cruise_refuse_it_in_one_line() -> None:
    from drivers.canopen_motion import ProfilePositionMotion
    from drivers.config import DriveCanopen, DriveSerial
    from acqcore.errors import ConfigError
    from drivers.serial_drive import SerialDrive

    s_curve = PROFILE.model_copy(update={"jerk_time_s": 0.02})
    pp = ProfilePositionMotion(None, "drive", DriveCanopen(driver="canopen", period_s=0.001), 131072,
                               lambda e: None, lambda s: None)
    with pytest.raises(ConfigError, match="^profile: jerk_time_s = 0.02 s, but profile position mode"):
        pp.start(s_curve)
    serial = SerialDrive(DriveSerial(driver="serial", period_s=0.001, port="loop://"), 131072)
    with pytest.raises(ConfigError, match=r"^profile: cruise_s = 0.1 s, jerk_time_s = 0 s cannot be sent"):
        serial.start_motion(PROFILE.model_copy(update={"cruise_s": 0.1}))


def test_s_curve_moves_travel_the_same_distance_with_a_continuous_acceleration() -> None:
    from drivers.sim.robot_program import Move, RobotProgram

    dt = 1e-5
    for s_curve in (False, True):
        move = Move(0.0, 30.0, 1000 * RPM_TO_RAD_S, 0.2, s_curve=s_curve)  # reaches its top speed
        u = np.arange(0.0, move.duration_s + 0.01, dt)
        speed, accel = move.reference(u)
        assert np.sum(speed) * dt == pytest.approx(30.0, rel=1e-4)  # the distance asked for
        if s_curve:  # its acceleration is the derivative of its speed (the trapezoid's is, piecewise)
            assert np.allclose(np.gradient(speed, dt)[2:-2], accel[2:-2], atol=5e-3 * np.max(accel), rtol=0)
        jump = np.max(np.abs(np.diff(accel)))  # largest acceleration step between two samples
        # a trapezoid steps to its full acceleration; the S-curve's steps are of order a_peak·π·dt/tr
        assert (jump < 1e-3 * np.max(accel)) if s_curve else (jump == pytest.approx(np.max(accel)))
    shares = [np.mean([m.s_curve for c in range(40) for m in RobotProgram(3, 0.0, 2.0, f).cycle(c).moves])
              for f in (0.0, 0.5, 1.0)]
    assert shares[0] == 0.0 and shares[2] == 1.0 and 0.4 < shares[1] < 0.6
    plain, mixed = RobotProgram(3, 0.0, 2.0, 0.0).cycle(7), RobotProgram(3, 0.0, 2.0, 0.5).cycle(7)
    assert [m.distance_rad for m in plain.moves] == [m.distance_rad for m in mixed.moves]  # same program, other ramps
