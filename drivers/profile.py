"""The motion-profile model and the strict base of every config model.

Apart from the bench models (:mod:`drivers.config`, which re-exports both) so that the serial codec
(:mod:`drivers.serial_codec`) can carry a profile in its ``start_triangle`` command while the bench's
``[drive]`` model checks its baud rate against the codec's frame size — without an import circle.
"""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import BaseModel, ConfigDict, Field

MAX_DURATION_S = 24 * 3600.0  # one day: a session file of ~17 GB per phase at 25.6 kS/s
Seconds = Annotated[float, Field(gt=0.0, le=MAX_DURATION_S)]


class Strict(BaseModel):
    """Base for all config sections: unknown keys are errors, values are not coerced from strings."""

    model_config = ConfigDict(extra="forbid", strict=True, frozen=True, allow_inf_nan=False)


class Profile(Strict):
    """A motion: the triangle speed profile of the paper (speed up, down, reverse, back)."""

    kind: Literal["triangle"]
    top_speed_rpm: float = Field(gt=0.0, le=100_000.0)  # fastest servo motors run ~60 000 rpm
    accel_time_s: Seconds
    decel_time_s: Seconds
    dwell_s: float = Field(default=0.0, ge=0.0, le=MAX_DURATION_S)
    duration_s: Seconds
    cruise_s: float = Field(default=0.0, ge=0.0, le=MAX_DURATION_S)  # at top speed between the ramps (a trapezoid), s
    jerk_time_s: float = Field(default=0.0, ge=0.0, le=MAX_DURATION_S)  # S-curve: acceleration ramp time (0: steps), s
