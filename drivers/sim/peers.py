"""Simulated peers behind plain adapters: the simulator puts itself together on the sim side.

A bench with ``[drive] simulated_node = true`` (CANopen) or ``simulated_device = true`` (serial) gets
the *real* adapter (:class:`drivers.canopen_drive.CanopenDrive` on a ``virtual`` channel,
:class:`drivers.serial_drive.SerialDrive` on a pseudo-terminal) with a simulated drive on the other
end of the wire, built here and started/stopped around the adapter — as ophyd-async's core swaps in
its mock backend. The registry (:mod:`drivers.registry`) chooses these factories by name; the real
adapters never import, build or own their simulated peer.
"""

from __future__ import annotations

from typing import Any, Protocol

from drivers import canopen_drive, serial_drive
from drivers.base import Drive, DriveInfo
from drivers.canopen_eds import passive_tpdo
from drivers.canopen_od import STATUSWORD, tpdo_cob_id
from drivers.config import Bench, DriveCanopen, DriveSerial
from drivers.config_drive import POSITION_ACTUAL_ENTRY
from acqcore.errors import ConfigError
from drivers.sim.bench import SimBench
from drivers.sim.can_node import SimCanNode
from drivers.sim.robot_controller import SimRobotController
from drivers.sim.serial_device import SimSerialDevice, open_simulated_device


class SimulatedPeer(Protocol):
    """The simulated drive on the other end of the wire."""

    def start(self) -> None:
        """Join the channel / start serving the port."""
        ...

    def stop(self) -> None:
        """Leave / close. Idempotent."""
        ...


class DriveWithPeer:
    """A real drive adapter and the simulated device it talks to, started and stopped together.

    Implements :class:`drivers.base.Drive` by delegating to ``adapter`` (any other attribute too, e.g.
    ``keep_raw_frames`` or ``stats``); :meth:`start` starts the peer first, :meth:`stop` stops it after
    the adapter, also when the adapter's start fails.

    Parameters
    ----------
    adapter : the plain adapter, pointed at the peer's channel or port.
    peer : the simulated drive on the other end.
    """

    def __init__(self, adapter: Drive, peer: SimulatedPeer) -> None:
        self.adapter, self.peer = adapter, peer

    def start(self) -> DriveInfo:
        """Start the peer, then the adapter; on any failure stop both and re-raise."""
        try:
            self.peer.start()
            return self.adapter.start()
        except BaseException:
            self.stop()
            raise

    def stop(self) -> None:
        """Stop the adapter, then the peer (both idempotent)."""
        try:
            self.adapter.stop()
        finally:
            self.peer.stop()

    def __getattr__(self, name: str) -> Any:
        return getattr(self.adapter, name)


class CanopenWithSimNode(DriveWithPeer):
    """A :class:`~drivers.canopen_drive.CanopenDrive` and the :class:`SimCanNode` on its virtual channel."""

    @property
    def sim_node(self) -> SimCanNode:
        """The simulated CiA 402 drive (tests steer its faults)."""
        return self.peer  # type: ignore[return-value]


class RobotCell:
    """The simulated drive and the production robot's controller that owns it, as one :class:`SimulatedPeer`:
    the drive joins the bus first, the controller configures and runs it."""

    def __init__(self, node: SimCanNode, controller: SimRobotController) -> None:
        self.node, self.controller = node, controller

    def start(self) -> None:
        self.node.start()
        self.controller.start()

    def stop(self) -> None:
        try:
            self.controller.stop()
        finally:
            self.node.stop()


class CanopenWithRobot(DriveWithPeer):
    """A listening :class:`~drivers.canopen_drive.CanopenDrive` on the bus of a simulated robot cell."""

    @property
    def sim_node(self) -> SimCanNode:
        """The simulated CiA 402 drive."""
        return self.peer.node  # type: ignore[attr-defined]

    @property
    def controller(self) -> SimRobotController:
        """The robot's CANopen master (SYNC, RPDO set-points, NMT)."""
        return self.peer.controller  # type: ignore[attr-defined]


#: the simulated master's own feedback TPDO when acq maps its own (configure = true): statusword + position
_MASTER_FEEDBACK = ((STATUSWORD << 16) | 16, POSITION_ACTUAL_ENTRY)


def _robot_cell(bench: Bench, sim_bench: SimBench) -> RobotCell:
    """The drive and its master for a listening bench; the master sets up the TPDO the bench says it did."""
    s = bench.drive
    assert isinstance(s, DriveCanopen) and sim_bench.robot_program is not None
    if s.configure:
        if s.tpdo == 1:
            raise ConfigError("[drive] tpdo = 1 with configure = true: the simulated robot's master uses TPDO1 "
                              "for its own feedback — give acq another one (2…4)")
        number, cob_id, entries = 1, tpdo_cob_id(1, s.node_id), _MASTER_FEEDBACK
    else:
        machine = passive_tpdo(s)
        number, cob_id, entries = s.tpdo, machine.cob_id, machine.entries
    controller = SimRobotController(bench, sim_bench.robot_program, number, cob_id, entries)
    return RobotCell(SimCanNode(bench, sim_bench), controller)


class _PtyPeer:
    """A :class:`SimSerialDevice` as a :class:`SimulatedPeer`: it serves its pty from construction on, and
    ``stop`` closes it."""

    def __init__(self, device: SimSerialDevice) -> None:
        self.device = device

    def start(self) -> None:
        """Nothing to do: the device's thread runs since it opened the pty."""

    def stop(self) -> None:
        self.device.close()


def open_canopen_with_sim_node(bench: Bench, sim_bench: SimBench | None, fast: bool) -> CanopenWithSimNode:
    """Registry factory for ``[drive] driver = "canopen"`` with ``simulated_node = true`` (with ``motion =
    "external"``: the drive owned by a simulated robot controller, :class:`RobotCell`, acq listening).

    Refuses (``ConfigError``) ``--fast``: a CAN bus runs in real time (``interface = "virtual"`` is a
    validator of :class:`DriveCanopen`).
    """
    s = bench.drive
    assert isinstance(s, DriveCanopen) and sim_bench is not None
    if fast:
        raise ConfigError("--fast: the simulated CANopen drive runs on the bus in real time; run without --fast")
    adapter = canopen_drive.open_drive(bench, None, fast)
    if s.motion == "external":  # the robot's own master owns the drive; acq listens
        return CanopenWithRobot(adapter, _robot_cell(bench, sim_bench))
    return CanopenWithSimNode(adapter, SimCanNode(bench, sim_bench))


def open_serial_with_sim_device(bench: Bench, sim_bench: SimBench | None, fast: bool) -> DriveWithPeer:
    """Registry factory for ``[drive] driver = "serial"`` with ``simulated_device = true``: a
    :class:`~drivers.serial_drive.SerialDrive` on the pty of a :class:`SimSerialDevice` streaming ``sim_bench``."""
    s = bench.drive
    assert isinstance(s, DriveSerial)
    device = open_simulated_device(bench, sim_bench)
    try:
        on_pty = bench.model_copy(update={"drive": s.model_copy(update={"port": device.port_name})})
        adapter = serial_drive.open_drive(on_pty, None, fast)
    except BaseException:
        device.close()
        raise
    return DriveWithPeer(adapter, _PtyPeer(device))
