"""The simulated drive's CAN controller on a python-can ``virtual`` channel: it answers SYNC "in hardware".

:class:`ControllerBus` queues the synchronous TPDOs of :class:`drivers.sim.can_node.SimCanNode` on the virtual bus
right behind the SYNC that triggers them, in the sender's thread, as a real controller does within microseconds — a
Python thread could not keep the CiA 301 synchronous window (TPDO k before SYNC k+1) on a loaded host, and the host
pairs each TPDO with the SYNC before it. SDO and NMT go through the LocalNode's own notifier thread as usual. The
controller's queue stays the last one of the channel whichever bus joins first (:class:`_ControllerLastChannel`), so
the SYNC reaches the host before the TPDO. An RPDO is handed over as it is delivered, in bus order.
"""

from __future__ import annotations

import queue
from collections.abc import Callable

import can
from can.interfaces.virtual import VirtualBus, channels, channels_lock


class _TriggerQueue(queue.Queue):
    """A receive queue that hands every SYNC to ``on_sync`` and every RPDO (COB-ID 0x200…0x57F) to ``on_rpdo``
    as it is delivered (in bus order: an RPDO sent before a SYNC is taken before that SYNC is answered)."""

    def __init__(self, on_sync: Callable[[], None], on_rpdo: Callable[[can.Message], None]) -> None:
        super().__init__()
        self._on_sync, self._on_rpdo = on_sync, on_rpdo

    def put(self, item: can.Message, block: bool = True, timeout: float | None = None) -> None:
        super().put(item, block, timeout)
        if item.is_extended_id:
            return
        if item.arbitration_id == 0x80:
            self._on_sync()
        elif 0x200 <= item.arbitration_id < 0x580:
            self._on_rpdo(item)


class _ControllerLastChannel(list):
    """A virtual channel's receive queues, kept with the drive controller's queue last: a bus that joins
    after the drive is inserted before it, so a SYNC is delivered to it before the TPDOs it triggers."""

    def append(self, item: queue.Queue) -> None:
        first_controller = next((i for i, q in enumerate(self) if isinstance(q, _TriggerQueue)), len(self))
        self.insert(first_controller, item)


class ControllerBus(VirtualBus):
    """The drive's end of a python-can ``virtual`` channel, answering SYNC at delivery (see the module doc)."""

    def __init__(self, channel: str, on_sync: Callable[[], None], on_rpdo: Callable[[can.Message], None]) -> None:
        with channels_lock:  # python-can's lock is re-entrant; the channel list must be ours before it is used
            channels.setdefault(channel, _ControllerLastChannel())
            super().__init__(channel=channel)
            self.channel.remove(self.queue)
            self.queue = _TriggerQueue(on_sync, on_rpdo)
            self.channel.append(self.queue)
