"""NI DAQ current source via ``nidaqmx``: continuous hardware-timed AI, nothing lost, errors said plainly.

``nidaqmx`` is imported only when this adapter is opened, so benches without NI hardware never
need the driver. One task holds one AI channel per phase (voltage channels for voltage-output sensors,
current channels for current-output sensors), with IEPE excitation and AC coupling where the config
asks for them, sampled CONTINUOUSLY on the card's clock into a host buffer of ``buffer_s`` seconds.
The rate is read back after timing is configured: the card's **coerced** rate is what the session
stores. Each :meth:`NidaqCurrentSource.read` fetches ``block_s`` of samples into one preallocated
array with ``AnalogMultiChannelReader.read_many_sample`` and copies them out as a
:class:`~drivers.base.CurrentBlock` with its cumulative first sample index and host arrival stamp.

Sensor scaling is applied here (one multiply per block) rather than through a DAQmx custom scale: the
card keeps its range in volts (or amperes) as its data sheet states them, the scaling is visible in one
place and testable without the driver, and no scale object has to be created in, or cleaned out of,
the driver's configuration.

Errors: no driver → :data:`DRIVER_MISSING`; a missing device or invalid channel names both, with
what the machine has; a buffer overflow (:data:`OVERFLOW_ADVICE`) ends the recording with an event
carrying the error code and the samples read, and a message saying what to change.
"""

from __future__ import annotations

import importlib
import math
import threading
import time
from collections.abc import Callable
from types import ModuleType
from typing import Any

import numpy as np

from drivers.base import CurrentBlock, CurrentSourceInfo, StreamEvent
from drivers.config import Bench, DaqNidaqmx
from acqcore.errors import ConfigError, DeviceError

DRIVER_MISSING = "NI-DAQmx driver not installed — install it or use configs/benches/sim.toml"
#: How to install the driver: the nidaqmx package's own installer (Windows, Linux) or NI's runtime.
INSTALL_DRIVER = ("install the NI-DAQmx driver: python -m nidaqmx installdriver (Windows, Linux), or the NI-DAQmx "
                  "runtime from ni.com")
SAMPLES_NOT_YET_AVAILABLE = -200284
#: DAQmx overflow codes → (what happened, what to change). ``{buffer_s}``/``{block_s}`` are filled in.
OVERFLOW_ADVICE: dict[int, tuple[str, str]] = {
    -200279: ("the host buffer was overwritten before it was read",
              "raise [daq] buffer_s (now {buffer_s:g} s) or block_s (now {block_s:g} s), or lower rate_hz"),
    -200361: ("the device's onboard memory overflowed (the bus did not keep up)",
              "lower [daq] rate_hz or the channel count, or give the device a bus of its own; raise buffer_s "
              "(now {buffer_s:g} s) and block_s (now {block_s:g} s) so the host drains it in larger reads"),
    -200714: ("the driver could not move data to the host fast enough",
              "raise [daq] buffer_s (now {buffer_s:g} s) and block_s (now {block_s:g} s), or lower rate_hz"),
}
_TERMINALS = {"default": "DEFAULT", "differential": "DIFF", "pseudo_differential": "PSEUDO_DIFF",
              "rse": "RSE", "nrse": "NRSE"}


def import_nidaqmx() -> ModuleType:
    """Import ``nidaqmx`` and the submodules this adapter uses (the Python package, not the driver)."""
    try:
        for sub in ("constants", "errors", "stream_readers", "system"):
            importlib.import_module(f"nidaqmx.{sub}")
    except ImportError as e:
        raise DeviceError(f"the nidaqmx Python package is missing ({e}) — pip install nidaqmx, "
                          "or use configs/benches/sim.toml") from None
    return importlib.import_module("nidaqmx")


def first_line(error: Exception) -> str:
    """The first non-empty line of a DAQmx error text (its extended info follows on later lines)."""
    return next((line.strip() for line in str(error).splitlines() if line.strip()), type(error).__name__)


