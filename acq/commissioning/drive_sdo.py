"""What ``acq selftest`` reads back from a CANopen drive by SDO, over a second connection to the bus (the adapter's
own client is idle before motion): its identity (0x1018), its software position limits (0x607D) and home offset
(0x607C). A read the bus or an SDO refuses gives its reason as one string (the selftest reports it), not an exception.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, TypeVar

from drivers.config import DriveCanopen

#: The sub-indices of the identity object 0x1018 (CiA 301; only the vendor ID, 1, is mandatory).
IDENTITY = {"vendor": 1, "product": 2, "revision": 3, "serial": 4}
T = TypeVar("T")


def read_identity(settings: DriveCanopen) -> dict[str, int] | str:
    """The drive's identity object 0x1018 by SDO from a second connection to the bus (the adapter's own
    client is idle before motion); the reason as a string when it cannot be read."""
    import canopen

    def identity(node: Any) -> dict[str, int]:
        found: dict[str, int] = {}
        for name, sub in IDENTITY.items():
            try:
                found[name] = int.from_bytes(node.sdo.upload(0x1018, sub), "little")
            except canopen.SdoAbortedError:
                if sub == 1:
                    raise
        return found

    return _by_sdo(settings, identity)


def read_position_frame(settings: DriveCanopen) -> str:
    """The 0x607D software position limits the drive holds and its 0x607C home offset, in words, by SDO from a
    second connection (as :func:`read_identity`). The adapter has refused a home offset other than 0 before motion
    (:meth:`drivers.canopen_drive.CanopenDrive.start`), so on a bench that got this far it reads 0 or is absent."""
    import canopen

    def frame(node: Any) -> str:
        low, high = (int.from_bytes(node.sdo.upload(0x607D, sub), "little", signed=True) for sub in (1, 2))
        window = "none set" if (low, high) == (-2**31, 2**31 - 1) else f"{low} … {high}"
        try:
            offset = f"0x607C home offset {int.from_bytes(node.sdo.upload(0x607C, 0), 'little', signed=True)}"
        except canopen.SdoAbortedError:
            offset = "no 0x607C home offset"
        return f"0x607D window {window}, {offset}"

    return _by_sdo(settings, frame)


def _by_sdo(settings: DriveCanopen, read: Callable[[Any], T]) -> T | str:
    """``read(node)`` on the drive as a RemoteNode of a second connection to the bus; the reason as a string when
    the bus or an SDO fails."""
    import can
    import canopen
    from canopen.objectdictionary import ObjectDictionary
    from canopen.sdo.exceptions import SdoError

    network = canopen.Network()
    try:
        network.connect(interface=settings.interface, channel=settings.channel, bitrate=settings.bitrate)
        node = network.add_node(canopen.RemoteNode(settings.node_id, ObjectDictionary()))
        node.sdo.RESPONSE_TIMEOUT = settings.sdo_timeout_s
        return read(node)
    except (SdoError, OSError, can.CanError) as e:
        return f"not readable ({e})"
    finally:
        network.disconnect()
