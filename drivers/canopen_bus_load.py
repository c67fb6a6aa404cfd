"""The worst-case CAN bus load of the traffic a commanding CANopen drive puts on the bus, and the refusal of a
``[drive]`` whose load exceeds ``max_bus_load``: SYNC, the TPDO answering it, the heartbeat and the motion
thread's SDO status poll, each frame at its worst-case bit stuffing.
"""

from __future__ import annotations

from collections.abc import Sequence

from drivers.canopen_motion import STATUS_POLL_S
from drivers.config import DriveCanopen
from acqcore.errors import ConfigError


def frame_bits(data_bytes: int) -> int:
    """Worst-case length of a CAN 2.0A data frame on the wire, bits: 47 + 8·n plus stuff bits
    (one per 4 of the 34 + 8·n stuffed bits), interframe space included."""
    return 47 + 8 * data_bytes + (34 + 8 * data_bytes - 1) // 4


def bus_load(bitrate: float, period_s: float, tpdo_bytes: Sequence[int], *, sync_bytes: int = 1,
             heartbeat_period_s: float = 0.1, sdo_poll_s: float = STATUS_POLL_S) -> float:
    """Worst-case bus load (fraction of ``bitrate``, bit/s) of SYNC every ``period_s`` (s) with the
    TPDOs of ``tpdo_bytes`` answering each, a heartbeat and the motion thread's SDO status poll."""
    bits_per_s = ((frame_bits(sync_bytes) + sum(frame_bits(n) for n in tpdo_bytes)) / period_s
                  + frame_bits(1) / heartbeat_period_s + 2 * frame_bits(8) / sdo_poll_s)
    return bits_per_s / bitrate


def check_bus_load(s: DriveCanopen) -> float:
    """The load ``[drive]`` asks for; :class:`ConfigError` naming the figure if above ``max_bus_load`` (the
    TPDO's size within a CAN frame is a validator of :class:`DriveCanopen`)."""
    tpdo = [s.tpdo_bytes]
    load = bus_load(s.bitrate, s.period_s, tpdo, heartbeat_period_s=s.heartbeat_period_s)
    if load > s.max_bus_load:
        raise ConfigError(
            f"[drive] period_s = {s.period_s:g}, bitrate = {s.bitrate}: CAN bus load {load:.0%} > max_bus_load "
            f"{s.max_bus_load:.0%} (SYNC at {1 / s.period_s:g} Hz and a TPDO of {tpdo[0]} bytes, worst-case bit "
            "stuffing) — raise period_s or bitrate")
    return load
