"""The CiA 301 / CiA 402 objects ``acq`` uses, as a canopen object dictionary built in code.

The host needs an object dictionary to talk to a drive (data types for SDO, PDO map entries); a real
drive's EDS would do, but only the standard objects below are ever touched, so ``acq`` carries them
itself and needs no vendor file. The simulated drive (:mod:`drivers.sim.can_node`) serves the same
dictionary, with its ``default`` values as the power-on state. Imports :mod:`canopen` (only adapters
that chose CANopen import this module).
"""

from __future__ import annotations

from canopen import ObjectDictionary
from canopen.objectdictionary import (INTEGER8, INTEGER32, UNSIGNED8, UNSIGNED16, UNSIGNED32, ODRecord,
                                      ODVariable)

DEVICE_TYPE = 0x1000
HEARTBEAT_TIME = 0x1017
SYNC_OVERFLOW = 0x1019
HIGH_RES_TIMESTAMP = 0x1013
TPDO_COMM = 0x1800
TPDO_MAP = 0x1A00
RPDO_COMM = 0x1400
RPDO_MAP = 0x1600
CONTROLWORD = 0x6040
STATUSWORD = 0x6041
MODE = 0x6060
MODE_DISPLAY = 0x6061
POSITION_ACTUAL = 0x6064
VELOCITY_ACTUAL = 0x606C
VELOCITY_DEMAND = 0x606B
TARGET_POSITION = 0x607A
TARGET_VELOCITY = 0x60FF
PROFILE_VELOCITY = 0x6081
PROFILE_ACCELERATION = 0x6083
PROFILE_DECELERATION = 0x6084
QUICK_STOP_DECELERATION = 0x6085
MAX_TORQUE = 0x6072  # per mille of 0x6076
MOTOR_RATED_TORQUE = 0x6076  # mN·m
SOFTWARE_POSITION_LIMIT = 0x607D  # sub 1 min, sub 2 max, position units
HOME_OFFSET = 0x607C  # position units
MAX_PROFILE_VELOCITY = 0x607F  # velocity units
SUPPORTED_MODES = 0x6502

MODE_PROFILE_POSITION = 1
MODE_CYCLIC_SYNC_VELOCITY = 9
PDO_INVALID = 1 << 31
RTR_NOT_ALLOWED = 1 << 30
N_TPDO = 4
#: power-on TPDO1 mapping of the simulated drive: the statusword alone (as many drives ship)
DEFAULT_TPDO1_MAP = (STATUSWORD << 16) | 16


def tpdo_cob_id(tpdo: int, node_id: int) -> int:
    """COB-ID of TPDO ``tpdo`` (1…4) in the predefined connection set."""
    return 0x180 + 0x100 * (tpdo - 1) + node_id


def map_entry(index: int, bits: int, subindex: int = 0) -> int:
    """A PDO mapping entry: index (16 bit), subindex (8 bit), length in bits (8 bit)."""
    return (index << 16) | (subindex << 8) | bits


def entries_text(entries: list[int]) -> str:
    """PDO mapping ``entries`` as a person reads them: ``[0x6064:00/32, …]`` (index:subindex/bits)."""
    return "[" + ", ".join(f"0x{e >> 16:04X}:{(e >> 8) & 0xFF:02X}/{e & 0xFF}" for e in entries) + "]"


def _var(name: str, index: int, data_type: int, access: str, default: int | None = None,
         subindex: int = 0, mappable: bool = False) -> ODVariable:
    var = ODVariable(name, index, subindex)
    var.data_type, var.access_type, var.default, var.pdo_mappable = data_type, access, default, mappable
    return var


def _tpdo_objects(n: int, node_id: int, receive: bool = False) -> tuple[ODRecord, ODRecord]:
    """Communication and mapping records of TPDO ``n`` (``receive``: of RPDO ``n``, COB-ID 0x200 + … ; empty map)."""
    kind, comm_index, map_index = ("RPDO", RPDO_COMM, RPDO_MAP) if receive else ("TPDO", TPDO_COMM, TPDO_MAP)
    comm = ODRecord(f"{kind}{n} communication parameter", comm_index + n - 1)
    enabled = n == 1
    cob_id = (tpdo_cob_id(n, node_id) + 0x80 * receive) | (0 if enabled else PDO_INVALID)
    for sub, name, dtype, access, default in (
        (0, "Highest sub-index", UNSIGNED8, "const", 5),
        (1, "COB-ID", UNSIGNED32, "rw", cob_id),
        (2, "Transmission type", UNSIGNED8, "rw", 255),
        (3, "Inhibit time", UNSIGNED16, "rw", 0),
        (5, "Event timer", UNSIGNED16, "rw", 0),
    ):
        comm.add_member(_var(name, comm.index, dtype, access, default, sub))
    mapping = ODRecord(f"{kind}{n} mapping parameter", map_index + n - 1)
    mapping.add_member(_var("Number of mapped objects", mapping.index, UNSIGNED8, "rw", int(enabled and not receive)))
    for sub in range(1, 9):
        default = DEFAULT_TPDO1_MAP if (enabled and sub == 1 and not receive) else 0
        mapping.add_member(_var(f"Mapped object {sub}", mapping.index, UNSIGNED32, "rw", default, sub))
    return comm, mapping


