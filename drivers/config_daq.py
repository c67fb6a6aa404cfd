"""The ``[daq]`` section of a bench: where the phase current comes from, one model per driver (simulated, NI-DAQmx).

Re-exported by :mod:`drivers.config`, the schema's face.
"""

from __future__ import annotations

from typing import Annotated, Literal, Union

from pydantic import AfterValidator, Field, model_validator

from drivers.config_fields import PhaseName, RateHz
from drivers.profile import Strict


def _distinct_phases(channels: list[str]) -> list[str]:
    """Each phase at most once: the session stores one dataset per phase (a phase twice made HDF5 fail mid-start)."""
    twice = next((c for i, c in enumerate(channels) if c in channels[:i]), None)
    if twice is not None:
        raise ValueError(f"{twice} is listed twice (each phase is one channel)")
    return channels


#: ``[daq] channels``: the phases wired to the DAQ, in its channel order, each once.
PhaseChannels = Annotated[list[PhaseName], Field(min_length=1, max_length=3), AfterValidator(_distinct_phases)]


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
