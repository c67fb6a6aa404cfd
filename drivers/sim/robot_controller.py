"""The simulated production robot's controller: a CANopen master that owns the simulated drive.

With ``[drive] motion = "external"`` the drive (:class:`drivers.sim.can_node.SimCanNode`) belongs to the robot's
controller, not to acq. :class:`SimRobotController` is that controller, a second canopen master on the same
python-can ``virtual`` channel. At start it does what a production master does at boot, over SDO: producer
heartbeat, SYNC counter (0x1019 = ``[drive] sync_counter_overflow``), its feedback TPDO (the COB-ID and mapping
the bench says the master set up, synchronous), RPDO1 = controlword + target velocity 0x60FF, mode of operation
cyclic synchronous velocity (9); then NMT OPERATIONAL. Then every ``period_s`` it sends RPDO1 and a SYNC: the
controlword walks the CiA 402 state machine to OPERATION ENABLED, the target velocity follows the robot
program (:class:`drivers.sim.robot_program.WindowReference`: point-to-point moves, pauses, the cycle's payload)
from the instant the drive is enabled.

Its bus counts every frame it sends by COB-ID (:attr:`SimRobotController.sent`), so a test that captures all
frames on the channel can tell the master's traffic from anything acq sends.
"""

from __future__ import annotations

import struct
import threading
import time
from collections import Counter

import canopen
import numpy as np
from can import Message
from can.interfaces.virtual import VirtualBus

from drivers.canopen_od import (CONTROLWORD, HEARTBEAT_TIME, MODE, MODE_CYCLIC_SYNC_VELOCITY, SYNC_OVERFLOW,
                                 TARGET_VELOCITY, drive_object_dictionary)
from drivers.canopen_stream import SYNC_COB_ID
from drivers.config import Bench, DriveCanopen
from acqcore.errors import ConfigError, DeviceError
from drivers.motion import RPM_TO_RAD_S
from drivers.sim.robot_program import WindowReference

#: cycles of controlword 0x06 (shutdown) and 0x07 (switch on) before 0x0F (enable operation)
_ENABLE_STEPS = (0x06, 0x07)
_CW_ENABLE = 0x0F
_HEARTBEAT_MS = 100
#: heartbeat periods the controller waits for the drive to report OPERATIONAL after NMT start (2 s): a drive that
#: takes longer is broken; a host loaded by the suite delayed a heartbeat beyond the 0.2 s one wait allows
_OPERATIONAL_WAIT_HEARTBEATS = 20
_RPDO = struct.Struct("<Hi")  # controlword u16, target velocity i32 (velocity units)
_GRID_CYCLES = 50  # program speeds computed per block of cycles (linear between them: the program is smooth)


class _CountingBus(VirtualBus):
    """A python-can virtual bus that counts the frames it sends, by arbitration ID."""

    def __init__(self, channel: str) -> None:
        super().__init__(channel=channel)
        self.sent: Counter[int] = Counter()
        self._count_lock = threading.Lock()

    def send(self, msg: Message, timeout: float | None = None) -> None:
        super().send(msg, timeout)
        with self._count_lock:
            self.sent[msg.arbitration_id] += 1


