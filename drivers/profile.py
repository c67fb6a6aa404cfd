"""The motion-profile model and the strict base of every config model.

Apart from the bench models (:mod:`drivers.config`, which re-exports the profile) so that the serial codec
(:mod:`drivers.serial_codec`) can carry a profile in its ``start_triangle`` command while the bench's
``[drive]`` model (:mod:`drivers.config_drive`) checks its baud rate against the codec's frame size — without an
import circle.
"""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import BaseModel, ConfigDict, Field, model_validator

MAX_DURATION_S = 24 * 3600.0  # one day: a session file of ~17 GB per phase at 25.6 kS/s
MAX_TOP_SPEED_RPM = 100_000.0  # fastest servo motors run ~60 000 rpm
#: Largest speed dither: ±5 % on each cycle's speed, acceleration and swing stays a margin a bench's speed and travel
#: limits can carry rather than a different motion (2 % already moves the paper's swing by thousands of counts at 2^17
#: counts/rev between cycles; see configs/profiles/triangle_0.2s.toml).
MAX_SPEED_DITHER = 0.05
MAX_SEED = 2**63 - 1  # a TOML integer is a signed 64-bit number
Seconds = Annotated[float, Field(gt=0.0, le=MAX_DURATION_S)]


class Strict(BaseModel):
    """Base for all config sections: unknown keys are errors, values are not coerced from strings."""

    model_config = ConfigDict(extra="forbid", strict=True, frozen=True, allow_inf_nan=False)


class Profile(Strict):
    """A motion: the triangle speed profile of the paper (speed up, down, reverse, back).

    ``speed_dither`` = d > 0 scales each full cycle (out and back, so the joint returns to its start and
    nothing drifts) by its own factor s_c drawn uniformly from [1 − d, 1 + d]: top speed, acceleration,
    deceleration and swing are s_c times the nominal ones; the ramp, cruise and dwell times — the cycle's
    timing — are unchanged. Why: a drive runs the profile and samples the encoder on the same cycle, so an
    undithered motion reads the same quantisation pattern every period, which then does not average out at the
    motion's lines; the dither moves the positions at the sampling instants by many counts between cycles.
    **The fastest cycle runs at (1 + d)·top_speed_rpm and swings (1 + d) times the nominal swing**: limits on
    speed and travel must allow for that (:attr:`max_speed_factor`). The factors are
    ``numpy.random.default_rng(dither_seed).uniform(1 − d, 1 + d)``, one per cycle in order
    (:func:`drivers.motion.speed_factors`); ``dither_seed`` None: acq draws one when the motion starts and the
    session file keeps the seed used (in its profile), so the motion can be re-simulated.
    """

    kind: Literal["triangle"]
    top_speed_rpm: float = Field(gt=0.0, le=MAX_TOP_SPEED_RPM)
    accel_time_s: Seconds
    decel_time_s: Seconds
    dwell_s: float = Field(default=0.0, ge=0.0, le=MAX_DURATION_S)
    duration_s: Seconds
    cruise_s: float = Field(default=0.0, ge=0.0, le=MAX_DURATION_S)  # at top speed between the ramps (a trapezoid), s
    jerk_time_s: float = Field(default=0.0, ge=0.0, le=MAX_DURATION_S)  # S-curve: acceleration ramp time (0: steps), s
    speed_dither: float = Field(default=0.0, ge=0.0, le=MAX_SPEED_DITHER)  # d: each cycle's scale in [1 − d, 1 + d]
    dither_seed: int | None = Field(default=None, ge=0, le=MAX_SEED)  # seed of the cycles' factors (None: drawn)

    @property
    def max_speed_factor(self) -> float:
        """The largest factor any cycle runs at (1 + d): its top speed, acceleration and swing over the nominal ones."""
        return 1.0 + self.speed_dither

    @property
    def min_speed_factor(self) -> float:
        """The smallest factor any cycle runs at (1 − d)."""
        return 1.0 - self.speed_dither

    @model_validator(mode="after")
    def _fastest_cycle_within_the_speed_limit(self) -> Profile:
        if self.top_speed_rpm * self.max_speed_factor > MAX_TOP_SPEED_RPM:
            raise ValueError(f"top_speed_rpm = {self.top_speed_rpm:g} with speed_dither = {self.speed_dither:g}: the "
                             f"fastest cycle would run at {self.top_speed_rpm * self.max_speed_factor:g} rpm, above "
                             f"{MAX_TOP_SPEED_RPM:g} rpm")
        return self
