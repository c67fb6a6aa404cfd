"""A simulated CiA 402 servo drive speaking real CANopen on a python-can ``virtual`` bus.

:class:`SimCanNode` is a :class:`canopen.LocalNode` (SDO server, NMT slave, heartbeat producer) on its
own :class:`canopen.Network`, on the same virtual channel as the host's — as canopen's
``test/test_local.py`` pairs a RemoteNode with a LocalNode. Its object dictionary is
:func:`drivers.canopen_od.drive_object_dictionary`, served over SDO, and it adds what a LocalNode
lacks: TPDOs sent on SYNC by their mapping in 0x1800…/0x1A00… (remappable over SDO, transmission type
1…240 = every n-th SYNC, in NMT OPERATIONAL only), a minimal CiA 402 state machine (controlword →
statusword, quick stop ending in SWITCH ON DISABLED once at rest) and Profile Position: the
new-set-point handshake feeds :class:`drivers.sim.pp_generator.ProfileGenerator`, which becomes the
:class:`~drivers.sim.bench.SimBench` speed reference (0x607A, 0x6081, 0x6083, 0x6084, 0x6085). A set-point
latches 0x6081/0x6083/0x6084 as they are when it is accepted (as CiA 402 drives do): a change written while a
move runs or is buffered acts from the next new set-point on — what a speed-dithered profile relies on
(:mod:`drivers.canopen_motion`). A disable while moving ramps the reference to rest at the quick-stop deceleration
(the bench's speed loop cannot let the motor coast).

The drive's CAN controller answers SYNC "in hardware" (:mod:`drivers.sim.can_controller`): the synchronous TPDOs
follow the SYNC that triggers them on the virtual bus, sent in the sender's thread; SDO and NMT go through the
LocalNode's own notifier thread as usual. The drive's clock (one cycle per SYNC) and what a TPDO or an SDO upload
carries at a cycle (0x6064, 0x606C, 0x606B, 0x1013) are :mod:`drivers.sim.can_node_clock`.

Cyclic synchronous velocity (mode 9, ``[drive] motion = "external"``: a master such as
:class:`drivers.sim.robot_controller.SimRobotController` owns the drive): RPDO1 (0x1400/0x1600, remappable over SDO)
is taken off the bus by the controller as it arrives and applied at the next SYNC — its controlword walks the state
machine, its target velocity 0x60FF becomes the :class:`~drivers.sim.csv_reference.SetpointReference` the bench
follows, :data:`SETPOINT_DELAY_CYCLES` after that SYNC.

Fault switches, for tests: :meth:`~SimCanNode.drop_tpdos`, :meth:`~SimCanNode.stop_heartbeat`,
``refuse_mode_change`` (0x6060 writes are ignored), ``has_timestamp`` (set False before :meth:`~SimCanNode.start`:
a drive without 0x1013), ``home_offset`` (0x607C at power-on, None: a drive without it; stored only — acq refuses to
move a drive with a home offset, :meth:`drivers.canopen_drive.CanopenDrive.start`), ``reject_mapping`` (0x1A0x keeps its
power-on mapping while the SDO writes succeed — a mismatch only a read-back finds) and ``reject_limits`` (the same
for the limits 0x607F, 0x6072, 0x607D).

Limits: a set-point's target is clamped to the 0x607D software position limits and its speed to the 0x607F max
profile velocity, as a CiA 402 drive does. 0x6072 max torque (per mille of 0x6076 motor rated torque; power-on 300 %)
clamps the simulated speed loop's torque (:meth:`~drivers.sim.bench.SimBench.set_torque_limit`), and while it does
the statusword's bit 11 "internal limit active" is set (CiA 402), as read by SDO.
"""

from __future__ import annotations

import threading
from typing import Any

import can
import canopen

from drivers.canopen_od import (HIGH_RES_TIMESTAMP, HOME_OFFSET, MAX_PROFILE_VELOCITY, MAX_TORQUE,
                                 MODE_CYCLIC_SYNC_VELOCITY, MODE_PROFILE_POSITION, MOTOR_RATED_TORQUE, N_TPDO, PDO_INVALID,
                                 RPDO_COMM, RPDO_MAP, SOFTWARE_POSITION_LIMIT, TARGET_VELOCITY, TPDO_COMM, TPDO_MAP,
                                 drive_object_dictionary)
from drivers.config import Bench, DriveCanopen
from acqcore.errors import ConfigError
from drivers.motion import RPM_TO_RAD_S
from drivers.sim.bench import SimBench
from drivers.sim.can_controller import ControllerBus
from drivers.sim.can_node_clock import DriveClock
from drivers.sim.csv_reference import SetpointReference
from drivers.sim.pp_generator import ProfileGenerator

