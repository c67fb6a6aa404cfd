"""The bench and motion-profile schema: validated models of the TOML configs (SI units in names).

These models only describe; they import no vendor library. ``acq.config`` loads TOML files into them
and turns validation failures into one-line errors naming the file, the key and the value.
Every model forbids unknown keys, so a misspelt key is an error, never silently ignored.
"""

from __future__ import annotations

from typing import Annotated, Literal, Union

from pydantic import BaseModel, ConfigDict, Field, PositiveFloat, PositiveInt


class Strict(BaseModel):
    """Base for all config sections: unknown keys are errors, values are not coerced from strings."""

    model_config = ConfigDict(extra="forbid", strict=True, frozen=True)


NonNegFloat = Annotated[float, Field(ge=0.0)]
PhaseName = Literal["i_a", "i_b", "i_c"]


class Motor(Strict):
    torque_constant_Nm_per_A: PositiveFloat
    pole_pairs: PositiveInt


class Encoder(Strict):
    counts_per_rev: PositiveInt


class Gear(Strict):
    ratio: PositiveFloat


class Nominal(Strict):
    """Nominal plant: the fit's starting point and the fixed inertias for ``--params K``."""

    K_Nm_per_rad: PositiveFloat
    Jm_kgm2: PositiveFloat
    Jl_kgm2: PositiveFloat
    inertia_known: bool = False  # Jm + Jl known independently (datasheet, CAD): `acq selftest` checks k_t against it


class DaqSim(Strict):
    """Current from the simulated bench."""

    driver: Literal["sim"]
    rate_hz: PositiveFloat
    channels: list[PhaseName] = Field(min_length=1, max_length=3)
    block_s: PositiveFloat = 0.1


class DaqNidaqmx(Strict):
    """Current from an NI-DAQmx device (see ``drivers.nidaq``).

    Attributes
    ----------
    rate_hz : requested sample rate, Hz (the card coerces it; the coerced rate is stored).
    channels, physical_channels : phase names and the DAQmx channels they are wired to, same order.
    block_s : samples per read, s of data (~10 reads/s); buffer_s : host buffer, s of data.
    measurement : ``voltage`` (sensor with a voltage output) or ``current`` (current output).
    sensor_A_per_V, range_V : sensor gain, A of phase current per V; input range, ±V.
    sensor_A_per_A, range_A : sensor ratio, A of phase current per A measured; input range, ±A.
    iepe_excitation_A : IEPE excitation current, A (0 = off); coupling : ``dc`` or ``ac``.
    terminal : input terminal configuration.
    """

    driver: Literal["nidaqmx"]
    rate_hz: PositiveFloat
    channels: list[PhaseName] = Field(min_length=1, max_length=3)
    physical_channels: list[str] = Field(min_length=1, max_length=3)
    block_s: PositiveFloat = 0.1
    buffer_s: PositiveFloat = 5.0
    measurement: Literal["voltage", "current"] = "voltage"
    sensor_A_per_V: PositiveFloat = 1.0
    range_V: PositiveFloat = 5.0
    sensor_A_per_A: PositiveFloat = 1.0
    range_A: PositiveFloat = 0.02
    iepe_excitation_A: NonNegFloat = 0.0
    coupling: Literal["dc", "ac"] = "dc"
    terminal: Literal["default", "differential", "pseudo_differential", "rse", "nrse"] = "default"


DaqSettings = Annotated[Union[DaqSim, DaqNidaqmx], Field(discriminator="driver")]


class DriveSim(Strict):
    """Encoder and motion from the simulated bench's drive (transport ``sim``)."""

    driver: Literal["sim"]
    period_s: PositiveFloat
    # "commanded": acq runs the profile; "external": the machine's own controller moves the joint (the
    # simulated production robot of drivers.sim.robot_program) and acq only listens (acq monitor)
    motion: Literal["commanded", "external"] = "commanded"


class DriveCanopen(Strict):
    """A CiA 402 drive over CANopen (see ``drivers.canopen_drive``)."""

    driver: Literal["canopen"]
    period_s: PositiveFloat
    interface: str = "socketcan"
    channel: str = "can0"
    bitrate: PositiveInt = 1_000_000
    node_id: int = Field(default=1, ge=1, le=127)
    tpdo: int = Field(default=1, ge=1, le=4)
    map_velocity: bool = False
    sdo_timeout_s: PositiveFloat = 0.5
    state_timeout_s: PositiveFloat = 2.0
    heartbeat_timeout_s: PositiveFloat = 0.5
    velocity_units_per_rpm: PositiveFloat = 1.0
    acceleration_units_per_rpm_per_s: PositiveFloat = 1.0
    counts_per_rev: PositiveInt | None = None  # position units (0x6064, 0x607A) per motor rev; None: [encoder]'s
    heartbeat_period_s: PositiveFloat = 0.1  # the drive's producer heartbeat time (0x1017)
    max_bus_load: float = Field(default=0.7, gt=0.0, le=1.0)  # refuse settings whose traffic needs more
    simulated_node: bool = False
    map_timestamp: bool = False  # map the drive's 0x1013 high-resolution time stamp (µs) into the TPDO