def drive_object_dictionary(node_id: int) -> ObjectDictionary:
    """The CiA 301/402 objects of a profile-position servo drive used by ``acq`` (defaults: power-on)."""
    od = ObjectDictionary()
    od.node_id = node_id
    for var in (
        _var("Device type", DEVICE_TYPE, UNSIGNED32, "ro", 0x00020192),  # CiA 402 servo drive
        _var("Producer heartbeat time", HEARTBEAT_TIME, UNSIGNED16, "rw", 0),
        _var("Synchronous counter overflow value", SYNC_OVERFLOW, UNSIGNED8, "rw", 0),
        _var("High resolution time stamp", HIGH_RES_TIMESTAMP, UNSIGNED32, "rw", 0, mappable=True),  # µs
        _var("Controlword", CONTROLWORD, UNSIGNED16, "rw", 0, mappable=True),
        _var("Statusword", STATUSWORD, UNSIGNED16, "ro", 0, mappable=True),
        _var("Modes of operation", MODE, INTEGER8, "rw", 0, mappable=True),
        _var("Modes of operation display", MODE_DISPLAY, INTEGER8, "ro", 0, mappable=True),
        _var("Position actual value", POSITION_ACTUAL, INTEGER32, "ro", 0, mappable=True),
        _var("Velocity demand value", VELOCITY_DEMAND, INTEGER32, "ro", 0, mappable=True),  # velocity units
        _var("Velocity actual value", VELOCITY_ACTUAL, INTEGER32, "ro", 0, mappable=True),
        _var("Target position", TARGET_POSITION, INTEGER32, "rw", 0, mappable=True),
        _var("Home offset", HOME_OFFSET, INTEGER32, "rw", 0),
        _var("Target velocity", TARGET_VELOCITY, INTEGER32, "rw", 0, mappable=True),  # velocity units
        _var("Profile velocity", PROFILE_VELOCITY, UNSIGNED32, "rw", 0),
        _var("Profile acceleration", PROFILE_ACCELERATION, UNSIGNED32, "rw", 0),
        _var("Profile deceleration", PROFILE_DECELERATION, UNSIGNED32, "rw", 0),
        _var("Quick stop deceleration", QUICK_STOP_DECELERATION, UNSIGNED32, "rw", 0),
        # the joint's limits (acq writes them from [limits]); power-on: no limit but the motor's 300 % peak torque
        _var("Max profile velocity", MAX_PROFILE_VELOCITY, UNSIGNED32, "rw", 0xFFFFFFFF),
        _var("Max torque", MAX_TORQUE, UNSIGNED16, "rw", 3000),
        _var("Motor rated torque", MOTOR_RATED_TORQUE, UNSIGNED32, "rw", SIM_RATED_TORQUE_MNM),
        _var("Supported drive modes", SUPPORTED_MODES, UNSIGNED32, "ro",
             1 << (MODE_PROFILE_POSITION - 1) | 1 << (MODE_CYCLIC_SYNC_VELOCITY - 1)),
    ):
        od.add_object(var)
    od.add_object(_position_limits())
    for n in range(1, N_TPDO + 1):
        for record in _tpdo_objects(n, node_id):
            od.add_object(record)
    for record in _tpdo_objects(1, node_id, receive=True):  # RPDO1: a master's cyclic set-points
        od.add_object(record)
    od.add_object(_identity())
    return od


#: 0x6076 of the simulated drive, mN·m: the paper's motor as drivers.config.SIM_LIMITS takes it (2.3 kW at 3000 rpm)
SIM_RATED_TORQUE_MNM = 7300


def _position_limits() -> ODRecord:
    """0x607D software position limit: sub 1 min, sub 2 max (position units); power-on: the whole int32 range."""
    record = ODRecord("Software position limit", SOFTWARE_POSITION_LIMIT)
    record.add_member(_var("Highest sub-index", SOFTWARE_POSITION_LIMIT, UNSIGNED8, "const", 2))
    record.add_member(_var("Min position limit", SOFTWARE_POSITION_LIMIT, INTEGER32, "rw", -2**31, 1))
    record.add_member(_var("Max position limit", SOFTWARE_POSITION_LIMIT, INTEGER32, "rw", 2**31 - 1, 2))
    return record


#: 0x1018 identity of the simulated drive (CiA 301 mandatory object; vendor ID 0: none registered)
SIM_IDENTITY = {"Vendor-ID": 0x00000000, "Product code": 0x00000402, "Revision number": 0x00010000,
                "Serial number": 0x00000001}


def _identity() -> ODRecord:
    record = ODRecord("Identity object", 0x1018)
    record.add_member(_var("Highest sub-index", 0x1018, UNSIGNED8, "const", len(SIM_IDENTITY)))
    for sub, (name, value) in enumerate(SIM_IDENTITY.items(), start=1):
        record.add_member(_var(name, 0x1018, UNSIGNED32, "ro", value, sub))
    return record
