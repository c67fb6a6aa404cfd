"""The bench and motion-profile schema: validated models of the TOML configs (SI units in names).

These models only describe; they import no vendor library. ``acq.config`` loads TOML files into them
and turns validation failures into one-line errors naming the file, the key and the value.
Every model forbids unknown keys, so a misspelt key is an error, never silently ignored. A rule that
involves two keys of a section is a ``model_validator`` of that section, its message naming both keys
(``[daq] block_s = 3 must be at most half of buffer_s = 5``), so ``acq record`` and ``acq import`` refuse
it alike, before anything starts.
"""

from __future__ import annotations

import unicodedata
from typing import Annotated, Literal, Union

from pydantic import AfterValidator, Field, PositiveFloat, PositiveInt, field_validator, model_validator

# Profile (and the Strict base, MAX_DURATION_S, Seconds) are defined in drivers.profile and used from here
from drivers.profile import MAX_DURATION_S, MAX_TOP_SPEED_RPM, Profile, Seconds, Strict
from drivers.serial_codec import CODECS, bits_per_byte, required_baud


NonNegFloat = Annotated[float, Field(ge=0.0)]
PhaseName = Literal["i_a", "i_b", "i_c"]

# Physical bounds: generous for any bench we can imagine, tight enough that a typo (1e12 for 1e4) is refused
# before anything is allocated or sent to a device.
MAX_RATE_HZ = 10e6  # fastest current sampling any supported card offers (NI PXIe-6124: 4 MS/s; margin ×2.5)
RateHz = Annotated[float, Field(gt=0.0, le=MAX_RATE_HZ)]
PeriodS = Annotated[float, Field(ge=1e-6, le=10.0)]  # an encoder sample every 1 µs … 10 s
Timeout = Annotated[float, Field(gt=0.0, le=600.0)]
Stiffness = Annotated[float, Field(gt=0.0, le=1e8)]  # N·m/rad: stiffest harmonic drives are ~1e6
Inertia = Annotated[float, Field(gt=0.0, le=1e3)]  # kg·m²
Damping = Annotated[float, Field(ge=0.0, le=1e6)]  # N·m·s/rad
MAX_JOINT_NAME = 64


def check_joint_name(name: str) -> str:
    """Return ``name`` if it is a safe joint name, else raise ValueError saying why.

    Safe: 1–64 characters, each a letter or digit (any script) or one of ``-``, ``_``, ``.``; no leading dot;
    already in Unicode NFC form (so two spellings of one name cannot make two joints). It becomes part of a
    file name, so nothing that a file system or a shell treats specially gets through.
    """
    if not name:
        raise ValueError("must not be empty")
    if len(name) > MAX_JOINT_NAME:
        raise ValueError(f"must be at most {MAX_JOINT_NAME} characters")
    if name.startswith("."):
        raise ValueError("must not start with a dot")
    bad = next((ch for ch in name if not (ch.isalnum() or ch in "-_.")), None)
    if bad is not None:
        raise ValueError(f"may hold only letters, digits, '-', '_' and '.' (not {ascii(bad)})")
    if unicodedata.normalize("NFC", name) != name:
        raise ValueError("must be in Unicode NFC form")
    return name


def _distinct_phases(channels: list[str]) -> list[str]:
    """Each phase at most once: the session stores one dataset per phase (a phase twice made HDF5 fail mid-start)."""
    twice = next((c for i, c in enumerate(channels) if c in channels[:i]), None)
    if twice is not None:
        raise ValueError(f"{twice} is listed twice (each phase is one channel)")
    return channels


#: ``[daq] channels``: the phases wired to the DAQ, in its channel order, each once.
PhaseChannels = Annotated[list[PhaseName], Field(min_length=1, max_length=3), AfterValidator(_distinct_phases)]


class Motor(Strict):
    torque_constant_Nm_per_A: float = Field(gt=0.0, le=1000.0)
    pole_pairs: int = Field(gt=0, le=1000)


class Encoder(Strict):
    counts_per_rev: int = Field(gt=0, le=2**31)


class Gear(Strict):
    ratio: float = Field(gt=0.0, le=1e5)


class Nominal(Strict):
    """Nominal plant: the fit's starting point and the fixed inertias for ``--params K``."""

    K_Nm_per_rad: Stiffness
    Jm_kgm2: Inertia
    Jl_kgm2: Inertia
    inertia_known: bool = False  # Jm + Jl known independently (datasheet, CAD): `acq selftest` checks k_t against it


