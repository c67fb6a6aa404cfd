"""The simulated servo drive: a :class:`drivers.base.Drive` streaming the encoder of a SimBench.

One frame per drive cycle k (t = k·``period_s``), index = k, position = the unwrapped encoder counts
latched at k·period (or, with ``sim.sync_jitter_s``, when SYNC k arrives), ``drive_time_s`` = the drive's
time stamp of that latch (:meth:`drivers.sim.bench.SimBench.stamp_times_s`), ``velocity_demand_counts_per_s`` = the
speed reference the drive's loop acts on at k·T (:meth:`~drivers.sim.bench.SimBench.velocity_demand_rad_s`, in the
encoder's counts per second). Frames arrive at the host
in batches of ~10 ms, each with its own jittered ``host_ns``; frames listed in ``sim.drop_encoder_frames``
as (first_cycle, count) never arrive (the recorder finds the gap from the index). ``start_motion`` begins
the triangle ``sim.pre_roll_s`` after the drive's present cycle; ``stop_motion`` ramps to rest at the
profile's deceleration.
"""

from __future__ import annotations

import time

import numpy as np

from drivers.base import DriveInfo, EncoderBlock, StreamEvent
from drivers.config import Bench, Profile
from drivers.sim.bench import SimBench

BATCH_S = 0.01
MAX_CATCH_UP_BATCHES = 100


class SimDrive:
    """Encoder stream and motion of the simulated bench (implements :class:`drivers.base.Drive`)."""

    def __init__(self, bench: Bench, sim_bench: SimBench) -> None:
        self._sim = sim_bench
        self._period_s = sim_bench.drive_period_s
        self._batch = max(1, round(BATCH_S / self._period_s))
        self._drops = [(int(a), int(a) + int(n)) for a, n in sim_bench.sim.drop_encoder_frames]
        self._next = 0
        self._last_host_ns = 0
        self._running = False
        self._consumer = f"sim-drive@{id(self):x}"  # its history cursor in the SimBench
        self._sim.hold_history(self._consumer, self._next * self._period_s)

    def start(self) -> DriveInfo:
        """Start streaming from cycle 0 (the motor rests)."""
        self._running = True
        return DriveInfo(period_s=self._period_s, counts_per_rev=self._sim.counts_per_rev, transport="sim",
                         timestamp_kind="drive_cycle", device="sim-drive")

    def _now_cycle(self) -> int:
        """The drive's present cycle: the last one streamed, or the host clock's if that is later."""
        cycle = max(self._next - 1, 0)
        if self._sim.realtime:
            t_s = (time.monotonic_ns() - self._sim.host_t0_ns) * 1e-9 - self._sim.sim.host_latency_s
            cycle = max(cycle, int(t_s / self._period_s))
        return cycle

    def start_motion(self, profile: Profile) -> None:
        """Start the triangle ``pre_roll_s`` after the present cycle."""
        self._sim.start_motion(profile, self._now_cycle() * self._period_s + self._sim.sim.pre_roll_s)

    def stop_motion(self) -> None:
        """Ramp the speed reference to rest from the present cycle. Idempotent."""
        self._sim.stop_motion(self._now_cycle() * self._period_s)

    def _batches_due(self) -> int:
        if not self._sim.realtime:
            return 1
        arrived = self._now_cycle() - self._next + 1
        return int(np.clip(arrived // self._batch, 1, MAX_CATCH_UP_BATCHES))

    def read(self, timeout_s: float) -> EncoderBlock | None:
        """Frames received since the last read (≥ one batch), or None within ``timeout_s`` (s)."""
        if not self._running:
            return None
        first, n = self._next, self._batch * self._batches_due()
        cycles = np.arange(first, first + n, dtype=np.int64)
        host_ns = self._sim.host_ns_at(cycles * self._period_s, self._sim.host_jitter_s("drive_host", first, n))
        host_ns = np.maximum.accumulate(np.maximum(host_ns, self._last_host_ns))
        if not self._sim.pace_until(int(host_ns[-1]), timeout_s):
            return None
        with self._sim.exclusive():
            counts = self._sim.encoder_counts(first, n)
            demand = self._sim.velocity_demand_rad_s(first, n) * (self._sim.counts_per_rev / (2.0 * np.pi))
            drive_time_s = self._sim.stamp_times_s(first, n)
            self._next, self._last_host_ns = first + n, int(host_ns[-1])
            self._sim.hold_history(self._consumer, self._next * self._period_s)
        keep = np.ones(n, dtype=bool)
        for a, b in self._drops:
            keep[max(a - first, 0):max(b - first, 0)] = False
        if not keep.any():
            return None
        return EncoderBlock(index=cycles[keep], position_counts=counts[keep], host_ns=host_ns[keep],
                            drive_time_s=drive_time_s[keep],
                            velocity_demand_counts_per_s=demand[keep])

    def machine_tags(self) -> dict[str, float]:
        """What the simulated machine knows of this session: the payload (kg) of the robot program's cycle it starts
        in (``motion = "external"``), else nothing."""
        program = self._sim.robot_program
        return {} if program is None else {"payload_kg": round(program.payload_kg(), 3)}

    def stop(self) -> None:
        """Stop streaming (brings the motor to rest first). Idempotent."""
        if self._running:
            self.stop_motion()
        self._running = False
        self._sim.release_history(self._consumer)

    def events(self) -> list[StreamEvent]:
        """Nothing goes wrong on the simulated drive."""
        return []


def open_drive(bench: Bench, sim_bench: SimBench | None, fast: bool) -> SimDrive:
    """Registry factory: the simulated drive on ``sim_bench`` (pacing is the SimBench's ``realtime``)."""
    if sim_bench is None:
        sim_bench = SimBench(bench, realtime=not fast)
    return SimDrive(bench, sim_bench)
