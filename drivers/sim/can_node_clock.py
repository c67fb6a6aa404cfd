"""The simulated CANopen drive's clock, and what it measures at its present cycle.

One drive cycle per SYNC received (the first SYNC is the cycle the host clock says it is); before the first SYNC
the cycle, and after SYNC stops the drive's time, follow the host clock. At its cycle the drive measures the
bench's int32 position register (0x6064), velocity (0x606C) and velocity demand (0x606B, the speed reference its
loop follows: :meth:`~drivers.sim.bench.SimBench.velocity_demand_rad_s`), and the high-resolution time stamp 0x1013
(µs of the drive clock, wrapping at 2³²) of the instant the position was latched: k·T, or the SYNC's arrival with
``[sim] sync_jitter_s`` (drawn from the bench's seed — the virtual bus's own timing is not reproducible, see
:meth:`~drivers.sim.bench.SimBench.latch_times_s`). Used by :class:`drivers.sim.can_node.SimCanNode` for its SDO
answers and TPDOs.
"""

from __future__ import annotations

import math
import time

import numpy as np

from drivers.sim.bench import SimBench

CACHE_CYCLES = 50


class DriveClock:
    """The drive clock on ``bench``, one cycle of ``period_s`` (s) per SYNC, and the bench's measurements at it."""

    def __init__(self, bench: SimBench, period_s: float) -> None:
        self._bench, self._period_s = bench, period_s
        self.rad_per_count = 2 * math.pi / bench.counts_per_rev
        self._start_counts = bench.sim.encoder_start_counts
        self.cycle: int | None = None  # the last SYNC's cycle (None: no SYNC yet)
        self.first_cycle: int | None = None  # drive cycle of the first SYNC (SYNC index 0)
        self._cache_first = 0
        self._cache_counts = np.zeros(0, dtype=np.int32)
        self._cache_omega = np.zeros(0)
        self._cache_demand = np.zeros(0)
        self._cache_stamp_us = np.zeros(0, dtype=np.int64)

    def tick(self) -> int:
        """A SYNC received: the next cycle (the first SYNC's is the cycle the host clock says it is)."""
        if self.cycle is None:
            self.cycle = self.first_cycle = self.now_cycle()
        else:
            self.cycle += 1
        return self.cycle

    def now_cycle(self) -> int:
        """The present cycle: the last SYNC's, before the first SYNC the host clock's."""
        if self.cycle is not None:
            return self.cycle
        t_s = (time.monotonic_ns() - self._bench.host_t0_ns) * 1e-9 - self._bench.sim.host_latency_s
        return max(0, int(t_s / self._period_s))

    def now_s(self) -> float:
        """The drive's own time, s: its SYNC cycle, running on by the host clock when SYNC stops."""
        t_host_s = (time.monotonic_ns() - self._bench.host_t0_ns) * 1e-9 - self._bench.sim.host_latency_s
        return max(self.now_cycle() * self._period_s, t_host_s)

    def sample(self) -> tuple[int, float, int, float]:
        """Position register (counts), speed (rad/s), 0x1013 time stamp (µs) and velocity demand (rad/s) at the
        present cycle, from a block computed ahead (one vectorised bench query per ``CACHE_CYCLES``: a query per
        SYNC would cost the bus its timing)."""
        cycle = self.now_cycle()
        i = cycle - self._cache_first
        if not 0 <= i < len(self._cache_counts):
            self._cache_first, i = cycle, 0
            self._cache_counts = self._bench.encoder_register(cycle, CACHE_CYCLES)
            t_s = (cycle + np.arange(CACHE_CYCLES)) * self._period_s
            self._cache_omega = self._bench.true_state_at(t_s)["omega_m_rad_s"]
            self._cache_stamp_us = np.round(self._bench.latch_times_s(cycle, CACHE_CYCLES) * 1e6).astype(np.int64)
            self._cache_demand = self._bench.velocity_demand_rad_s(cycle, CACHE_CYCLES)
        return (int(self._cache_counts[i]), float(self._cache_omega[i]), int(self._cache_stamp_us[i]) % 2**32,
                float(self._cache_demand[i]))

    def theta_rad(self) -> float:
        """The motor's true angle now, rad."""
        return float(self._bench.true_state_at(self.now_s())["theta_m_rad"])

    def register(self, theta_rad: float) -> int:
        """The int32 position register (counts) at motor angle ``theta_rad`` (rad)."""
        counts = math.floor(theta_rad / self.rad_per_count) + self._start_counts
        return (counts + 2**31) % 2**32 - 2**31
