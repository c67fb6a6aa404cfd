"""The ``[drive]`` section of a bench: where the encoder stream comes from, one model per transport (simulated,
CANopen, serial), with the rules between their keys, and what makes a master's TPDO mapping recordable.

Re-exported by :mod:`drivers.config`, the schema's face.
"""

from __future__ import annotations

from typing import Annotated, Literal, Union

from pydantic import Field, model_validator

from drivers.config_fields import PeriodS, Timeout
from drivers.profile import Strict
from drivers.serial_codec import CODECS, bits_per_byte, required_baud


class DriveSim(Strict):
    """Encoder and motion from the simulated bench's drive (transport ``sim``)."""

    driver: Literal["sim"]
    period_s: PeriodS
    # "commanded": acq runs the profile; "external": the machine's own controller moves the joint (the
    # simulated production robot of drivers.sim.robot_program) and acq only listens (acq monitor)
    motion: Literal["commanded", "external"] = "commanded"


class DriveCanopen(Strict):
    """A CiA 402 drive over CANopen (see ``drivers.canopen_drive``)."""

    driver: Literal["canopen"]
    period_s: PeriodS
    interface: str = "socketcan"
    channel: str = "can0"
    bitrate: int = Field(default=1_000_000, gt=0, le=1_000_000)  # classic CAN's maximum
    node_id: int = Field(default=1, ge=1, le=127)
    tpdo: int = Field(default=1, ge=1, le=4)
    map_velocity: bool = False
    sdo_timeout_s: Timeout = 0.5
    state_timeout_s: Timeout = 2.0
    heartbeat_timeout_s: Timeout = 0.5
    velocity_units_per_rpm: float = Field(default=1.0, gt=0.0, le=1e9)
    acceleration_units_per_rpm_per_s: float = Field(default=1.0, gt=0.0, le=1e9)
    counts_per_rev: Annotated[int, Field(gt=0, le=2**31)] | None = None  # position units (0x6064, 0x607A) per motor rev; None: [encoder]'s
    heartbeat_period_s: Timeout = 0.1  # the drive's producer heartbeat time (0x1017)
    max_bus_load: float = Field(default=0.7, gt=0.0, le=1.0)  # refuse settings whose traffic needs more
    simulated_node: bool = False
    map_timestamp: bool = False  # map the drive's 0x1013 high-resolution time stamp (µs) into the TPDO
    # "external": the machine's own master runs NMT, SYNC and the motion; acq only listens (acq monitor): it
    # records the TPDO the master set up (tpdo_cob_id + tpdo_mapping, or TPDO ``tpdo`` of the drive's EDS/DCF
    # file ``eds``) or, with configure = true, maps TPDO ``tpdo`` itself by SDO (never NMT, SYNC or motion)
    motion: Literal["commanded", "external"] = "commanded"
    configure: bool = False
    # the TPDO's COB-ID on the bus: CiA 301's predefined connection set puts the PDOs at 0x181…0x57F (TPDO1…4 at
    # 0x181…0x4FF, RPDO1…4 above them); a master may reassign them anywhere below the SDO identifiers (0x581…),
    # but not onto NMT (0x000), SYNC/EMCY (0x080…0x0FF) or TIME (0x100)
    tpdo_cob_id: int | None = Field(default=None, ge=0x101, le=0x57F)
    tpdo_mapping: list[Annotated[int, Field(ge=0, le=0xFFFFFFFF)]] | None = None  # CiA 301 entries, 0x60640020 …
    eds: str | None = Field(default=None, min_length=1)  # the drive's EDS/DCF file (its TPDO mapping and COB-ID)
    sync_counter_overflow: int = Field(default=0, ge=0, le=240)  # the master's SYNC counter (0x1019); 0: none

    @property
    def tpdo_bytes(self) -> int:
        """Payload of the TPDO asked for, bytes: position, [velocity], [0x1013 time stamp], 4 each."""
        return 4 * (1 + self.map_velocity + self.map_timestamp)

    @model_validator(mode="after")
    def _two_key_rules(self) -> DriveCanopen:
        if self.tpdo_bytes > 8:
            raise ValueError(f"[drive] map_velocity = true and map_timestamp = true need a TPDO of {self.tpdo_bytes} "
                             "bytes, a CAN frame carries 8 — set one of them to false")
        if self.heartbeat_timeout_s <= self.heartbeat_period_s:
            raise ValueError(f"[drive] heartbeat_timeout_s = {self.heartbeat_timeout_s:g} must exceed "
                             f"heartbeat_period_s = {self.heartbeat_period_s:g}")
        if self.simulated_node and self.interface != "virtual":
            raise ValueError(f"[drive] simulated_node = true needs interface = \"virtual\", not {self.interface!r}")
        self._passive_keys()
        return self

    def _passive_keys(self) -> None:
        """The rules of ``motion = "external"``: where the TPDO's layout comes from, one source only."""
        given = [k for k in ("tpdo_cob_id", "tpdo_mapping", "eds") if getattr(self, k) is not None]
        if self.motion == "commanded":
            if self.configure or given or self.sync_counter_overflow:
                what = "configure" if self.configure else (given[0] if given else "sync_counter_overflow")
                raise ValueError(f"[drive] {what} applies only to motion = \"external\" (acq maps and syncs the "
                                 "TPDO itself when it commands the motion)")
            return
        if self.configure:
            if given:
                raise ValueError(f"[drive] configure = true maps acq's own TPDO{self.tpdo}: drop {given[0]} "
                                 "(it describes a TPDO the machine's master set up)")
            return
        if self.map_velocity or self.map_timestamp:
            key = "map_velocity" if self.map_velocity else "map_timestamp"
            raise ValueError(f"[drive] {key} = true needs configure = true (with configure = false the master's "
                             "TPDO mapping, tpdo_mapping or eds, decides what is recorded)")
        if self.eds is not None:
            if given != ["eds"]:
                raise ValueError(f"[drive] eds and {[k for k in given if k != 'eds'][0]}: give the TPDO's layout once "
                                 "(eds, or tpdo_cob_id with tpdo_mapping)")
            return
        if self.tpdo_cob_id is None or self.tpdo_mapping is None:
            missing = "tpdo_cob_id" if self.tpdo_cob_id is None else "tpdo_mapping"
            raise ValueError(f"[drive] motion = \"external\" with configure = false needs the TPDO the master set up: "
                             f"{missing} missing (give tpdo_cob_id and tpdo_mapping, or eds = the drive's EDS/DCF file, "
                             "or configure = true)")
        problem = tpdo_mapping_problem(self.tpdo_mapping)
        if problem:
            raise ValueError(f"[drive] tpdo_mapping = [{', '.join(f'0x{e:08X}' for e in self.tpdo_mapping)}]: {problem}")