class DaqSim(Strict):
    """Current from the simulated bench."""

    driver: Literal["sim"]
    rate_hz: RateHz
    channels: PhaseChannels
    block_s: float = Field(default=0.1, gt=0.0, le=10.0)


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
    rate_hz: RateHz
    channels: PhaseChannels
    physical_channels: list[str] = Field(min_length=1, max_length=3)
    block_s: float = Field(default=0.1, gt=0.0, le=10.0)
    buffer_s: float = Field(default=5.0, gt=0.0, le=600.0)
    measurement: Literal["voltage", "current"] = "voltage"
    sensor_A_per_V: float = Field(default=1.0, gt=0.0, le=1e4)
    range_V: float = Field(default=5.0, gt=0.0, le=1000.0)
    sensor_A_per_A: float = Field(default=1.0, gt=0.0, le=1e5)
    range_A: float = Field(default=0.02, gt=0.0, le=100.0)
    iepe_excitation_A: float = Field(default=0.0, ge=0.0, le=0.1)
    coupling: Literal["dc", "ac"] = "dc"
    terminal: Literal["default", "differential", "pseudo_differential", "rse", "nrse"] = "default"

    @model_validator(mode="after")
    def _channels_and_buffer(self) -> DaqNidaqmx:
        if len(self.channels) != len(self.physical_channels):
            raise ValueError(f"[daq] channels {self.channels} and physical_channels {self.physical_channels} "
                             "must have the same length")
        if self.block_s * 2 > self.buffer_s:  # the card fills one half of the host buffer while the host reads the other
            raise ValueError(f"[daq] block_s = {self.block_s:g} must be at most half of buffer_s = {self.buffer_s:g}")
        return self


DaqSettings = Annotated[Union[DaqSim, DaqNidaqmx], Field(discriminator="driver")]


class DriveSim(Strict):
    """Encoder and motion from the simulated bench's drive (transport ``sim``)."""

    driver: Literal["sim"]
    period_s: PeriodS
    # "commanded": acq runs the profile; "external": the machine's own controller moves the joint (the
    # simulated production robot of drivers.sim.robot_program) and acq only listens (acq monitor)
    motion: Literal["commanded", "external"] = "commanded"


