"""The simulated bench: one joint's physics shared by the simulated DAQ and drive, and their clocks.

Clocks (all times in s unless the name says ns):

* drive clock — the reference: drive cycle k is at t = k·``drive.period_s``; the physics runs on it;
* DAQ clock — sample n is at t = ``daq_offset_s`` + n/``rate_hz``·(1 + ``daq_drift_ppm``·1e-6), i.e. the
  analysis's convention t_drive = offset + t_daq·(1 + drift), t_daq = n/rate; before t = 0 the joint rests;
* host clock — host_ns = host_t0_ns + (t + ``host_latency_s`` + |jitter|)·1e9, host_t0_ns being
  ``time.monotonic_ns()`` at construction; jitter ~ N(0, ``host_jitter_s``).

Samples are computed from indices and rates, never from the wall clock; :meth:`SimBench.pace_until` is
the separate real-time layer (no sleeping when not real-time). Noise and jitter are functions of the
sample index and ``sim.seed`` only, so a session is reproducible whatever the read pattern or threads.

The physics advances on demand to whatever time a stream asks for, under one lock (the DAQ and the
drive are read from different threads). History older than every registered consumer's cursor (see
:meth:`SimBench.hold_history`; the sim DAQ and drive register when constructed, release on ``stop()``)
is dropped unless ``keep_history``. With no consumer registered nothing is dropped.
"""

from __future__ import annotations

import dataclasses
import math
import threading
import time
from typing import Any, Literal

import numpy as np

from drivers.config import Bench, Profile, SimSettings
from acqcore.errors import ConfigError
from drivers.sim.joint_effects import JointEffects
from drivers.sim.measurement import CurrentChain
from drivers.sim.motion import MotionSchedule
from drivers.sim.physics import Gravity, JointSimulation
from drivers.sim.plant import TwoMass, tune_speed_pi
from drivers.sim.robot_program import RobotProgram, WindowReference

PHASE_SHIFT_RAD = {"i_a": 0.0, "i_b": -2.0 * np.pi / 3.0, "i_c": 2.0 * np.pi / 3.0}
_NOISE_CHUNK = 1 << 14
NoiseStream = Literal["current", "daq_host", "drive_host", "sync_latch"]
_STREAM_IDS = {"current": 1, "daq_host": 2, "drive_host": 3, "sync_latch": 4}
# SYNC k+1 is sent only after SYNC k arrived, so latch instants stay in order: the jitter is clipped here (× T)
LATCH_CLIP = 0.45


def _int32(counts: np.ndarray) -> np.ndarray:
    """Wrap int64 counts to a two's-complement int32 register."""
    return ((counts + 2**31) % 2**32 - 2**31).astype(np.int32)


