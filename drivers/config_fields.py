"""The bounded field types of the config models, SI units in their names: what a value may be on any bench.

Shared by the sections of :mod:`drivers.config` (the plant's bounds by ``[nominal]`` and ``[sim]``, the phase names
and the sampling-rate bound by ``[daq]`` and ``[sim]``, the encoder period and time-outs by ``[drive]``).
"""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import Field

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