SOD, RTSO, SO, OE, QSA = 0x40, 0x21, 0x23, 0x27, 0x07  # CiA 402 statusword state bits
REMOTE, TARGET_REACHED, INTERNAL_LIMIT, SETPOINT_ACK = 1 << 9, 1 << 10, 1 << 11, 1 << 12
HISTORY_EVERY = 64
#: A cyclic set-point acts this many cycles after the SYNC that applies it, a set-point buffer (a real drive
#: delays by one or two cycles; here it only shifts the master's program in time). What the bench computed must
#: not change: the drive computes its samples CACHE_CYCLES (drivers.sim.can_node_clock) ahead, and the simulated
#: DAQ reads the bench by the host clock, which a stalled SYNC master's cycles lag (catching up in bursts) — 250 ms
#: covers the lags measured on a loaded 2-core host; a later set-point is dropped and counted (SetpointReference.late)
SETPOINT_DELAY_CYCLES = 250


class SimCanNode:
    """The simulated drive of ``bench`` on ``sim_bench``; :meth:`start` puts it on the bus."""

    def __init__(self, bench: Bench, sim_bench: SimBench) -> None:
        s = bench.drive
        assert isinstance(s, DriveCanopen)
        if s.counts_per_rev not in (None, bench.encoder.counts_per_rev):
            raise ConfigError("[drive] counts_per_rev: the simulated node counts in [encoder] counts_per_rev")
        self._s, self._bench = s, sim_bench
        self._period_s = s.period_s
        self._clock = DriveClock(sim_bench, s.period_s)
        self.generator = ProfileGenerator()
        self.external = getattr(s, "motion", "commanded") == "external"
        self.setpoints = SetpointReference(s.period_s)
        self._rpdo: bytes | None = None  # RPDO1 received since the last SYNC
        self._rpdo_layout: tuple[int, list[tuple[int, int, int]]] | None = None  # (COB-ID or -1, [(index, sub, bytes)])
        self.rpdos = 0
        self.network: canopen.Network | None = None
        self.node: canopen.LocalNode | None = None
        self._consumer = f"can-node@{id(self):x}"
        self._syncs = 0
        self._state = SOD
        self._mode = 0
        self._setpoint_latched = False
        self._tpdos: list[tuple[int, int, list[tuple[int, int, int]]]] | None = None
        self._drop = 0
        self._lock = threading.RLock()  # the bus thread (SDO, NMT) and the SYNC sender's thread share the node
        self.refuse_mode_change = False
        self.has_timestamp = True
        self.home_offset: int | None = 0  # power-on 0x607C (None: no such object); nothing is shifted by it
        self.reject_mapping = False
        self.reject_limits = False
        sim_bench.hold_history(self._consumer, 0.0)

    # ---- fault switches ----------------------------------------------------------------------------
    def drop_tpdos(self, count: int) -> None:
        """Do not send the next ``count`` TPDOs (the host sees a gap in the SYNC counter)."""
        self._drop += count

    def stop_heartbeat(self) -> None:
        """Stop producing heartbeats (SDO, SYNC and TPDOs carry on)."""
        self.node.nmt.stop_heartbeat()

    # ---- life cycle --------------------------------------------------------------------------------
    def start(self) -> None:
        """Join the virtual bus, boot (boot-up message) into NMT PRE-OPERATIONAL."""
        self._bench.use_reference(self.setpoints if self.external else self.generator)
        self.network = canopen.Network(ControllerBus(self._s.channel, self._on_sync, self._on_rpdo))
        self.network.connect()
        dictionary = drive_object_dictionary(self._s.node_id)
        if not self.has_timestamp:
            del dictionary[HIGH_RES_TIMESTAMP]
        if self.home_offset is None:
            del dictionary[HOME_OFFSET]
        self.node = canopen.LocalNode(self._s.node_id, dictionary)
        self.network.add_node(self.node)
        if self.home_offset:
            self.node.sdo[HOME_OFFSET].raw = self.home_offset
        self.node.add_read_callback(self._on_read)
        self.node.add_write_callback(self._on_write)
        self.node.nmt.state = "INITIALISING"
        self.node.nmt.state = "PRE-OPERATIONAL"
        self._limit_torque(self._param(MAX_TORQUE), self._param(MOTOR_RATED_TORQUE))

    def stop(self) -> None:
        """Leave the bus. Idempotent."""
        if self.network is not None:
            self.node.nmt.stop_heartbeat()
            self.network.disconnect()
            self.network = None
        self._bench.release_history(self._consumer)

    @property
    def state_402(self) -> int:
        """The CiA 402 state bits of the statusword (e.g. 0x40 SWITCH ON DISABLED, 0x27 OPERATION ENABLED)."""
        with self._lock:
            self._settle()
            return self._state

    @property
    def first_cycle(self) -> int | None:
        """Drive cycle of the first SYNC (SYNC index 0); None before it."""
        return self._clock.first_cycle

    # ---- SDO ---------------------------------------------------------------------------------------
    def _on_read(self, index: int, subindex: int, od: Any) -> int | None:
        with self._lock:
            return self._read(index, subindex, od)

    def _read(self, index: int, subindex: int, od: Any) -> int | None:
        if index == 0x6041:
            return self._statusword()
        if index == 0x6061:
            return self._mode
        if index == 0x6064:
            return self._clock.sample()[0]
        if index == 0x606C:
            return round(self._clock.sample()[1] / RPM_TO_RAD_S * self._s.velocity_units_per_rpm)
        if index == 0x606B:
            return round(self._clock.sample()[3] / RPM_TO_RAD_S * self._s.velocity_units_per_rpm)
        if index == HIGH_RES_TIMESTAMP:
            return self._clock.sample()[2]
        if self.reject_mapping and TPDO_MAP <= index < TPDO_MAP + N_TPDO:
            return od.default
        if self.reject_limits and index in (MAX_PROFILE_VELOCITY, MAX_TORQUE, SOFTWARE_POSITION_LIMIT):
            return od.default
        return None

    def _on_write(self, index: int, subindex: int, od: Any, data: bytes) -> None:
        with self._lock:
            self._write(index, od, data)

    def _write(self, index: int, od: Any, data: bytes) -> None:
        if TPDO_COMM <= index < TPDO_COMM + N_TPDO or TPDO_MAP <= index < TPDO_MAP + N_TPDO:
            self._tpdos = None
        elif index in (RPDO_COMM, RPDO_MAP):
            self._rpdo_layout = None
        elif index == MAX_TORQUE and not self.reject_limits:
            self._limit_torque(od.decode_raw(data), self._param(MOTOR_RATED_TORQUE))
        elif index == MOTOR_RATED_TORQUE:
            self._limit_torque(self._param(MAX_TORQUE), od.decode_raw(data))
        elif index == 0x6060 and not self.refuse_mode_change:
            self._mode = od.decode_raw(data)
        elif index == 0x6040:
            self._controlword(od.decode_raw(data))
        elif index == TARGET_VELOCITY and self._state == OE and self._mode == MODE_CYCLIC_SYNC_VELOCITY:
            speed = od.decode_raw(data) / self._s.velocity_units_per_rpm * RPM_TO_RAD_S
            self.setpoints.push(self._setpoint_time_s(), speed)

    def _param(self, index: int) -> int:
        return int(self.node.sdo[index].raw)

    def _limit_torque(self, per_mille: int, rated_mNm: int) -> None:
        """0x6072 max torque (‰ of 0x6076 rated torque, mN·m) into the simulated speed loop (the written value: the
        write callback runs before canopen stores it)."""
        self._bench.set_torque_limit(per_mille * 1e-3 * rated_mNm * 1e-3)

    # ---- CiA 402 -----------------------------------------------------------------------------------
    def _settle(self) -> None:
        """Quick stop ends in SWITCH ON DISABLED once at rest (quick stop option code 2)."""
        if self._state == QSA and self.generator.at_rest(self._clock.now_s()):
            self._state = SOD

    def _statusword(self) -> int:
        self._settle()
        sw = self._state | REMOTE
        if self._state in (OE, QSA):
            now = self._clock.now_s()
            if self.generator.at_rest(now):
                sw |= TARGET_REACHED
            if self._setpoint_latched or self.generator.pending(now):
                sw |= SETPOINT_ACK
            if self._bench.torque_limited_at(now):
                sw |= INTERNAL_LIMIT
        return sw

    def _ramp_to_rest(self) -> None:
        if self._mode == MODE_CYCLIC_SYNC_VELOCITY:  # the master's set-points stop; the drive's ramp is one cycle
            self.setpoints.push(self._setpoint_time_s(), 0.0)
            return
        decel = self._param(0x6085) or self._param(0x6084)
        self.generator.stop(self._clock.now_s(),
                            max(decel, 1) / self._s.acceleration_units_per_rpm_per_s * RPM_TO_RAD_S)

    def _controlword(self, cw: int) -> None:
        self._settle()
        state = self._state
        if cw & 0x02 == 0:                      # disable voltage
            if state in (OE, QSA):
                self._ramp_to_rest()
            self._state = SOD
        elif cw & 0x06 == 0x02:                 # quick stop
            if state == OE:
                self._ramp_to_rest()
                self._state = QSA
            elif state in (RTSO, SO):
                self._state = SOD
        elif cw & 0x8F == 0x06 and state in (SOD, SO, OE):   # shutdown
            if state == OE:
                self._ramp_to_rest()
            self._state = RTSO
        elif cw & 0x8F == 0x07 and state in (RTSO, OE):      # switch on
            if state == OE:
                self._ramp_to_rest()
            self._state = SO
        elif cw & 0x8F == 0x0F and state in (SO, QSA):       # enable operation
            if state == SO:
                self.generator.hold_at(self._clock.theta_rad())
            self._state = OE
        new_setpoint = bool(cw & 0x10)
        if self._state == OE and self._mode == MODE_PROFILE_POSITION and new_setpoint and not self._setpoint_latched:
            self._setpoint_latched = self._accept_setpoint()
        elif not new_setpoint:
            self._setpoint_latched = False

    def _accept_setpoint(self) -> bool:
        """Latch 0x607A into the generator unless a set-point is already buffered."""
        now = self._clock.now_s()
        if self.generator.pending(now):
            return False
        cmd = self.generator.commanded_rad
        limits = self.node.sdo[SOFTWARE_POSITION_LIMIT]  # the target clamped to them, the speed to 0x607F
        target = min(max(self._param(0x607A), int(limits[1].raw)), int(limits[2].raw))
        steps = (target - self._clock.register(cmd) + 2**31) % 2**32 - 2**31
        v_units, a_units = self._s.velocity_units_per_rpm, self._s.acceleration_units_per_rpm_per_s
        self.generator.move_to(cmd + steps * self._clock.rad_per_count, now,
                               min(self._param(0x6081), self._param(MAX_PROFILE_VELOCITY)) / v_units * RPM_TO_RAD_S,
                               max(self._param(0x6083), 1) / a_units * RPM_TO_RAD_S,
                               max(self._param(0x6084), 1) / a_units * RPM_TO_RAD_S)
        return True

    # ---- SYNC → TPDOs ------------------------------------------------------------------------------
    def _tpdo_table(self) -> list[tuple[int, int, list[tuple[int, int, int]]]]:
        """(COB-ID, transmission type, [(index, subindex, bytes)]) of every valid TPDO, read via the OD."""
        table = []
        for n in range(N_TPDO):
            cob = self.node.sdo[TPDO_COMM + n][1].raw
            kind = self.node.sdo[TPDO_COMM + n][2].raw
            mapping = self.node.sdo[TPDO_MAP + n]
            entries = [mapping[i].raw for i in range(1, mapping[0].raw + 1)]
            if not cob & PDO_INVALID and 1 <= kind <= 240:
                table.append((cob & 0x7FF, kind, [(e >> 16, (e >> 8) & 0xFF, (e & 0xFF) // 8) for e in entries]))
        return table

    def _on_sync(self) -> None:
        with self._lock:
            self._sync()

    def _setpoint_time_s(self) -> float:
        """When a cyclic set-point applied at this SYNC takes effect, s of drive time: one cycle of interpolation
        plus SETPOINT_DELAY_CYCLES after the drive's present cycle (the master's program runs on the SYNC cycles,
        so set-points arrive one per cycle, evenly spaced whatever the host's timing)."""
        return (self._clock.now_cycle() + 1 + SETPOINT_DELAY_CYCLES) * self._period_s

    def _on_rpdo(self, msg: can.Message) -> None:
        with self._lock:
            if self.node is None or self.node.nmt.state != "OPERATIONAL":
                return
            if self._rpdo_layout is None:
                cob, mapping = int(self.node.sdo[RPDO_COMM][1].raw), self.node.sdo[RPDO_MAP]
                entries = [mapping[i].raw for i in range(1, mapping[0].raw + 1)]
                self._rpdo_layout = (-1 if cob & PDO_INVALID else cob & 0x7FF,
                                     [(e >> 16, (e >> 8) & 0xFF, (e & 0xFF) // 8) for e in entries])
            if msg.arbitration_id == self._rpdo_layout[0]:
                self._rpdo = bytes(msg.data)

    def _apply_rpdo(self) -> None:
        """Write the RPDO1 received before this SYNC into the objects it maps (through the write callbacks)."""
        data, self._rpdo = self._rpdo, None
        at = 0
        for index, subindex, size in self._rpdo_layout[1]:
            self.node.set_data(index, subindex, data[at:at + size])
            at += size
        self.rpdos += 1

    def _sync(self) -> None:
        cycle = self._clock.tick()
        self._syncs += 1
        if cycle % HISTORY_EVERY == 0:
            self._bench.hold_history(self._consumer, cycle * self._period_s)
        if self.node.nmt.state != "OPERATIONAL":
            return
        if self._rpdo is not None and self._rpdo_layout is not None:
            self._apply_rpdo()
        if self._tpdos is None:
            self._tpdos = self._tpdo_table()
        for cob, kind, entries in self._tpdos:
            if self._syncs % kind:
                continue
            if self._drop > 0:
                self._drop -= 1
                continue
            payload = b"".join(self.node.get_data(i, sub)[:size] for i, sub, size in entries)
            self.network.send_message(cob, payload)

