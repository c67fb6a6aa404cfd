"""The bench and motion-profile schema: validated models of the TOML configs (SI units in names).

These models only describe; they import no vendor library. ``acq.config`` loads TOML files into them
and turns validation failures into one-line errors naming the file, the key and the value.
Every model forbids unknown keys, so a misspelt key is an error, never silently ignored. A rule that
involves two keys of a section is a ``model_validator`` of that section, its message naming both keys
(``[daq] block_s = 3 must be at most half of buffer_s = 5``), so ``acq record`` and ``acq import`` refuse
it alike, before anything starts.

This module is the schema's face: the whole bench (:class:`Bench`), its small sections and ``[limits]``. The
sections with a model per device live in their own modules and are re-exported from here — ``[daq]``
(:mod:`drivers.config_daq`), ``[drive]`` (:mod:`drivers.config_drive`), ``[sim]`` (:mod:`drivers.config_sim`) —
as is the motion profile (:mod:`drivers.profile`); the bounded field types they share are
:mod:`drivers.config_fields`.
"""

from __future__ import annotations

import unicodedata

from pydantic import Field, field_validator

from drivers.config_daq import DaqNidaqmx, DaqSettings, DaqSim
from drivers.config_drive import DriveCanopen, DriveSerial, DriveSettings, DriveSim
from drivers.config_fields import Inertia, Stiffness
from drivers.config_sim import SimSettings
from drivers.profile import MAX_TOP_SPEED_RPM, Profile, Strict

# the section models are defined in their own modules (see the module doc); their names stay importable from here,
# where the callers have always found them
__all__ = [
    "MAX_JOINT_NAME", "SIM_LIMITS", "Bench", "DaqNidaqmx", "DaqSettings", "DaqSim", "DriveCanopen", "DriveSerial",
    "DriveSettings", "DriveSim", "Encoder", "Gear", "Limits", "Motor", "Nominal", "Profile", "SimSettings",
    "check_joint_name", "moves_real_joint",
]

MAX_JOINT_NAME = 64


def check_joint_name(name: str) -> str:
    """Return ``name`` if it is a safe joint name, else raise ValueError saying why.

    Safe: 1–64 characters, each a letter or digit (any script) or one of ``-``, ``_``, ``.``; no leading dot;
    already in Unicode NFC form (so two spellings of one name cannot make two joints). It becomes part of a
    file name, so nothing that a file system or a shell treats specially gets through.
    """
    if not name:
        raise ValueError("must not be empty")
    if len(name) > MAX_JOINT_NAME:
        raise ValueError(f"must be at most {MAX_JOINT_NAME} characters")
    if name.startswith("."):
        raise ValueError("must not start with a dot")
    bad = next((ch for ch in name if not (ch.isalnum() or ch in "-_.")), None)
    if bad is not None:
        raise ValueError(f"may hold only letters, digits, '-', '_' and '.' (not {ascii(bad)})")
    if unicodedata.normalize("NFC", name) != name:
        raise ValueError("must be in Unicode NFC form")
    return name


class Motor(Strict):
    torque_constant_Nm_per_A: float = Field(gt=0.0, le=1000.0)
    pole_pairs: int = Field(gt=0, le=1000)


class Encoder(Strict):
    counts_per_rev: int = Field(gt=0, le=2**31)


class Gear(Strict):
    ratio: float = Field(gt=0.0, le=1e5)


#: How far the true J_m + J_l may lie from a stated (``inertia_known``) [nominal] Jm + Jl, as a fraction: the default of
#: ``[nominal] inertia_tolerance``. The rigid-body inertia from torque/acceleration (``acq selftest``) is within ~3 % of
#: J_m + J_l on the simulated bench (10 Hz low-pass, gravity and friction fitted); a datasheet/CAD inertia is rarely
#: better than 10 %. A wrong sensor scale or k_t is usually a factor (2×, √2 for RMS vs peak, 10×): 15 % separates them.
INERTIA_TOLERANCE = 0.15


