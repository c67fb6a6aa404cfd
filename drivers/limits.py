"""What a motion profile demands of the joint as executed, against the bench's ``[limits]`` (SI units, motor side
unless said otherwise; see :class:`drivers.config.Limits`).

The profile is judged as it will run: its fastest cycle (``speed_dither``: :attr:`~drivers.config.Profile.max_speed_factor`
times the nominal top speed, acceleration and swing, whatever seed is drawn), the steepest ramp (an S-curve's
``jerk_time_s`` steepens it: :mod:`drivers.motion`), and the triangle's one-sided excursion (out from the start and
back to it). The torque is the rigid-body torque (J_m + J_l)·α of ``[nominal]``'s inertias: a lower bound of what the
motor must give (gravity, friction and the resonance's overshoot come on top — on the paper's simulated bench the peak
is 9.3 N·m for 5.6 N·m of inertial torque), so a profile refused here cannot be followed at all; a drive told the limit
(CANopen 0x6072) clamps the rest.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from acqcore.errors import ConfigError
from drivers.config import Bench, Profile
from drivers.motion import RPM_TO_RAD_S, half_swing_rad, peak_ramp_rate


@dataclass(frozen=True)
class Demand:
    """What the fastest cycle of a profile asks of the joint.

    Attributes
    ----------
    speed_rpm : top motor speed, rpm.
    travel_deg : load-side angle away from the start position, deg.
    accel_rad_s2 : steepest motor acceleration or deceleration, rad/s².
    torque_Nm : (J_m + J_l)·``accel_rad_s2``, N·m (nominal inertias, motor side).
    """

    speed_rpm: float
    travel_deg: float
    accel_rad_s2: float
    torque_Nm: float


def demand(profile: Profile, gear_ratio: float, inertia_kgm2: float) -> Demand:
    """The :class:`Demand` of ``profile`` on a joint of ``gear_ratio`` (motor turns per arm turn) and motor-side
    total inertia ``inertia_kgm2`` (kg·m²)."""
    factor = profile.max_speed_factor
    top_rad_s = profile.top_speed_rpm * RPM_TO_RAD_S * factor
    rate = max(peak_ramp_rate(profile.accel_time_s, profile.jerk_time_s),
               peak_ramp_rate(profile.decel_time_s, profile.jerk_time_s))
    accel = top_rad_s * rate
    return Demand(speed_rpm=profile.top_speed_rpm * factor,
                  travel_deg=math.degrees(half_swing_rad(profile) * factor / gear_ratio),
                  accel_rad_s2=accel, torque_Nm=inertia_kgm2 * accel)


def missing_limits(bench: Bench) -> str | None:
    """Why acq must not move ``bench``'s joint at all: a real drive without ``[limits]``; else None."""
    if bench.motion_limits() is not None:
        return None
    return (f"[limits]: missing — acq commands the motion of a real drive ([drive] driver = \"{bench.drive.driver}\"): "
            "state the joint's max_speed_rpm, max_travel_deg and max_torque_Nm (see configs/benches/template_hardware.toml)")


def limit_problem(profile: Profile, bench: Bench) -> str | None:
    """Why ``profile`` as executed exceeds ``bench``'s limits (its key and value, the figure, the limit), else None.
    ``bench`` must have limits (:func:`missing_limits`)."""
    lim, d = bench.motion_limits(), profile.speed_dither
    assert lim is not None, "a real drive without [limits] (drivers.limits.missing_limits)"
    inertia = bench.nominal.Jm_kgm2 + bench.nominal.Jl_kgm2
    need = demand(profile, bench.gear.ratio, inertia)
    dither = f" with speed_dither = {d:g}" if d else ""
    cycle = "the fastest cycle" if d else "the motion"
    if need.speed_rpm > lim.max_speed_rpm:
        return (f"top_speed_rpm = {profile.top_speed_rpm:g}{dither}: {cycle} runs the motor at {need.speed_rpm:g} rpm, "
                f"above [limits] max_speed_rpm = {lim.max_speed_rpm:g}")
    if need.travel_deg > lim.max_travel_deg:
        keys = [f"top_speed_rpm = {profile.top_speed_rpm:g}", f"accel_time_s = {profile.accel_time_s:g}",
                f"decel_time_s = {profile.decel_time_s:g}"] + ([f"cruise_s = {profile.cruise_s:g}"] if profile.cruise_s else [])
        return (f"{', '.join(keys)}{dither}: {cycle} swings the joint {need.travel_deg:.1f}° from its start (load side, "
                f"[gear] ratio = {bench.gear.ratio:g}), beyond [limits] max_travel_deg = {lim.max_travel_deg:g}")
    if need.torque_Nm > lim.max_torque_Nm:
        steep = "accel_time_s" if profile.accel_time_s <= profile.decel_time_s else "decel_time_s"
        keys = f"{steep} = {getattr(profile, steep):g}" + (f", jerk_time_s = {profile.jerk_time_s:g}"
                                                            if profile.jerk_time_s else "")
        return (f"{keys} (top_speed_rpm = {profile.top_speed_rpm:g}{dither}): {cycle}'s steepest ramp needs "
                f"{need.torque_Nm:.3g} N·m to accelerate [nominal] Jm_kgm2 + Jl_kgm2 = {inertia:.4g} kg·m² at "
                f"{need.accel_rad_s2:.4g} rad/s², above [limits] max_torque_Nm = {lim.max_torque_Nm:g}")
    return None


def refuse_beyond_limits(profile: Profile, bench: Bench, profile_name: str = "profile",
                         bench_name: str = "the bench config") -> None:
    """Raise :class:`ConfigError` in one line — ``profile <name>: <key> = <value> …: <figure>, above [limits] <key> =
    <limit> of <bench>`` — if ``profile`` as executed exceeds the bench's limits, or ``<bench>: [limits]: missing …``
    if it moves a real drive and states none."""
    missing = missing_limits(bench)
    if missing is not None:
        raise ConfigError(f"{bench_name}: {missing}")
    problem = limit_problem(profile, bench)
    if problem is not None:
        default = "" if bench.limits is not None else " (a simulated bench's default: drivers.config.SIM_LIMITS)"
        raise ConfigError(f"profile {profile_name}: {problem} of {bench_name}{default}")


def travel_counts(max_travel_deg: float, gear_ratio: float, counts_per_rev: int) -> int:
    """``max_travel_deg`` of the arm in motor position counts, rounded down (a drive told it stops inside the limit)."""
    return math.floor(max_travel_deg / 360.0 * gear_ratio * counts_per_rev)