class DriveCanopen(Strict):
    """A CiA 402 drive over CANopen (see ``drivers.canopen_drive``)."""

    driver: Literal["canopen"]
    period_s: PeriodS
    interface: str = "socketcan"
    channel: str = "can0"
    bitrate: int = Field(default=1_000_000, gt=0, le=1_000_000)  # classic CAN's maximum
    node_id: int = Field(default=1, ge=1, le=127)
    tpdo: int = Field(default=1, ge=1, le=4)
    map_velocity: bool = False
    sdo_timeout_s: Timeout = 0.5
    state_timeout_s: Timeout = 2.0
    heartbeat_timeout_s: Timeout = 0.5
    velocity_units_per_rpm: float = Field(default=1.0, gt=0.0, le=1e9)
    acceleration_units_per_rpm_per_s: float = Field(default=1.0, gt=0.0, le=1e9)
    counts_per_rev: Annotated[int, Field(gt=0, le=2**31)] | None = None  # position units (0x6064, 0x607A) per motor rev; None: [encoder]'s
    heartbeat_period_s: Timeout = 0.1  # the drive's producer heartbeat time (0x1017)
    max_bus_load: float = Field(default=0.7, gt=0.0, le=1.0)  # refuse settings whose traffic needs more
    simulated_node: bool = False
    map_timestamp: bool = False  # map the drive's 0x1013 high-resolution time stamp (µs) into the TPDO
    # "external": the machine's own master runs NMT, SYNC and the motion; acq only listens (acq monitor): it
    # records the TPDO the master set up (tpdo_cob_id + tpdo_mapping, or TPDO ``tpdo`` of the drive's EDS/DCF
    # file ``eds``) or, with configure = true, maps TPDO ``tpdo`` itself by SDO (never NMT, SYNC or motion)
    motion: Literal["commanded", "external"] = "commanded"
    configure: bool = False
    # the TPDO's COB-ID on the bus: CiA 301's predefined connection set puts the PDOs at 0x181…0x57F (TPDO1…4 at
    # 0x181…0x4FF, RPDO1…4 above them); a master may reassign them anywhere below the SDO identifiers (0x581…),
    # but not onto NMT (0x000), SYNC/EMCY (0x080…0x0FF) or TIME (0x100)
    tpdo_cob_id: int | None = Field(default=None, ge=0x101, le=0x57F)
    tpdo_mapping: list[Annotated[int, Field(ge=0, le=0xFFFFFFFF)]] | None = None  # CiA 301 entries, 0x60640020 …
    eds: str | None = Field(default=None, min_length=1)  # the drive's EDS/DCF file (its TPDO mapping and COB-ID)
    sync_counter_overflow: int = Field(default=0, ge=0, le=240)  # the master's SYNC counter (0x1019); 0: none

    @property
    def tpdo_bytes(self) -> int:
        """Payload of the TPDO asked for, bytes: position, [velocity], [0x1013 time stamp], 4 each."""
        return 4 * (1 + self.map_velocity + self.map_timestamp)

    @model_validator(mode="after")
    def _two_key_rules(self) -> DriveCanopen:
        if self.tpdo_bytes > 8:
            raise ValueError(f"[drive] map_velocity = true and map_timestamp = true need a TPDO of {self.tpdo_bytes} "
                             "bytes, a CAN frame carries 8 — set one of them to false")
        if self.heartbeat_timeout_s <= self.heartbeat_period_s:
            raise ValueError(f"[drive] heartbeat_timeout_s = {self.heartbeat_timeout_s:g} must exceed "
                             f"heartbeat_period_s = {self.heartbeat_period_s:g}")
        if self.simulated_node and self.interface != "virtual":
            raise ValueError(f"[drive] simulated_node = true needs interface = \"virtual\", not {self.interface!r}")
        self._passive_keys()
        return self

    def _passive_keys(self) -> None:
        """The rules of ``motion = "external"``: where the TPDO's layout comes from, one source only."""
        given = [k for k in ("tpdo_cob_id", "tpdo_mapping", "eds") if getattr(self, k) is not None]
        if self.motion == "commanded":
            if self.configure or given or self.sync_counter_overflow:
                what = "configure" if self.configure else (given[0] if given else "sync_counter_overflow")
                raise ValueError(f"[drive] {what} applies only to motion = \"external\" (acq maps and syncs the "
                                 "TPDO itself when it commands the motion)")
            return
        if self.configure:
            if given:
                raise ValueError(f"[drive] configure = true maps acq's own TPDO{self.tpdo}: drop {given[0]} "
                                 "(it describes a TPDO the machine's master set up)")
            return
        if self.map_velocity or self.map_timestamp:
            key = "map_velocity" if self.map_velocity else "map_timestamp"
            raise ValueError(f"[drive] {key} = true needs configure = true (with configure = false the master's "
                             "TPDO mapping, tpdo_mapping or eds, decides what is recorded)")
        if self.eds is not None:
            if given != ["eds"]:
                raise ValueError(f"[drive] eds and {[k for k in given if k != 'eds'][0]}: give the TPDO's layout once "
                                 "(eds, or tpdo_cob_id with tpdo_mapping)")
            return
        if self.tpdo_cob_id is None or self.tpdo_mapping is None:
            missing = "tpdo_cob_id" if self.tpdo_cob_id is None else "tpdo_mapping"
            raise ValueError(f"[drive] motion = \"external\" with configure = false needs the TPDO the master set up: "
                             f"{missing} missing (give tpdo_cob_id and tpdo_mapping, or eds = the drive's EDS/DCF file, "
                             "or configure = true)")
        problem = tpdo_mapping_problem(self.tpdo_mapping)
        if problem:
            raise ValueError(f"[drive] tpdo_mapping = [{', '.join(f'0x{e:08X}' for e in self.tpdo_mapping)}]: {problem}")


#: CiA 402 position actual value (0x6064, 32 bit): the one object a passively recorded TPDO must carry
POSITION_ACTUAL_ENTRY = 0x60640020


def tpdo_mapping_problem(entries: list[int]) -> str:
    """Why CiA 301 PDO mapping ``entries`` (index << 16 | subindex << 8 | bits) cannot be recorded, "" if they can:
    whole bytes, at most 8 bytes (one classic CAN frame), 0x6064 position actual (32 bit) among them."""
    if not entries:
        return "empty"
    if any(e & 0xFF == 0 or e & 0x7 for e in entries):
        return "each entry's length (its low byte) must be a whole number of bytes"
    size = sum(e & 0xFF for e in entries) // 8
    if size > 8:
        return f"{size} bytes, a CAN frame carries 8"
    if POSITION_ACTUAL_ENTRY not in entries:
        return "must map 0x6064 position actual value (0x60640020)"
    return ""