class DriveSerial(Strict):
    """A drive streaming framed encoder telemetry over a serial link (see ``drivers.serial_drive``)."""

    driver: Literal["serial"]
    period_s: PositiveFloat
    port: str = "/dev/ttyUSB0"
    baud: PositiveInt = 921_600
    parity: Literal["N", "E", "O"] = "N"
    codec: str = "acq1"
    read_timeout_s: PositiveFloat = 0.5
    simulated_device: bool = False


DriveSettings = Annotated[Union[DriveSim, DriveCanopen, DriveSerial], Field(discriminator="driver")]


class SimSettings(Strict):
    """The simulated bench's truth (plant, motor, measurement chain). Read only by ``drivers.sim``.

    Defaults are the paper's bench (Xu et al. 2021, Table 2) reflected to the motor side.
    """

    K_Nm_per_rad: PositiveFloat = 891.0
    Jm_kgm2: PositiveFloat = 0.003027
    Jl_kgm2: PositiveFloat = 0.00748
    C_Nms_per_rad: NonNegFloat = 0.1
    bm_Nms_per_rad: NonNegFloat = 0.002
    bl_Nms_per_rad: NonNegFloat = 0.002
    arm_mass_kg: NonNegFloat = 5.0
    arm_com_distance_m: NonNegFloat = 0.375
    arm_start_deg: float = -60.0
    speed_loop_hz: PositiveFloat = 4000.0
    speed_bandwidth_hz: PositiveFloat = 15.0
    current_bandwidth_hz: PositiveFloat = 1500.0
    theta0_rad: float = 0.3
    daq_offset_s: float = 0.037
    daq_drift_ppm: float = 40.0
    host_latency_s: NonNegFloat = 0.002
    host_jitter_s: NonNegFloat = 0.0002
    current_noise_A: NonNegFloat = 0.01
    current_dc_offset_A: float = 0.005
    current_dc_offsets_A: dict[PhaseName, float] = Field(default_factory=dict)  # per phase, overrides the above
    encoder_start_counts: int = 0  # position register at θ_m = 0 (near ±2**31 to exercise the int32 wrap)
    pre_roll_s: NonNegFloat = 0.2
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
    K_decay_pct_per_hour: NonNegFloat = 0.0  # wear: K falls linearly with elapsed_s
    # The bench's physical truth where it may differ from what [motor], [encoder] and [daq] state (a bench
    # misconfigured on purpose, for `acq selftest`); None / 1.0 / +1: the same as stated.
    pole_pairs: PositiveInt | None = None  # the motor's real pole pairs (sets the current's electrical angle)
    counts_per_rev: PositiveInt | None = None  # the encoder's real counts per revolution (what it streams)
    current_sensor_gain: PositiveFloat = 1.0  # measured / true phase current (a sensor scale stated wrongly)
    phase_order: list[PhaseName] | None = None  # the phases really wired to [daq] channels, same order
    encoder_direction: Literal[1, -1] = 1  # −1: the encoder counts down while the motor turns forward

    def K_at_start_Nm_per_rad(self) -> float:
        """The true K at this session's start (``elapsed_s``) after the wear ``K_decay_pct_per_hour``, N·m/rad."""
        return self.K_Nm_per_rad * max(1.0 - self.K_decay_pct_per_hour * self.elapsed_s / 3600.0 / 100.0, 0.01)


class Bench(Strict):
    """A whole bench: joint name, motor, encoder, gear, nominal plant, DAQ, drive, optional sim truth."""

    joint: str = Field(min_length=1)
    motor: Motor
    encoder: Encoder
    gear: Gear
    nominal: Nominal
    daq: DaqSettings
    drive: DriveSettings
    sim: SimSettings | None = None


class Profile(Strict):
    """A motion: the triangle speed profile of the paper (speed up, down, reverse, back)."""

    kind: Literal["triangle"]
    top_speed_rpm: PositiveFloat
    accel_time_s: PositiveFloat
    decel_time_s: PositiveFloat
    dwell_s: NonNegFloat = 0.0
    duration_s: PositiveFloat
    cruise_s: NonNegFloat = 0.0  # at top speed between the ramps (a trapezoid), s
    jerk_time_s: NonNegFloat = 0.0  # S-curve: the acceleration ramps in this time (0: steps), s
