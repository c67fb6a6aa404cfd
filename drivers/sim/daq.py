"""The simulated DAQ: a :class:`drivers.base.CurrentSource` reading phase currents from a SimBench.

Blocks of round(``block_s``·rate) samples on the DAQ's own clock (offset and ppm drift against the
drive, see :mod:`drivers.sim.bench`). A block's ``host_ns`` is the host arrival time of its last sample;
in real time a read returns no earlier than that, in ``--fast`` mode at once.
"""

from __future__ import annotations

from drivers.base import CurrentBlock, CurrentSourceInfo, StreamEvent
from drivers.config import Bench
from drivers.sim.bench import SimBench



class SimCurrentSource:
    """Phase currents from the simulated bench (implements :class:`drivers.base.CurrentSource`)."""

    def __init__(self, bench: Bench, sim_bench: SimBench) -> None:
        self._sim = sim_bench
        self._block = max(1, round(bench.daq.block_s * sim_bench.daq_rate_hz))
        self._next = 0
        self._last_host_ns = 0
        self._running = False
        self._consumer = f"sim-daq@{id(self):x}"  # its history cursor in the SimBench
        self._sim.hold_history(self._consumer, self._sim.daq_history_from_s(self._next))

    def start(self) -> CurrentSourceInfo:
        """Start acquiring at sample 0 (drive time ``daq_offset_s``)."""
        self._running = True
        return CurrentSourceInfo(rate_hz=self._sim.daq_rate_hz, channels=self._sim.channels, device="sim-daq")

    def read(self, timeout_s: float) -> CurrentBlock | None:
        """The next block, or None if it has not arrived within ``timeout_s`` (s) or the DAQ is stopped."""
        if not self._running:
            return None
        first, n = self._next, self._block
        jitter_s = self._sim.host_jitter_s("daq_host", first // n, 1)
        host_ns = max(int(self._sim.host_ns_at(self._sim.daq_time_s(first + n - 1), jitter_s)[0]), self._last_host_ns)
        if not self._sim.pace_until(host_ns, timeout_s):
            return None
        with self._sim.exclusive():
            current_a = self._sim.current_samples(first, n)
            self._next, self._last_host_ns = first + n, host_ns
            self._sim.hold_history(self._consumer, self._sim.daq_history_from_s(self._next))
        return CurrentBlock(first_index=first, current_a=current_a, host_ns=host_ns)

    def stop(self) -> None:
        """Stop acquiring. Idempotent."""
        self._running = False
        self._sim.release_history(self._consumer)

    def events(self) -> list[StreamEvent]:
        """Nothing goes wrong on the simulated card."""
        return []


def open_current_source(bench: Bench, sim_bench: SimBench | None, fast: bool) -> SimCurrentSource:
    """Registry factory: the simulated DAQ on ``sim_bench`` (pacing is the SimBench's ``realtime``)."""
    if sim_bench is None:
        sim_bench = SimBench(bench, realtime=not fast)
    return SimCurrentSource(bench, sim_bench)
