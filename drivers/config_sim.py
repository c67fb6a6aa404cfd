"""The ``[sim]`` section of a bench: the simulated bench's truth (plant, motor, measurement chain, scenario effects).

Re-exported by :mod:`drivers.config`, the schema's face.
"""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import Field, PositiveFloat, PositiveInt

from drivers.config_fields import MAX_RATE_HZ, Damping, Inertia, NonNegFloat, PhaseName, Stiffness
from drivers.profile import Strict


class SimSettings(Strict):
    """The simulated bench's truth (plant, motor, measurement chain). Read only by ``drivers.sim``.

    Defaults are the paper's bench (Xu et al. 2021, Table 2) reflected to the motor side.
    """

    K_Nm_per_rad: Stiffness = 891.0
    Jm_kgm2: Inertia = 0.003027
    Jl_kgm2: Inertia = 0.00748
    C_Nms_per_rad: Damping = 0.1
    bm_Nms_per_rad: Damping = 0.002
    bl_Nms_per_rad: Damping = 0.002
    arm_mass_kg: float = Field(default=5.0, ge=0.0, le=1e4)
    arm_com_distance_m: float = Field(default=0.375, ge=0.0, le=100.0)
    arm_start_deg: float = Field(default=-60.0, ge=-360.0, le=360.0)
    speed_loop_hz: float = Field(default=4000.0, gt=0.0, le=MAX_RATE_HZ)
    speed_bandwidth_hz: float = Field(default=15.0, gt=0.0, le=1e5)
    current_bandwidth_hz: float = Field(default=1500.0, gt=0.0, le=1e6)
    theta0_rad: float = Field(default=0.3, ge=-1e3, le=1e3)
    daq_offset_s: float = Field(default=0.037, ge=-3600.0, le=3600.0)
    daq_drift_ppm: float = Field(default=40.0, ge=-1000.0, le=1000.0)  # quartz: ±100 ppm; cheap RC clocks ±1000
    host_latency_s: float = Field(default=0.002, ge=0.0, le=10.0)
    host_jitter_s: float = Field(default=0.0002, ge=0.0, le=10.0)
    current_noise_A: float = Field(default=0.01, ge=0.0, le=1e3)
    current_dc_offset_A: float = Field(default=0.005, ge=-1e3, le=1e3)
    current_dc_offsets_A: dict[PhaseName, float] = Field(default_factory=dict)  # per phase, overrides the above
    encoder_start_counts: int = 0  # position register at θ_m = 0 (near ±2**31 to exercise the int32 wrap)
    pre_roll_s: float = Field(default=0.2, ge=0.0, le=3600.0)
    # (first_cycle, count) frames the sim drive never delivers; a TOML array of pairs becomes tuples
    drop_encoder_frames: list[Annotated[tuple[Annotated[int, Field(ge=0)], PositiveInt], Field(strict=False)]] = (
        Field(default_factory=list))
    seed: int = 0
    # ---- effects of the scenario family (issue 13); every one is off by default -------------------
    # plant (drivers.sim.joint_effects): load-side friction, motor-side N·m and rad/s (see friction.py)
    load_coulomb_Nm: NonNegFloat = 0.0
    load_stribeck_Nm: NonNegFloat = 0.0  # breakaway excess over Coulomb at rest
    load_stribeck_speed_rad_s: PositiveFloat = 2.0
    friction_smoothing_rad_s: PositiveFloat = 0.5  # tanh width of the sign(ω) of the Coulomb law
    backlash_load_rad: NonNegFloat = 0.0  # gear backlash (full dead zone width) on the load side, rad
    third_mass_Jl_fraction: NonNegFloat = 0.0  # J_3 / J_l of a third mass behind the load (0 = none)
    third_mass_hz: PositiveFloat = 800.0  # its natural frequency on a clamped load, √(K_2/J_3)/2π, Hz
    third_mass_damping_ratio: NonNegFloat = 0.02
    # motor side (the reducer's input: bearings, seals, the motor's own cogging), torques the phase current does not
    # carry — the drive's speed loop supplies them, the analysis sees them as part of k_t·i_q
    motor_coulomb_Nm: NonNegFloat = 0.0
    motor_stribeck_Nm: NonNegFloat = 0.0  # breakaway excess over Coulomb at rest
    motor_stribeck_speed_rad_s: PositiveFloat = 2.0
    cogging_Nm: NonNegFloat = 0.0  # amplitude of the cogging torque A·sin(n·θ_m + φ), N·m
    cogging_per_rev: PositiveInt = 24  # n: periods per motor revolution (LCM of slots and poles: 12 slots, 8 poles)
    cogging_phase_rad: float = Field(default=0.0, ge=-1e3, le=1e3)  # φ, at θ_m = 0
    # the encoder's once-per-revolution error (a disc mounted off-centre): it reads θ_m + e·sin(θ_m + φ), rad, in the
    # drive's speed loop and in what it streams
    encoder_eccentricity_rad: NonNegFloat = 0.0
    encoder_eccentricity_phase_rad: float = Field(default=0.0, ge=-1e3, le=1e3)
    speed_accel_feedforward: bool = True  # the speed loop adds J_nominal·α_ref
    # measurement chain of the current (drivers.sim.measurement)
    daq_antialias: bool = False  # True: an oversampled analog signal through a linear-phase low-pass
    daq_bits: int = Field(default=0, ge=0, le=24)  # ADC resolution (0 = not quantised) over ±daq_range_A
    daq_range_A: PositiveFloat = 20.0
    pwm_ripple_A: NonNegFloat = 0.0  # peak ripple of the phase current at standstill, A
    pwm_hz: PositiveFloat = 16000.0
    pwm_modulation_at_top: float = Field(default=0.8, ge=0.0, le=1.0)  # modulation index at 1000 rpm
    mains_hum_A: NonNegFloat = 0.0  # amplitude of the fundamental, A, on ``mains_phase`` only
    mains_hz: PositiveFloat = 50.0
    mains_harmonics: list[NonNegFloat] = Field(default_factory=lambda: [0.3, 0.15])  # 2nd, 3rd … relative
    mains_phase: PhaseName = "i_a"
    offset_drift_A: NonNegFloat = 0.0  # amplitude of a slow sensor offset drift, A (every channel)
    offset_drift_period_s: PositiveFloat = 20.0
    current_gain_errors: dict[PhaseName, float] = Field(default_factory=dict)  # relative, e.g. {i_b = 0.02}
    # the drive latches the position when SYNC arrives: std of that instant around k·T, s (0 = exactly k·T)
    sync_jitter_s: NonNegFloat = 0.0
    # the sim and serial drives' time stamp is the true latch instant (False: the nominal k·T, no real stamp)
    drive_time_stamps: bool = True
    # Condition monitoring (acq monitor). ``elapsed_s``: machine time at this session's start, s (the monitor
    # sets it per window; the robot program's phase, the wear and the noise seed follow it).
    elapsed_s: NonNegFloat = 0.0
    robot_idle_fraction: float = Field(default=0.15, ge=0.0, le=1.0)  # program cycles that are a long wait
    robot_payload_max_kg: NonNegFloat = 2.0  # payload per program cycle, uniform in 0 … this, kg at the arm's tip
    # share of the program's moves with S-curve (jerk-limited, raised-cosine) ramps instead of trapezoid ones
    robot_s_curve_fraction: float = Field(default=0.0, ge=0.0, le=1.0)
    # the payload also adds to J_l (as a point mass at the tip: payload_Jl_kgm2); off: it changes the gravity load only
    robot_payload_inertia: bool = False
    K_decay_pct_per_hour: NonNegFloat = 0.0  # wear: K falls linearly with elapsed_s
    # The bench's physical truth where it may differ from what [motor], [encoder] and [daq] state (a bench
    # misconfigured on purpose, for `acq selftest`); None / 1.0 / +1: the same as stated.
    pole_pairs: PositiveInt | None = None  # the motor's real pole pairs (sets the current's electrical angle)
    counts_per_rev: PositiveInt | None = None  # the encoder's real counts per revolution (what it streams)
    current_sensor_gain: PositiveFloat = 1.0  # measured / true phase current (a sensor scale stated wrongly)
    phase_order: list[PhaseName] | None = None  # the phases really wired to [daq] channels, same order
    encoder_direction: Literal[1, -1] = 1  # −1: the encoder counts down while the motor turns forward

    def payload_Jl_kgm2(self, payload_kg: float, gear_ratio: float) -> float:
        """Motor-side load inertia a payload adds, kg·m²: a point mass at the arm's tip (twice ``arm_com_distance_m``,
        where the gravity model puts it), m·r²/ratio²; zero unless ``robot_payload_inertia``."""
        return payload_kg * (2.0 * self.arm_com_distance_m / gear_ratio) ** 2 if self.robot_payload_inertia else 0.0

    def K_at_start_Nm_per_rad(self) -> float:
        """The true K at this session's start (``elapsed_s``) after the wear ``K_decay_pct_per_hour``, N·m/rad."""
        return self.K_Nm_per_rad * max(1.0 - self.K_decay_pct_per_hour * self.elapsed_s / 3600.0 / 100.0, 0.01)