class NidaqCurrentSource:
    """A :class:`~drivers.base.CurrentSource` on an NI-DAQmx device.

    Parameters
    ----------
    settings : DaqNidaqmx
        The bench's ``[daq]`` section.
    lib : module, optional
        The ``nidaqmx`` package (or a stand-in with its API); imported lazily when omitted.

    Raises
    ------
    DeviceError
        If the NI-DAQmx driver is not installed.

    The rules between keys (channels vs physical_channels, block_s vs buffer_s) are validators of
    :class:`drivers.config.DaqNidaqmx`.
    """

    def __init__(self, settings: DaqNidaqmx, lib: ModuleType | None = None) -> None:
        self.settings = settings
        self.nidaqmx = lib if lib is not None else import_nidaqmx()
        try:
            self.nidaqmx.system.System.local().driver_version  # noqa: B018 - fails fast without the driver
        except self.nidaqmx.errors.DaqNotFoundError:
            raise DeviceError(DRIVER_MISSING) from None
        self._task: Any = None
        self._reader: Any = None
        self._buffer = np.zeros((0, 0))
        self._rate_hz = 0.0
        self._next_index = 0
        self._started = False
        self._events: list[StreamEvent] = []
        self._events_lock = threading.Lock()  # read() runs in the recorder's reader thread, events() in others
        scale = settings.sensor_A_per_V if settings.measurement == "voltage" else settings.sensor_A_per_A
        self._scale_A_per_unit = float(scale)

    def start(self) -> CurrentSourceInfo:
        """Create the task, configure channels and timing, start it; return the coerced settings.

        Raises
        ------
        DeviceError
            Driver missing, device not found, channel invalid or a setting refused (named).
        """
        s, lib = self.settings, self.nidaqmx
        try:
            self._task = lib.Task()
            for phys in s.physical_channels:
                self._add_channel(phys)
            timing = self._task.timing
            timing.cfg_samp_clk_timing(s.rate_hz, sample_mode=lib.constants.AcquisitionType.CONTINUOUS,
                                       samps_per_chan=math.ceil(s.buffer_s * s.rate_hz))
            self._task.control(lib.constants.TaskMode.TASK_COMMIT)  # DAQmx may coerce the rate only when verifying
            self._rate_hz = float(timing.samp_clk_rate)
            self._task.in_stream.input_buf_size = math.ceil(s.buffer_s * self._rate_hz)
            block = max(1, round(s.block_s * self._rate_hz))
            self._buffer = np.zeros((len(s.physical_channels), block), dtype=np.float64)
            self._reader = lib.stream_readers.AnalogMultiChannelReader(self._task.in_stream)
            device = self._describe_devices()
            self._task.start()
            self._started = True
        except lib.errors.DaqNotFoundError:
            self.stop()
            raise DeviceError(DRIVER_MISSING) from None
        except lib.errors.DaqError as e:
            self.stop()
            raise DeviceError(f"NI-DAQmx {', '.join(s.physical_channels)}: {first_line(e)} "
                              f"(DAQmx error {e.error_code})") from None
        except DeviceError:
            self.stop()
            raise
        return CurrentSourceInfo(rate_hz=self._rate_hz, channels=tuple(s.channels), device=device)

    def _add_channel(self, phys: str) -> None:
        """Add one AI channel; name the device and channel (and what exists) if DAQmx refuses it."""
        s, c = self.settings, self.nidaqmx.constants
        terminal = getattr(c.TerminalConfiguration, _TERMINALS[s.terminal])
        ai = self._task.ai_channels
        try:
            if s.measurement == "voltage":
                chan = ai.add_ai_voltage_chan(phys, terminal_config=terminal, min_val=-s.range_V, max_val=s.range_V,
                                              units=c.VoltageUnits.VOLTS)
            else:
                chan = ai.add_ai_current_chan(phys, terminal_config=terminal, min_val=-s.range_A, max_val=s.range_A,
                                              units=c.CurrentUnits.AMPS)
        except self.nidaqmx.errors.DaqError as e:
            raise self._channel_error(phys, e) from None
        try:
            if s.iepe_excitation_A > 0:
                chan.ai_excit_src = c.ExcitationSource.INTERNAL
                chan.ai_excit_val = s.iepe_excitation_A
            if s.coupling == "ac":
                chan.ai_coupling = c.Coupling.AC
        except self.nidaqmx.errors.DaqError as e:
            raise DeviceError(f"NI-DAQmx channel {phys} refused [daq] iepe_excitation_A = {s.iepe_excitation_A:g}, "
                              f"coupling = {s.coupling!r}: {first_line(e)} (DAQmx error {e.error_code})") from None

    def _channel_error(self, phys: str, error: Any) -> DeviceError:
        """Name the device and channel, and list what the machine has instead."""
        dev = phys.split("/")[0]
        code = error.error_code
        try:
            devices = {d.name.lower(): d for d in self.nidaqmx.system.System.local().devices}
            if dev.lower() not in devices:
                present = ", ".join(d.name for d in devices.values()) or "none"
                return DeviceError(f"NI-DAQmx device {dev!r} not found (channel {phys!r} in [daq] "
                                   f"physical_channels; devices present: {present}; DAQmx error {code})")
            found = devices[dev.lower()]
            chans = ", ".join(ch.name for ch in found.ai_physical_chans) or "none"
            return DeviceError(f"NI-DAQmx channel {phys!r} is invalid on device {dev!r} ({found.product_type}): "
                               f"{first_line(error)} (DAQmx error {code}; its AI channels: {chans})")
        except self.nidaqmx.errors.DaqError:
            return DeviceError(f"NI-DAQmx channel {phys!r} on device {dev!r}: {first_line(error)} (DAQmx error {code})")

    def _describe_devices(self) -> str:
        """``Dev1 (NI 9234): i_a=Dev1/ai0`` — device, product and the wiring of phases to channels."""
        devices = ", ".join(f"{d.name} ({d.product_type})" for d in self._task.devices)
        wiring = " ".join(f"{n}={p}" for n, p in zip(self.settings.channels, self.settings.physical_channels))
        return f"{devices}: {wiring}"

    def read(self, timeout_s: float) -> CurrentBlock | None:
        """Read the next ``block_s`` of samples (fewer if ``timeout_s`` ran out first), in A.

        Raises
        ------
        DeviceError
            On a buffer overflow (an event with the code and the samples read is queued first) or any
            other DAQmx read error.
        """
        errors = self.nidaqmx.errors
        try:
            got = self._reader.read_many_sample(self._buffer, self._buffer.shape[1], timeout_s)
        except errors.DaqReadError as e:
            if e.error_code != SAMPLES_NOT_YET_AVAILABLE:
                raise self._read_error(e) from None
            got = e.samps_per_chan_read  # the samples read before the timeout are consumed: keep them
        except errors.DaqError as e:
            raise self._read_error(e) from None
        host_ns = time.monotonic_ns()
        if got == 0:
            return None
        block = CurrentBlock(self._next_index, self._buffer[:, :got] * self._scale_A_per_unit, host_ns)
        self._next_index += got
        return block

    def _read_error(self, error: Any) -> DeviceError:
        code, s = error.error_code, self.settings
        read = self._next_index
        at = f"after {read} samples per channel read ({read / self._rate_hz:.3f} s)"
        if code in OVERFLOW_ADVICE:
            what, advice = OVERFLOW_ADVICE[code]
            advice = advice.format(buffer_s=s.buffer_s, block_s=s.block_s)
            self._add_event(StreamEvent(time.monotonic_ns(), "current", "error",
                                            f"DAQmx error {code}: {what}; {read} samples per channel read"))
            return DeviceError(f"NI-DAQmx buffer overflow {at}, DAQmx error {code}: {what} — {advice}")
        self._add_event(StreamEvent(time.monotonic_ns(), "current", "error",
                                        f"DAQmx error {code}; {read} samples per channel read"))
        return DeviceError(f"NI-DAQmx read failed {at}: {first_line(error)} (DAQmx error {code})")

    def stop(self) -> None:
        """Cross-check the card's sample count against the samples read, stop and release. Idempotent."""
        task, self._task = self._task, None
        if task is None:
            return
        started, self._started = self._started, False
        if started:
            self._guarded("sample count check", lambda: self._cross_check(
                int(task.in_stream.total_samp_per_chan_acquired)))
        self._guarded("stop", task.stop)
        self._guarded("close", task.close)

    def _guarded(self, step: str, action: Callable[[], None]) -> None:
        """Run one stop step; a DAQmx error (after an overflow DAQmx repeats it) becomes an event."""
        try:
            action()
        except self.nidaqmx.errors.DaqError as e:
            self._add_event(StreamEvent(time.monotonic_ns(), "current", "warning",
                                            f"at stop ({step}): {first_line(e)} (DAQmx error {e.error_code})"))

    def _cross_check(self, acquired: int) -> None:
        """Compare the card's count with ours: read ≤ acquired ≤ read + buffer, else an event."""
        read, buffered = self._next_index, math.ceil(self.settings.buffer_s * self._rate_hz)
        unread = acquired - read
        now = time.monotonic_ns()
        if unread < 0:
            self._add_event(StreamEvent(now, "current", "error", f"sample count mismatch at stop: card acquired "
                                            f"{acquired} samples per channel, {read} read"))
        elif unread > buffered:
            self._add_event(StreamEvent(now, "current", "gap", f"sample count mismatch at stop: card acquired "
                                            f"{acquired} samples per channel, {read} read, {unread} unread exceed "
                                            f"the {buffered}-sample buffer"))
        else:
            self._add_event(StreamEvent(now, "current", "info", f"card acquired {acquired} samples per channel, "
                                            f"{read} read, {unread} left in the buffer at stop"))

    def _add_event(self, event: StreamEvent) -> None:
        with self._events_lock:
            self._events.append(event)

    def events(self) -> list[StreamEvent]:
        """Return and forget the events noticed since the last call."""
        with self._events_lock:
            events, self._events = self._events, []
        return events


def open_current_source(bench: Bench, sim_bench: object | None, fast: bool) -> NidaqCurrentSource:
    """Registry factory: the NI-DAQmx current source of ``bench`` (``sim_bench`` and ``fast`` unused)."""
    if not isinstance(bench.daq, DaqNidaqmx):
        raise ConfigError(f"[daq] driver = {bench.daq.driver!r} is not 'nidaqmx'")
    return NidaqCurrentSource(bench.daq)