class SimRobotController:
    """The robot controller of ``bench`` running ``program``; its feedback TPDO is ``tpdo`` (1…4) with ``cob_id``
    and CiA 301 mapping ``entries``."""

    def __init__(self, bench: Bench, program: WindowReference, tpdo: int, cob_id: int,
                 entries: tuple[int, ...]) -> None:
        s = bench.drive
        assert isinstance(s, DriveCanopen)
        self._s, self._program = s, program
        self._tpdo, self._cob_id, self._entries = tpdo, cob_id, entries
        self._bus: _CountingBus | None = None
        self._network: canopen.Network | None = None
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self.syncs = 0
        self._grid_t, self._grid_v = np.array([np.inf]), np.zeros(1)

    @property
    def sent(self) -> Counter[int]:
        """Frames this master sent, by COB-ID."""
        return Counter() if self._bus is None else Counter(self._bus.sent)

    def start(self) -> None:
        """Configure the drive over SDO, NMT start it, start the cyclic RPDO + SYNC thread."""
        s = self._s
        self._bus = _CountingBus(s.channel)
        self._network = canopen.Network(self._bus)
        self._network.connect()
        node = canopen.RemoteNode(s.node_id, drive_object_dictionary(s.node_id))
        self._network.add_node(node)
        node.sdo.RESPONSE_TIMEOUT = s.sdo_timeout_s
        try:
            node.sdo[HEARTBEAT_TIME].raw = _HEARTBEAT_MS
            node.sdo[SYNC_OVERFLOW].raw = s.sync_counter_overflow
            self._map(node.tpdo[self._tpdo], self._cob_id, self._entries)
            self._map(node.rpdo[1], 0x200 + s.node_id, ((CONTROLWORD << 16) | 16, (TARGET_VELOCITY << 16) | 32))
            node.sdo[MODE].raw = MODE_CYCLIC_SYNC_VELOCITY
            node.nmt.state = "OPERATIONAL"
            # the drive must be OPERATIONAL before its first RPDO counts: wait for its heartbeat to say so
            # (canopen sets the master's view of the state as it sends the command)
            self._wait_operational(node)
        except BaseException as e:
            self.stop()
            if not isinstance(e, (canopen.sdo.SdoAbortedError, canopen.sdo.SdoCommunicationError,
                                  canopen.nmt.NmtError)):
                raise
            raise DeviceError(f"simulated robot controller: configuring drive {s.node_id} failed: {e}") from None
        self._stop.clear()
        self._thread = threading.Thread(target=self._run, name="sim-robot-controller", daemon=True)
        self._thread.start()

    @staticmethod
    def _wait_operational(node: canopen.RemoteNode) -> None:
        """Return once ``node``'s heartbeat reports OPERATIONAL, else raise :class:`DeviceError` after
        :data:`_OPERATIONAL_WAIT_HEARTBEATS` heartbeat periods.

        canopen's ``wait_for_heartbeat`` raises ``NmtError`` when no heartbeat came within its timeout; a heartbeat
        late on a loaded host (the drive's thread shares the CPU and the GIL with the recorder's) is waited for again
        until the deadline instead of failing the start."""
        period_s = _HEARTBEAT_MS * 1e-3
        deadline = time.monotonic() + _OPERATIONAL_WAIT_HEARTBEATS * period_s
        while True:
            try:
                if node.nmt.wait_for_heartbeat(2 * period_s) == "OPERATIONAL":
                    return
            except canopen.nmt.NmtError:
                pass  # no heartbeat within two periods: late, not yet lost
            if time.monotonic() > deadline:
                raise DeviceError(f"simulated robot controller: drive {node.id} not OPERATIONAL within "
                                  f"{_OPERATIONAL_WAIT_HEARTBEATS * period_s:g} s")

    @staticmethod
    def _map(pdo: canopen.pdo.PdoMap, cob_id: int, entries: tuple[int, ...]) -> None:
        pdo.clear()
        for e in entries:
            try:
                pdo.add_variable(e >> 16, (e >> 8) & 0xFF, e & 0xFF)
            except KeyError:
                raise ConfigError(f"[drive] the simulated drive has no object 0x{e >> 16:04X} to map "
                                  f"(entry 0x{e:08X})") from None
        pdo.cob_id, pdo.trans_type, pdo.enabled = cob_id, 1, True
        pdo.save()

    def stop(self) -> None:
        """Stop the cyclic traffic and leave the bus. Idempotent."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(2.0)
            self._thread = None
        if self._network is not None:
            self._network.disconnect()
            self._network = None

    def _speed_at(self, u_s: float) -> float:
        """The program's speed (rad/s) at program time ``u_s`` (s), from a grid computed a block ahead (the
        program's numpy evaluation per cycle would cost the 1 kHz loop its timing)."""
        if not self._grid_t[0] <= u_s <= self._grid_t[-1]:
            self._grid_t = u_s + np.arange(_GRID_CYCLES + 1) * self._s.period_s
            self._grid_v = self._program.reference(self._grid_t)[0]
        return float(np.interp(u_s, self._grid_t, self._grid_v))

    def _run(self) -> None:
        """Every period: RPDO1 (controlword, the program's target velocity), then SYNC (with its counter). A
        late thread catches up the SYNCs it owes (the drive's cycle count stays with the clock)."""
        s = self._s
        period, overflow, units = s.period_s, s.sync_counter_overflow, s.velocity_units_per_rpm
        t0, k = time.monotonic(), 0
        steps = len(_ENABLE_STEPS)
        while not self._stop.is_set():
            wait = t0 + k * period - time.monotonic()
            if wait > 0 and self._stop.wait(wait):
                return
            if k < steps:
                cw, speed = _ENABLE_STEPS[k], 0.0
            else:  # the program runs on the SYNC cycles from the one the drive is enabled in
                cw, speed = _CW_ENABLE, self._speed_at((k - steps + 1) * period)
            rpdo = _RPDO.pack(cw, round(speed / RPM_TO_RAD_S * units))
            self._network.send_message(0x200 + s.node_id, rpdo)
            self._network.send_message(SYNC_COB_ID, bytes([k % overflow + 1]) if overflow else b"")
            self.syncs += 1
            k += 1