#: CiA 402 position actual value (0x6064, 32 bit): the one object a passively recorded TPDO must carry
POSITION_ACTUAL_ENTRY = 0x60640020


def tpdo_mapping_problem(entries: list[int]) -> str:
    """Why CiA 301 PDO mapping ``entries`` (index << 16 | subindex << 8 | bits) cannot be recorded, "" if they can:
    whole bytes, at most 8 bytes (one classic CAN frame), 0x6064 position actual (32 bit) among them."""
    if not entries:
        return "empty"
    if any(e & 0xFF == 0 or e & 0x7 for e in entries):
        return "each entry's length (its low byte) must be a whole number of bytes"
    size = sum(e & 0xFF for e in entries) // 8
    if size > 8:
        return f"{size} bytes, a CAN frame carries 8"
    if POSITION_ACTUAL_ENTRY not in entries:
        return "must map 0x6064 position actual value (0x60640020)"
    return ""


class DriveSerial(Strict):
    """A drive streaming framed encoder telemetry over a serial link (see ``drivers.serial_drive``)."""

    driver: Literal["serial"]
    period_s: PeriodS
    port: str = "/dev/ttyUSB0"
    baud: int = Field(default=921_600, gt=0, le=20_000_000)
    parity: Literal["N", "E", "O"] = "N"
    codec: str = "acq1"
    read_timeout_s: Timeout = 0.5
    simulated_device: bool = False
    # "external": the machine's own controller moves the joint; acq switches the telemetry stream on and
    # never sends a motion command (acq monitor)
    motion: Literal["commanded", "external"] = "commanded"

    @model_validator(mode="after")
    def _codec_carries_the_frame_rate(self) -> DriveSerial:
        if self.codec not in CODECS:
            raise ValueError(f'[drive] codec = "{self.codec}": unknown codec (known: {", ".join(sorted(CODECS))})')
        codec = CODECS[self.codec]()
        need = required_baud(codec, self.period_s, self.parity)
        if self.baud < need:
            raise ValueError(
                f"[drive] baud = {self.baud}: too low for one {codec.telemetry_bytes}-byte {codec.name} frame every "
                f"{self.period_s:g} s; needs at least {need:.0f} baud ({codec.telemetry_bytes} bytes × "
                f"{bits_per_byte(self.parity)} bits / {self.period_s:g} s)")
        return self


DriveSettings = Annotated[Union[DriveSim, DriveCanopen, DriveSerial], Field(discriminator="driver")]