class SimBench:
    """Physics, measurement chain and clocks of the simulated bench.

    Parameters
    ----------
    bench : the bench config; ``bench.sim`` holds the truth (a default :class:`SimSettings` if absent).
    realtime : pace reads to the host clock (True) or run as fast as possible (False, ``--fast``).
    keep_history : keep every simulated state (for :meth:`true_state_at` on the whole session).
    """

    def __init__(self, bench: Bench, *, realtime: bool, keep_history: bool = False) -> None:
        self.bench = bench
        self.sim: SimSettings = bench.sim if bench.sim is not None else SimSettings()
        self.realtime = realtime
        self.keep_history = keep_history
        s, nom = self.sim, bench.nominal
        program = None
        if getattr(bench.drive, "motion", "commanded") == "external":  # the machine's own robot program moves it
            robot = RobotProgram(s.seed, s.robot_idle_fraction, s.robot_payload_max_kg, s.robot_s_curve_fraction)
            program = WindowReference(robot, robot.rest_before(s.elapsed_s))
        payload_kg = program.payload_kg() if program is not None else 0.0
        Jl_kgm2 = s.Jl_kgm2 + s.payload_Jl_kgm2(payload_kg, bench.gear.ratio)  # the session's J_l: its start cycle's payload
        self.plant = TwoMass(s.K_at_start_Nm_per_rad(), s.Jm_kgm2, Jl_kgm2, s.C_Nms_per_rad, s.bm_Nms_per_rad,
                             s.bl_Nms_per_rad, bench.motor.torque_constant_Nm_per_A, s.current_bandwidth_hz)
        self.speed_pi = tune_speed_pi(nom.Jm_kgm2 + nom.Jl_kgm2, s.speed_bandwidth_hz, 1.0 / s.speed_loop_hz)
        if not s.speed_accel_feedforward:
            self.speed_pi = dataclasses.replace(self.speed_pi, ff_inertia_kgm2=0.0)
        # the payload sits at the arm's tip, twice the centre of mass's distance: the same torque as 2× its mass there
        gravity = Gravity(s.arm_mass_kg + 2.0 * payload_kg, s.arm_com_distance_m, math.radians(s.arm_start_deg), bench.gear.ratio)
        self.schedule = MotionSchedule()
        self.effects = JointEffects.from_settings(s, bench.gear.ratio)
        self._physics = JointSimulation(self.plant, self.speed_pi, gravity, bench.encoder.counts_per_rev,
                                        self.schedule, effects=self.effects)
        self.channels: tuple[str, ...] = tuple(bench.daq.channels)
        self.daq_rate_hz = float(bench.daq.rate_hz)
        self.chain = CurrentChain(s, self.channels, self.daq_rate_hz)
        self.drive_period_s = float(bench.drive.period_s)
        self.counts_per_rev = int(bench.encoder.counts_per_rev)
        self.dc_offset_A = np.array([s.current_dc_offsets_A.get(c, s.current_dc_offset_A) for c in self.channels])
        # A bench misconfigured on purpose ([sim] truth differing from the stated config, for `acq selftest`):
        # only what the sensors deliver changes (the drive's own loop and units stay consistent); all
        # default to "as stated", which leaves every other session unchanged.
        if s.phase_order is not None and len(s.phase_order) != len(self.channels):
            raise ConfigError(f"[sim] phase_order = {s.phase_order}: needs one phase per [daq] channels "
                              f"{list(self.channels)}")
        self._wired = tuple(s.phase_order or self.channels)  # the phase each DAQ channel really measures
        self._true_pole_pairs = s.pole_pairs or bench.motor.pole_pairs
        self._encoder_cpr = s.counts_per_rev or self.counts_per_rev
        self.host_t0_ns = time.monotonic_ns()
        self._lock = threading.RLock()
        self._cursors: dict[str, float] = {}
        self._noise_cache: dict[tuple[str, int, int], np.ndarray] = {}
        self._noise_seed = [s.seed % 2**64] + ([round(s.elapsed_s * 1e3)] if s.elapsed_s else [])  # new noise per window
        #: the robot program of this session (``motion = "external"``), else None; a simulated master reads it
        self.robot_program: WindowReference | None = program
        if program is not None:
            self.use_reference(program)

    # ---- truth -------------------------------------------------------------------------------------
    @property
    def truth(self) -> dict[str, Any]:
        """The true plant and clock values (SI units; keys carry the unit) for scoring the analysis.

        ``theta0_encoder_rad`` is the electrical offset relative to the encoder's count zero, i.e.
        i_a = −i_q·sin(p·counts·2π/cpr + theta0_encoder_rad) up to quantisation.
        """
        s, p = self.sim, self.plant
        f_a, f_r = p.resonances_hz()
        pp = self.bench.motor.pole_pairs
        theta0_enc = (s.theta0_rad - pp * 2 * math.pi * s.encoder_start_counts / self.counts_per_rev) % (2 * math.pi)
        with self._lock:
            motions = self.schedule.describe()
        return {
            "K_Nm_per_rad": p.K_Nm_per_rad, "Jm_kgm2": p.Jm_kgm2, "Jl_kgm2": p.Jl_kgm2,
            "C_Nms_per_rad": p.C_Nms_per_rad, "bm_Nms_per_rad": p.bm_Nms_per_rad, "bl_Nms_per_rad": p.bl_Nms_per_rad,
            "f_a_hz": f_a, "f_r_hz": f_r,
            "kt_Nm_per_A": p.kt_Nm_per_A, "pole_pairs": pp, "theta0_rad": s.theta0_rad,
            "theta0_encoder_rad": theta0_enc, "encoder_start_counts": s.encoder_start_counts,
            "current_dc_offset_A": dict(zip(self.channels, self.dc_offset_A.tolist())),
            "current_noise_A": s.current_noise_A,
            "daq_offset_s": s.daq_offset_s, "daq_drift_ppm": s.daq_drift_ppm, "daq_rate_hz": self.daq_rate_hz,
            "drive_period_s": self.drive_period_s, "counts_per_rev": self.counts_per_rev,
            "host_t0_ns": self.host_t0_ns, "host_latency_s": s.host_latency_s, "host_jitter_s": s.host_jitter_s,
            "speed_kp_Nms_per_rad": self.speed_pi.kp_Nms_per_rad, "speed_ki_Nm_per_rad": self.speed_pi.ki_Nm_per_rad,
            "speed_loop_hz": s.speed_loop_hz, "current_bandwidth_hz": s.current_bandwidth_hz,
            "motions": motions,
            "joint_effects": dataclasses.asdict(self.effects), "current_chain": self.chain.describe(),
        }

    # ---- clocks ------------------------------------------------------------------------------------
    def daq_time_s(self, indices: np.ndarray) -> np.ndarray:
        """Drive-clock time (s) of DAQ samples ``indices``: offset + n/rate·(1 + drift·1e-6)."""
        n = np.asarray(indices, dtype=np.float64)
        return self.sim.daq_offset_s + n / self.daq_rate_hz * (1.0 + self.sim.daq_drift_ppm * 1e-6)

    def host_ns_at(self, t_s: np.ndarray | float, jitter_s: np.ndarray | float = 0.0) -> np.ndarray:
        """Host monotonic time (int64 ns) at which something at drive time ``t_s`` (s) arrives."""
        t = np.asarray(t_s, dtype=np.float64) + self.sim.host_latency_s + np.abs(jitter_s)
        return self.host_t0_ns + np.round(t * 1e9).astype(np.int64)

    def host_jitter_s(self, stream: NoiseStream, first_index: int, count: int) -> np.ndarray:
        """Arrival jitter (s, ≥ 0) of items ``first_index …`` of a stream; a function of the index only."""
        return np.abs(self._normal(stream, first_index, count, 1)[0]) * self.sim.host_jitter_s

    def pace_until(self, host_ns: int, timeout_s: float | None = None) -> bool:
        """Real-time layer: sleep until ``time.monotonic_ns() >= host_ns``, at most ``timeout_s`` (s).

        Returns True if that host time is reached. Never sleeps when not real-time.
        """
        if not self.realtime:
            return True
        wait_s = (host_ns - time.monotonic_ns()) * 1e-9
        if timeout_s is not None and wait_s > timeout_s:
            time.sleep(max(timeout_s, 0.0))
            return False
        if wait_s > 0:
            time.sleep(wait_s)
        return True

    # ---- motion ------------------------------------------------------------------------------------
    def start_motion(self, profile: Profile, t_start_s: float) -> float:
        """Start ``profile`` at drive time ``t_start_s`` (s), or at the simulated frontier if that is
        later (the simulated past cannot change). Returns the actual start time, s."""
        with self._lock:
            return self.schedule.start(profile, max(t_start_s, self._physics.t_end_s))

    def stop_motion(self, t_s: float) -> float | None:
        """Ramp the reference to rest from drive time ``t_s`` (s, or the frontier if later) at the
        profile's deceleration. Returns the time the reference reaches zero, None if not moving."""
        with self._lock:
            return self.schedule.stop(max(t_s, self._physics.t_end_s))

    def use_reference(self, source: Any) -> None:
        """Take the speed reference from ``source`` instead of :attr:`schedule` (e.g. a simulated drive's
        own trajectory generator, :mod:`drivers.sim.pp_generator`): ``source.reference(t_s)`` returns
        (speed rad/s, accel rad/s²) and must not change for times it was already asked for. After this
        :meth:`start_motion` / :meth:`stop_motion` no longer move the joint."""
        with self._lock:
            self._physics.schedule = source

    def exclusive(self) -> threading.RLock:
        """The bench's lock, for a device to hold over a whole read (``with sim.exclusive(): ...``; the methods
        below take it again at no cost). The DAQ's and the drive's reader threads then compute their blocks one
        after the other instead of side by side (each numpy call that releases the GIL let the other thread run
        its Python meanwhile on the other core, for more CPU per sample). Measured with bench/record_throughput.py's
        rates (3 × 51.2 kS/s + 4 kHz, one BLAS thread, M samples per CPU second, medians of interleaved runs): with
        the cores free enough for both readers to run at once (load 2.5, 8 runs) the bench read by a thread per
        stream 4.49 → 5.73 (read in one thread: 5.82) and the recorder 4.01 → 5.05; at load 4 (16 runs, ABBA) the
        recorder 4.54 → 4.78, its readers 5.03 → 5.27, the floor unchanged (5.33, 5.36). Same samples (they depend
        on indices only). Never held while pacing to the host clock."""
        return self._lock

    def set_torque_limit(self, torque_Nm: float) -> None:
        """Clamp the speed loop's torque reference to ±``torque_Nm`` (N·m, motor side) from the simulated frontier
        on (a simulated drive told 0x6072 max torque; the past already computed stays as it was)."""
        with self._lock:
            self._physics.torque_limit_Nm = torque_Nm

    def torque_limited_at(self, t_drive_s: float) -> bool:
        """Whether the torque limit clamps the speed loop at drive time ``t_drive_s`` (s)."""
        with self._lock:
            self._physics.advance_to(t_drive_s)
            return bool(self._physics.limited_at(np.array([t_drive_s]))[0])

    # ---- history -----------------------------------------------------------------------------------
    def hold_history(self, consumer: str, from_t_s: float) -> None:
        """Declare that ``consumer`` will still read states at drive times ≥ ``from_t_s`` (s)."""
        with self._lock:
            self._cursors[consumer] = from_t_s - LATCH_CLIP * self.drive_period_s * (self.sim.sync_jitter_s > 0)
            if not self.keep_history:
                self._physics.forget_before(min(self._cursors.values()))

    def release_history(self, consumer: str) -> None:
        """``consumer`` reads no more (its stream stopped)."""
        with self._lock:
            self._cursors.pop(consumer, None)

    # ---- measurements ------------------------------------------------------------------------------
    def _states(self, t_s: np.ndarray) -> np.ndarray:
        with self._lock:
            self._physics.advance_to(float(np.max(t_s, initial=0.0)))
            return self._physics.states_at(t_s)

    def true_state_at(self, t_drive_s: np.ndarray | float) -> dict[str, np.ndarray]:
        """True joint state at drive times ``t_drive_s`` (s) (older history needs ``keep_history``).

        Returns ``iq_A`` (A), ``torque_Nm`` (electromagnetic, k_t·i_q, N·m), ``theta_m_rad``,
        ``omega_m_rad_s``, ``theta_l_rad``, ``omega_l_rad_s`` (motor side, rad and rad/s).
        """
        t = np.asarray(t_drive_s, dtype=np.float64)
        x = self._states(t.ravel())
        shape = t.shape
        return {
            "iq_A": x[:, 4].reshape(shape), "torque_Nm": (self.plant.kt_Nm_per_A * x[:, 4]).reshape(shape),
            "theta_m_rad": x[:, 0].reshape(shape), "omega_m_rad_s": x[:, 1].reshape(shape),
            "theta_l_rad": x[:, 2].reshape(shape), "omega_l_rad_s": x[:, 3].reshape(shape),
        }

    def _encoder_rad(self, theta_m_rad: np.ndarray) -> np.ndarray:
        """The motor angle as the drive's encoder reads it (rad): with its eccentricity, if any. The drive commutates
        on it, so the phase currents follow it too."""
        ecc = self.effects.eccentricity
        return theta_m_rad if ecc is None else ecc.read_rad(theta_m_rad)

    def current_samples(self, first_index: int, count: int) -> np.ndarray:
        """Phase currents (A), shape (n_channels, count), of DAQ samples ``first_index …``.

        i_x = −i_q·sin(p·θ_m + θ0 + shift_x) + dc_x + noise, shift = 0, −2π/3, +2π/3 for a, b, c.
        """
        if self.chain.active:
            return self._measured_currents(first_index, count)
        x = self._states(self.daq_time_s(np.arange(first_index, first_index + count)))
        theta_e = self._true_pole_pairs * self._encoder_rad(x[:, 0]) + self.sim.theta0_rad
        shifts = np.array([PHASE_SHIFT_RAD[c] for c in self._wired])[:, None]
        clean = -x[:, 4][None, :] * np.sin(theta_e[None, :] + shifts) * self.sim.current_sensor_gain
        noise = self._normal("current", first_index, count, len(self.channels)) * self.sim.current_noise_A
        return clean + self.dc_offset_A[:, None] + noise

    def _measured_currents(self, first_index: int, count: int) -> np.ndarray:
        """Phase currents through the measurement chain's effects (:mod:`drivers.sim.measurement`)."""
        t = self.daq_time_s(self.chain.analog_indices(first_index, count))
        x = self._states(t)
        angle = (self._true_pole_pairs * self._encoder_rad(x[:, 0]) + self.sim.theta0_rad)[None, :] + np.array(
            [PHASE_SHIFT_RAD[c] for c in self._wired])[:, None]
        torque_current = -x[:, 4][None, :] * np.sin(angle) * self.sim.current_sensor_gain
        analog = self.chain.analog(t, torque_current, angle, x[:, 1]) + self.dc_offset_A[:, None]
        noise = self._normal("current", first_index, count, len(self.channels)) * self.sim.current_noise_A
        return self.chain.digitise(self.chain.acquire(analog) + noise)

    def daq_history_from_s(self, next_index: int) -> float:
        """Earliest drive time (s) that DAQ samples from ``next_index`` on depend on (the AA filter looks back)."""
        return float(self.daq_time_s(next_index - self.chain.lookback_samples))

    def latch_times_s(self, first_cycle: int, count: int) -> np.ndarray:
        """Drive time (s) at which the drive latches the position of cycles ``first_cycle …``.

        k·T, or with ``sync_jitter_s`` the instant SYNC k arrives: k·T + δ_k, δ_k ~ N(0, sync_jitter_s)
        clipped to ±``LATCH_CLIP``·T (a function of the cycle and the seed only).
        """
        t = np.arange(first_cycle, first_cycle + count) * self.drive_period_s
        if self.sim.sync_jitter_s == 0:
            return t
        clip = LATCH_CLIP * self.drive_period_s
        return t + np.clip(self._normal("sync_latch", first_cycle, count, 1)[0] * self.sim.sync_jitter_s, -clip, clip)

    def stamp_times_s(self, first_cycle: int, count: int) -> np.ndarray:
        """The drive's own time stamp (s) of cycles ``first_cycle …``: the latch instant, or k·T without
        ``drive_time_stamps``."""
        if self.sim.drive_time_stamps:
            return self.latch_times_s(first_cycle, count)
        return np.arange(first_cycle, first_cycle + count) * self.drive_period_s

    def velocity_demand_rad_s(self, first_cycle: int, count: int) -> np.ndarray:
        """The drive's velocity demand (CiA 402 0x606B) at drive cycles ``first_cycle …`` (at k·T), rad/s of the motor:
        the speed reference the speed loop acts on, held from its last control instant at or before k·T — the very
        values the simulated physics followed (it is advanced there first, so the reference answers nothing new)."""
        t = np.arange(first_cycle, first_cycle + count) * self.drive_period_s
        loop_s = self.speed_pi.period_s
        with self._lock:
            self._physics.advance_to(float(np.max(t, initial=0.0)))
            return self._physics.schedule.reference(np.floor(t / loop_s + 1e-9) * loop_s)[0]

    def encoder_counts(self, first_cycle: int, count: int) -> np.ndarray:
        """Unwrapped position (int64 counts) latched at drive cycles ``first_cycle …`` (at
        :meth:`latch_times_s`): floor(θ_m/2π·cpr) + start (θ_m as the encoder reads it: with its eccentricity)."""
        t = self.latch_times_s(first_cycle, count)
        theta_enc = self.sim.encoder_direction * self._encoder_rad(self._states(t)[:, 0])  # the encoder's true counting direction and resolution
        return np.floor(theta_enc / (2 * np.pi) * self._encoder_cpr).astype(np.int64) + self.sim.encoder_start_counts

    def encoder_register(self, first_cycle: int, count: int) -> np.ndarray:
        """The drive's position register (int32 counts, wraps like CiA 402 0x6064) at drive cycles."""
        return _int32(self.encoder_counts(first_cycle, count))

    def _normal(self, stream: NoiseStream, first_index: int, count: int, rows: int) -> np.ndarray:
        """Standard normal draws (rows, count) for items ``first_index …``, fixed by (seed, stream, index)."""
        out = np.empty((rows, count))
        c0, c1 = first_index // _NOISE_CHUNK, (first_index + count - 1) // _NOISE_CHUNK
        pos = 0
        for c in range(c0, c1 + 1):
            block = self._noise_chunk(stream, rows, c)
            lo = max(first_index - c * _NOISE_CHUNK, 0)
            hi = min(first_index + count - c * _NOISE_CHUNK, _NOISE_CHUNK)
            out[:, pos:pos + hi - lo] = block[:, lo:hi]
            pos += hi - lo
        return out

    def _noise_chunk(self, stream: NoiseStream, rows: int, chunk: int) -> np.ndarray:
        key = (stream, rows, chunk)
        with self._lock:
            block = self._noise_cache.get(key)
            if block is None:
                seq = np.random.SeedSequence([*self._noise_seed, _STREAM_IDS[stream], rows, chunk])
                block = np.random.default_rng(seq).standard_normal((rows, _NOISE_CHUNK))
                # keep this chunk and its predecessor per (stream, rows): reads move forwards
                self._noise_cache = {k: v for k, v in self._noise_cache.items()
                                     if k[:2] != key[:2] or k[2] == chunk - 1}
                self._noise_cache[key] = block
            return block
