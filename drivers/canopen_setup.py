"""Configuring a CiA 402 drive over SDO in NMT PRE-OPERATIONAL, drive disabled: each step verified on the drive.

The steps :meth:`drivers.canopen_drive.CanopenDrive.start` takes before the stream starts: the SYNC counter
(0x1019, or plain SYNC if the drive has none), the TPDO mapped to 0x6064 position actual (+ 0x606C velocity actual,
+ 0x1013 high-resolution time stamp, refused if the drive lacks it) with transmission type 1 and **read back** (a
differing mapping refuses to record), mode of operation Profile Position **verified** on 0x6061 (canopen's own setter
only logs a refusal), the bench's ``[limits]`` written to 0x607F and 0x6072 and **read back**, and the position frame
(0x607D window and 0x607C home offset) reported, a home offset refused. Each failure is a :class:`DeviceError`
naming the drive (``name``); ``info`` receives what is worth an info event.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable

import canopen
from canopen.profiles.p402 import BaseNode402
from canopen.sdo import SdoAbortedError

from drivers import canopen_od as od
from drivers.canopen_motion import STATUS_POLL_S, device_step
from drivers.config import DriveCanopen, Limits
from acqcore.errors import DeviceError


def enable_sync_counter(node: BaseNode402, name: str, overflow: int, info: Callable[[str], None]) -> int:
    """0x1019 = ``overflow`` if the drive has it (then SYNC carries the counter), else 0."""
    with device_step(name, "writing 0x1019 SYNC counter overflow failed"):
        try:
            node.sdo[od.SYNC_OVERFLOW].raw = overflow
        except SdoAbortedError:
            info("drive has no SYNC counter (0x1019): plain SYNC, the host counts them")
            return 0
    return overflow


def map_tpdo(network: canopen.Network, node: BaseNode402, name: str, s: DriveCanopen) -> tuple[int, list[int]]:
    """Map the TPDO (CiA 301 sequence via canopen), read it back, refuse a difference; its COB-ID and entries."""
    wanted = [od.map_entry(od.POSITION_ACTUAL, 32)] + ([od.map_entry(od.VELOCITY_ACTUAL, 32)] if s.map_velocity else [])
    if s.map_timestamp:
        _require_timestamp(node, name)
        wanted.append(od.map_entry(od.HIGH_RES_TIMESTAMP, 32))
    cob_id = od.tpdo_cob_id(s.tpdo, s.node_id)
    pdo = node.tpdo[s.tpdo]
    with device_step(name, f"writing the TPDO{s.tpdo} mapping failed"):
        pdo.clear()
        for entry in wanted:
            pdo.add_variable(entry >> 16, 0, entry & 0xFF)
        pdo.cob_id, pdo.trans_type, pdo.enabled, pdo.rtr_allowed = cob_id, 1, True, False
        pdo.save()
        network.unsubscribe(cob_id, pdo.on_message)  # our capture reads this COB-ID, not canopen's map
    with device_step(name, f"reading the TPDO{s.tpdo} mapping back failed"):
        comm, mapping = node.sdo[od.TPDO_COMM + s.tpdo - 1], node.sdo[od.TPDO_MAP + s.tpdo - 1]
        got_cob, got_type = int(comm[1].raw), int(comm[2].raw)
        got = [int(mapping[i].raw) for i in range(1, int(mapping[0].raw) + 1)]
    if got != wanted or got_type != 1 or got_cob & 0x7FF != cob_id or got_cob & od.PDO_INVALID:
        raise DeviceError(
            f"{name}: TPDO{s.tpdo} read back differs from what was written — wrote {od.entries_text(wanted)} "
            f"type 1 COB-ID 0x{cob_id:X}, read {od.entries_text(got)} type {got_type} COB-ID 0x{got_cob:X}")
    return cob_id, wanted


def _require_timestamp(node: BaseNode402, name: str) -> None:
    """0x1013 must exist on the drive (an SDO upload of it must succeed) before it is mapped."""
    with device_step(name, "reading 0x1013 high-resolution time stamp failed"):
        try:
            node.sdo[od.HIGH_RES_TIMESTAMP].raw
        except SdoAbortedError as e:
            raise DeviceError(f"{name}: the drive has no 0x1013 high-resolution time stamp (SDO abort "
                              f"0x{e.code:08X}) — set [drive] map_timestamp = false") from None


def set_profile_position(node: BaseNode402, name: str, timeout: float) -> None:
    """Mode of operation 1 (0x6060), verified on 0x6061 within ``timeout`` (s, ``[drive] state_timeout_s``)."""
    with device_step(name, "checking 0x6502 supported drive modes failed"):
        supported = node.is_op_mode_supported("PROFILED POSITION")
    if not supported:
        raise DeviceError(f"{name}: the drive does not support Profile Position (0x6502)")
    with device_step(name, "switching the mode of operation failed"):
        node.sdo[od.MODE].raw = od.MODE_PROFILE_POSITION
        deadline = time.monotonic() + timeout
        while (shown := int(node.sdo[od.MODE_DISPLAY].raw)) != od.MODE_PROFILE_POSITION:
            if time.monotonic() > deadline:
                raise DeviceError(f"{name}: the drive refused Profile Position: 0x6061 mode display "
                                  f"is {shown}, not {od.MODE_PROFILE_POSITION}, {timeout:g} s after writing 0x6060")
            time.sleep(STATUS_POLL_S)


def write_limits(node: BaseNode402, name: str, limits: Limits, velocity_units_per_rpm: float) -> None:
    """[limits] into the drive, which then enforces them itself: 0x607F max profile velocity (velocity units) and
    0x6072 max torque (per mille of the drive's 0x6076 motor rated torque, mN·m), both rounded down, written and
    read back — a drive that keeps other values is refused, as a differing TPDO mapping is. The travel limit
    (0x607D) is set around the start position when the motion starts (:mod:`drivers.canopen_motion`)."""
    with device_step(name, "reading 0x6076 motor rated torque failed"):
        rated_mNm = int(node.sdo[od.MOTOR_RATED_TORQUE].raw)
    if rated_mNm <= 0:
        raise DeviceError(f"{name}: 0x6076 motor rated torque reads {rated_mNm} mN·m: [limits] max_torque_Nm "
                          "cannot be set as 0x6072 — enter the motor's data in the drive")
    wanted = {od.MAX_PROFILE_VELOCITY: math.floor(limits.max_speed_rpm * velocity_units_per_rpm),
              od.MAX_TORQUE: min(math.floor(limits.max_torque_Nm * 1e6 / rated_mNm), 0xFFFF)}
    with device_step(name, "writing [limits] to 0x607F / 0x6072 failed"):
        for index, value in wanted.items():
            node.sdo[index].raw = value
        got = {index: int(node.sdo[index].raw) for index in wanted}
    if got != wanted:
        shown = ", ".join(f"0x{i:04X} = {v}" for i, v in wanted.items())
        read = ", ".join(f"0x{i:04X} = {v}" for i, v in got.items())
        raise DeviceError(f"{name}: [limits] read back differ from what was written — wrote {shown}, read {read}")


def check_position_frame(node: BaseNode402, name: str, info: Callable[[str], None]) -> None:
    """Read 0x607C home offset and the 0x607D window the drive holds, say both in an info event, and refuse a home
    offset other than 0.

    acq takes its travel window in 0x6064's frame: the start position p0 it reads there ± [limits] max_travel_deg
    (:mod:`drivers.canopen_motion`). 0x6064 (and 0x607A) already include the home offset — they count from the
    application's zero — and so does acq's own check of the swing, which is relative to p0: for those the offset
    changes nothing, and it is only reported. But CiA 402 takes 0x607D relative to the machine's home position:
    the drive corrects the limits by the home offset before comparing a target with them (corrected limit = limit
    − 0x607C, as drive manuals quote the profile), so with an offset the window the drive enforces is not the one
    acq wrote, and no read-back shows it. acq does not write limits it would have to shift by a convention it
    cannot check on the drive: it refuses to move such a drive, in one line, before anything is enabled."""
    with device_step(name, "reading 0x607D software position limits failed"):
        limits = node.sdo[od.SOFTWARE_POSITION_LIMIT]
        window = f"0x607D software position limits {int(limits[1].raw)} … {int(limits[2].raw)}"
    with device_step(name, "reading 0x607C home offset failed"):
        try:
            offset = int(node.sdo[od.HOME_OFFSET].raw)
        except SdoAbortedError:  # an optional object: a drive without homing has none
            info(f"{window}; the drive has no 0x607C home offset")
            return
    info(f"{window}; 0x607C home offset {offset} (position units)")
    if offset != 0:
        raise DeviceError(
            f"{name}: 0x607C home offset = {offset}: the drive takes 0x607D software position limits relative "
            "to its home position, shifted by the offset from 0x6064 position actual, in which acq sets the window of "
            "[limits] max_travel_deg — set 0x607C to 0 in the drive before acq moves the joint")