class DriveSerial(Strict):
    """A drive streaming framed encoder telemetry over a serial link (see ``drivers.serial_drive``)."""

    driver: Literal["serial"]
    period_s: PeriodS
    port: str = "/dev/ttyUSB0"
    baud: int = Field(default=921_600, gt=0, le=20_000_000)
    parity: Literal["N", "E", "O"] = "N"
    codec: str = "acq1"
    read_timeout_s: Timeout = 0.5
    simulated_device: bool = False
    # "external": the machine's own controller moves the joint; acq switches the telemetry stream on and
    # never sends a motion command (acq monitor)
    motion: Literal["commanded", "external"] = "commanded"

    @model_validator(mode="after")
    def _codec_carries_the_frame_rate(self) -> DriveSerial:
        if self.codec not in CODECS:
            raise ValueError(f'[drive] codec = "{self.codec}": unknown codec (known: {", ".join(sorted(CODECS))})')
        codec = CODECS[self.codec]()
        need = required_baud(codec, self.period_s, self.parity)
        if self.baud < need:
            raise ValueError(
                f"[drive] baud = {self.baud}: too low for one {codec.telemetry_bytes}-byte {codec.name} frame every "
                f"{self.period_s:g} s; needs at least {need:.0f} baud ({codec.telemetry_bytes} bytes × "
                f"{bits_per_byte(self.parity)} bits / {self.period_s:g} s)")
        return self


DriveSettings = Annotated[Union[DriveSim, DriveCanopen, DriveSerial], Field(discriminator="driver")]


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


class Limits(Strict):
    """``[limits]``: what the joint may see while acq commands its motion (checked by :mod:`drivers.limits` before any
    motion against the profile as executed; a CANopen drive is also told them, :mod:`drivers.canopen_drive`).

    Attributes
    ----------
    max_speed_rpm : motor speed, either direction, rpm (motor side, before the gear).
    max_travel_deg : load-side (arm) angle the motion may move the joint away from where it starts, either
        direction, deg: the mechanical stops or the cables, less a margin.
    max_torque_Nm : motor torque k_t·i_q, N·m (motor side); the drive's current limit is max_torque_Nm / k_t.
    """

    max_speed_rpm: float = Field(gt=0.0, le=MAX_TOP_SPEED_RPM)
    max_travel_deg: float = Field(gt=0.0, le=36_000.0)  # 100 arm turns: a continuous joint's cable reel
    max_torque_Nm: float = Field(gt=0.0, le=1e5)


#: The limits of a simulated joint whose bench states no ``[limits]``: the paper's motor (Xu et al. 2021, Table 2:
#: a 2.3 kW PMSM, k_t = 3 N·m/A) taken as a 3000 rpm servo — rated torque 2.3 kW / 3000 rpm = 7.3 N·m, peak three
#: times that (a typical servo datasheet ratio; an assumption, the paper gives neither) — and one arm turn either
#: way (the simulated arm has no stops). The shipped profiles need 1020 rpm, 306° (triangle_0.5s) and 5.6 N·m.
SIM_LIMITS = Limits(max_speed_rpm=3000.0, max_travel_deg=360.0, max_torque_Nm=22.0)


def moves_real_joint(drive: DriveSim | DriveCanopen | DriveSerial) -> bool:
    """True if acq commands the motion of a real drive (not simulated, not ``motion = "external"``)."""
    simulated = isinstance(drive, DriveSim) or getattr(drive, "simulated_node", False) \
        or getattr(drive, "simulated_device", False)
    return drive.motion == "commanded" and not simulated


class Bench(Strict):
    """A whole bench: joint name, motor, encoder, gear, nominal plant, DAQ, drive, joint limits, optional sim truth.

    ``[limits]`` is required before acq moves a real joint (no default can know a real joint's stops, motor or
    gear: :func:`drivers.limits.refuse_beyond_limits` refuses the motion); a simulated bench without it gets
    :data:`SIM_LIMITS` (:meth:`motion_limits`). A bench only read (``acq import``, ``acq monitor``) needs none.
    """

    joint: str = Field(min_length=1)  # see check_joint_name
    motor: Motor
    encoder: Encoder
    gear: Gear
    nominal: Nominal
    daq: DaqSettings
    drive: DriveSettings
    limits: Limits | None = None
    sim: SimSettings | None = None

    @field_validator("joint")
    @classmethod
    def _safe_joint(cls, name: str) -> str:
        return check_joint_name(name)

    def listens(self) -> bool:
        """True when the machine's own controller moves the joint (``[drive] motion = "external"``): acq commands no
        motion, it only records (``acq monitor``, a passive ``acq record`` or ``acq selftest``)."""
        return self.drive.motion == "external"

    def motion_limits(self) -> Limits | None:
        """``[limits]``; where the bench states none, :data:`SIM_LIMITS` for a simulated drive, None for a real one."""
        if self.limits is not None:
            return self.limits
        return None if moves_real_joint(self.drive) else SIM_LIMITS

