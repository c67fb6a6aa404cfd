"""A stand-in for the hardware side of ``nidaqmx``: the task, reader and system APIs with their documented
signatures, backed by a simulated card instead of the NI-DAQmx driver.

It uses the real ``nidaqmx.constants`` and ``nidaqmx.errors`` (importing them needs no driver), so the
adapter under test catches the very exception classes and codes the driver raises. What it imitates:

* ``Task`` with ``ai_channels.add_ai_voltage_chan`` / ``add_ai_current_chan`` (device and channel
  checked: DAQmx errors -200220 / -200170), settable ``ai_excit_src``, ``ai_excit_val``, ``ai_coupling``
  (-200452 on a card without them), ``timing.cfg_samp_clk_timing`` with rate coercion to the card's
  rate ladder (NI 9234: 51.2 kS/s / n), ``timing.samp_clk_rate``, ``in_stream.input_buf_size``,
  ``in_stream.total_samp_per_chan_acquired``, ``devices``, ``control`` (the rate reads back coerced only
  once the task is verified or committed, as DAQmx may coerce it then), ``start``/``stop``/``close``;
* ``stream_readers.AnalogMultiChannelReader(task.in_stream).read_many_sample(data,
  number_of_samples_per_channel, timeout)`` filling the caller's array (channel-major) with what the
  sensors output (current / sensor gain, clipped to the range) and returning samples per channel;
* ``system.System.local()`` with ``devices`` (``name``, ``product_type``, ``ai_physical_chans``) and
  ``driver_version``;
* faults a test can switch on: driver missing (``DaqNotFoundError``), an overflow code after N samples,
  a read that times out with part of its samples (-200284), a card that miscounts its samples.

Time is virtual: samples exist as soon as they are asked for, so a 5 s acquisition takes milliseconds.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from types import SimpleNamespace
from typing import Any

import numpy as np
from nidaqmx import constants, errors

#: (first_index, count) → phase currents, A, shape (n_channels, count), for the card's own sample index.
CurrentSamples = Callable[[int, int], np.ndarray]


def real_driver_installed() -> bool:
    """Whether the real NI-DAQmx driver is on this machine (tests of its absence skip if it is)."""
    from nidaqmx.system import System

    try:
        System.local().driver_version  # noqa: B018
    except errors.DaqNotFoundError:
        return False
    return True


def synthetic_currents(rate_hz: float, n_channels: int) -> CurrentSamples:
    """Three-phase 40 Hz currents of 10 A plus a slow ramp, a pure function of the sample index."""

    def samples(first_index: int, count: int) -> np.ndarray:
        t_s = (first_index + np.arange(count)) / rate_hz
        phases = 2 * np.pi * np.arange(n_channels)[:, None] / 3
        return 10.0 * np.sin(2 * np.pi * 40.0 * t_s[None, :] - phases) + 1e-3 * t_s[None, :]

    return samples


@dataclass
class StandinDevice:
    """A simulated NI module: its name, product, AI channels, rate ladder and IEPE/coupling support."""

    name: str = "cDAQ1Mod1"
    product_type: str = "NI 9234"
    n_ai: int = 4
    master_rate_hz: float = 51200.0
    max_divider: int = 31
    supports_iepe: bool = True

    @property
    def ai_channel_names(self) -> list[str]:
        return [f"{self.name}/ai{i}" for i in range(self.n_ai)]

    def coerce(self, rate_hz: float) -> float:
        """The smallest ladder rate master/n at or above ``rate_hz`` (capped at the master rate)."""
        n = max(1, min(self.max_divider, int(self.master_rate_hz // rate_hz)))
        return self.master_rate_hz / n


@dataclass
class StandinHardware:
    """The machine the stand-in pretends to be: devices, the sensors' output and the faults to inject.

    ``sensor_gain`` converts phase current to what the channel measures (A per V or A per A).
    """

    currents: CurrentSamples
    sensor_gain: float = 1.0
    devices: list[StandinDevice] = field(default_factory=lambda: [StandinDevice()])
    driver_installed: bool = True
    overflow_code: int | None = None
    overflow_after: int = 0
    timeout_every: int = 0
    miscount: int = 0
    tasks: list[Task] = field(default_factory=list)
    arrays_read_into: set[int] = field(default_factory=set)

    def device(self, name: str) -> StandinDevice | None:
        return next((d for d in self.devices if d.name.lower() == name.lower()), None)

    def module(self) -> SimpleNamespace:
        """A namespace shaped like the ``nidaqmx`` package, bound to this hardware."""
        hw = self

        class BoundTask(Task):
            hardware = hw

        class BoundSystem(System):
            hardware = hw

        return SimpleNamespace(Task=BoundTask, constants=constants, errors=errors,
                               stream_readers=SimpleNamespace(AnalogMultiChannelReader=AnalogMultiChannelReader),
                               system=SimpleNamespace(System=BoundSystem))


def _require_driver(hw: StandinHardware) -> None:
    if not hw.driver_installed:
        raise errors.DaqNotFoundError("Could not find an installation of NI-DAQmx. Please ensure that NI-DAQmx "
                                      "is installed on this machine or contact National Instruments for support.")


class AIChannel:
    """One virtual AI channel; IEPE and coupling properties refuse on a card without them."""

    def __init__(self, device: StandinDevice, physical: str, measurement: str, range_: float) -> None:
        self.device, self.physical_channel, self.measurement, self.range = device, physical, measurement, range_
        self._excit_src = constants.ExcitationSource.NONE
        self._excit_val = 0.0
        self._coupling = constants.Coupling.DC

    def _check(self) -> None:
        if not self.device.supports_iepe:
            raise errors.DaqError(f"Specified property is not supported by the device or is not applicable "
                                  f"to the task.\nChannel Name: {self.physical_channel}", -200452)

    @property
    def ai_excit_src(self) -> Any:
        return self._excit_src

    @ai_excit_src.setter
    def ai_excit_src(self, value: Any) -> None:
        self._check()
        self._excit_src = value

    @property
    def ai_excit_val(self) -> float:
        return self._excit_val

    @ai_excit_val.setter
    def ai_excit_val(self, value: float) -> None:
        self._check()
        self._excit_val = value

    @property
    def ai_coupling(self) -> Any:
        return self._coupling

    @ai_coupling.setter
    def ai_coupling(self, value: Any) -> None:
        self._check()
        self._coupling = value


class AIChannelCollection:
    def __init__(self, task: Task) -> None:
        self._task = task
        self.channels: list[AIChannel] = []

    def _add(self, physical_channel: str, measurement: str, range_: float) -> AIChannel:
        dev_name, _, _ = physical_channel.partition("/")
        device = self._task.hardware.device(dev_name)
        if device is None:
            raise errors.DaqError(f"Device identifier is invalid.\nDevice Specified: {dev_name}", -200220)
        if physical_channel.lower() not in (c.lower() for c in device.ai_channel_names):
            raise errors.DaqError(f"Physical channel specified does not exist on this device.\n"
                                  f"Physical Channel Name: {physical_channel}", -200170)
        channel = AIChannel(device, physical_channel, measurement, range_)
        self.channels.append(channel)
        return channel

    def add_ai_voltage_chan(self, physical_channel: str, name_to_assign_to_channel: str = "",
                            terminal_config: Any = constants.TerminalConfiguration.DEFAULT, min_val: float = -5.0,
                            max_val: float = 5.0, units: Any = constants.VoltageUnits.VOLTS,
                            custom_scale_name: str = "") -> AIChannel:
        return self._add(physical_channel, "voltage", max_val)

    def add_ai_current_chan(self, physical_channel: str, name_to_assign_to_channel: str = "",
                            terminal_config: Any = constants.TerminalConfiguration.DEFAULT, min_val: float = -0.01,
                            max_val: float = 0.01, units: Any = constants.CurrentUnits.AMPS,
                            shunt_resistor_loc: Any = constants.CurrentShuntResistorLocation.LET_DRIVER_CHOOSE,
                            ext_shunt_resistor_val: float = 249.0, custom_scale_name: str = "") -> AIChannel:
        return self._add(physical_channel, "current", max_val)


class Timing:
    """Like DAQmx, the rate reads back coerced only once the task is verified (or committed)."""

    def __init__(self, task: Task) -> None:
        self._task = task
        self._rate_hz = 0.0
        self.sample_mode: Any = None

    def cfg_samp_clk_timing(self, rate: float, source: str = "", active_edge: Any = constants.Edge.RISING,
                            sample_mode: Any = constants.AcquisitionType.FINITE, samps_per_chan: int = 1000) -> None:
        self._rate_hz = rate
        self.sample_mode = sample_mode
        self._task.in_stream.input_buf_size = samps_per_chan
        self._task.verified = False

    @property
    def samp_clk_rate(self) -> float:
        if not self._task.verified:
            return self._rate_hz
        return self._task.ai_channels.channels[0].device.coerce(self._rate_hz)


class InStream:
    def __init__(self, task: Task) -> None:
        self._task = task
        self.input_buf_size = 0
        self.read_count = 0

    @property
    def total_samp_per_chan_acquired(self) -> int:
        return self._task.acquired + self._task.hardware.miscount


class Task:
    """``nidaqmx.Task``: channels, timing, stream; acquisition runs on a virtual clock."""

    hardware: StandinHardware

    def __init__(self, new_task_name: str = "") -> None:
        _require_driver(self.hardware)
        self.ai_channels = AIChannelCollection(self)
        self.timing = Timing(self)
        self.in_stream = InStream(self)
        self.acquired = 0
        self.verified = False
        self.running = False
        self.closed = False
        self.hardware.tasks.append(self)

    @property
    def devices(self) -> list[StandinDevice]:
        seen: dict[str, StandinDevice] = {}
        for channel in self.ai_channels.channels:
            seen.setdefault(channel.device.name, channel.device)
        return list(seen.values())

    def control(self, action: Any) -> None:
        if action in (constants.TaskMode.TASK_VERIFY, constants.TaskMode.TASK_COMMIT):
            self.verified = True

    def start(self) -> None:
        self.verified = self.running = True

    def stop(self) -> None:
        self.running = False

    def close(self) -> None:
        self.running = False
        self.closed = True


class AnalogMultiChannelReader:
    """``nidaqmx.stream_readers.AnalogMultiChannelReader`` on the stand-in task."""

    def __init__(self, task_in_stream: InStream) -> None:
        self._in_stream = task_in_stream
        self._task = task_in_stream._task

    def read_many_sample(self, data: np.ndarray, number_of_samples_per_channel: int = -1,
                         timeout: float = 10.0) -> int:
        task, hw = self._task, self._task.hardware
        channels = task.ai_channels.channels
        if data.shape != (len(channels), number_of_samples_per_channel):
            raise errors.DaqError("Read cannot be performed because the NumPy array passed into this function "
                                  "is not shaped correctly.", -1)
        self._in_stream.read_count += 1
        hw.arrays_read_into.add(id(data))
        first = task.acquired
        n = number_of_samples_per_channel
        if hw.overflow_code is not None and first + n > hw.overflow_after:
            task.acquired += n + task.in_stream.input_buf_size
            raise errors.DaqReadError("Attempted to read samples that are no longer available.", hw.overflow_code, 0)
        partial = hw.timeout_every and self._in_stream.read_count % hw.timeout_every == 0
        got = n // 2 if partial else n
        values = hw.currents(first, got) / hw.sensor_gain
        ranges = np.array([c.range for c in channels])[:, None]
        data[:, :got] = np.clip(values, -ranges, ranges)
        task.acquired += got
        if partial:
            raise errors.DaqReadError("Some or all of the samples requested have not yet been acquired.",
                                      -200284, got)
        return got


class System:
    """``nidaqmx.system.System``: ``System.local().devices`` and ``driver_version``."""

    hardware: StandinHardware

    @classmethod
    def local(cls) -> System:
        return cls()

    @property
    def devices(self) -> list[SimpleNamespace]:
        _require_driver(self.hardware)
        return [SimpleNamespace(name=d.name, product_type=d.product_type,
                                ai_physical_chans=[SimpleNamespace(name=c) for c in d.ai_channel_names])
                for d in self.hardware.devices]

    @property
    def driver_version(self) -> SimpleNamespace:
        _require_driver(self.hardware)
        return SimpleNamespace(major_version=2025, minor_version=3, update_version=0)