class Nominal(Strict):
    """Nominal plant: the fit's starting point and the fixed inertias for ``--params K``.

    With ``inertia_known`` (Jm + Jl known independently: datasheet, CAD) ``acq selftest`` checks k_t against them and
    the analysis flags a fitted J_m + J_l outside ``inertia_tolerance`` (a fraction) of them as a torque-scale mistake.
    """

    K_Nm_per_rad: Stiffness
    Jm_kgm2: Inertia
    Jl_kgm2: Inertia
    inertia_known: bool = False
    inertia_tolerance: float = Field(default=INERTIA_TOLERANCE, gt=0.0, lt=1.0)


class Limits(Strict):
    """``[limits]``: what the joint may see while acq commands its motion (checked by :mod:`drivers.limits` before any
    motion against the profile as executed; a CANopen drive is also told them, :mod:`drivers.canopen_setup`).

    Attributes
    ----------
    max_speed_rpm : motor speed, either direction, rpm (motor side, before the gear).
    max_travel_deg : load-side (arm) angle the motion may move the joint away from where it starts, either
        direction, deg: the mechanical stops or the cables, less a margin.
    max_torque_Nm : motor torque k_t·i_q, N·m (motor side); the drive's current limit is max_torque_Nm / k_t.
    """

    max_speed_rpm: float = Field(gt=0.0, le=MAX_TOP_SPEED_RPM)
    max_travel_deg: float = Field(gt=0.0, le=36_000.0)  # 100 arm turns: a continuous joint's cable reel
    max_torque_Nm: float = Field(gt=0.0, le=1e5)


#: The limits of a simulated joint whose bench states no ``[limits]``: the paper's motor (Xu et al. 2021, Table 2:
#: a 2.3 kW PMSM, k_t = 3 N·m/A) taken as a 3000 rpm servo — rated torque 2.3 kW / 3000 rpm = 7.3 N·m, peak three
#: times that (a typical servo datasheet ratio; an assumption, the paper gives neither) — and one arm turn either
#: way (the simulated arm has no stops). The shipped profiles need 1020 rpm, 306° (triangle_0.5s) and 5.6 N·m.
SIM_LIMITS = Limits(max_speed_rpm=3000.0, max_travel_deg=360.0, max_torque_Nm=22.0)


def moves_real_joint(drive: DriveSim | DriveCanopen | DriveSerial) -> bool:
    """True if acq commands the motion of a real drive (not simulated, not ``motion = "external"``)."""
    simulated = isinstance(drive, DriveSim) or getattr(drive, "simulated_node", False) \
        or getattr(drive, "simulated_device", False)
    return drive.motion == "commanded" and not simulated


class Bench(Strict):
    """A whole bench: joint name, motor, encoder, gear, nominal plant, DAQ, drive, joint limits, optional sim truth.

    ``[limits]`` is required before acq moves a real joint (no default can know a real joint's stops, motor or
    gear: :func:`drivers.limits.refuse_beyond_limits` refuses the motion); a simulated bench without it gets
    :data:`SIM_LIMITS` (:meth:`motion_limits`). A bench only read (``acq import``, ``acq monitor``) needs none.
    """

    joint: str = Field(min_length=1)  # see check_joint_name
    motor: Motor
    encoder: Encoder
    gear: Gear
    nominal: Nominal
    daq: DaqSettings
    drive: DriveSettings
    limits: Limits | None = None
    sim: SimSettings | None = None

    @field_validator("joint")
    @classmethod
    def _safe_joint(cls, name: str) -> str:
        return check_joint_name(name)

    def listens(self) -> bool:
        """True when the machine's own controller moves the joint (``[drive] motion = "external"``): acq commands no
        motion, it only records (``acq monitor``, a passive ``acq record`` or ``acq selftest``)."""
        return self.drive.motion == "external"

    def motion_limits(self) -> Limits | None:
        """``[limits]``; where the bench states none, :data:`SIM_LIMITS` for a simulated drive, None for a real one."""
        if self.limits is not None:
            return self.limits
        return None if moves_real_joint(self.drive) else SIM_LIMITS

