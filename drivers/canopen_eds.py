"""The TPDO a machine's master set up, as ``acq`` listens to it: from the bench config or the drive's EDS/DCF.

Passive capture (``[drive] motion = "external"``, ``configure = false``) never asks the drive anything, so the
COB-ID and the mapping of the TPDO to record come from outside: ``tpdo_cob_id`` with ``tpdo_mapping``, or TPDO
``tpdo`` of the drive's EDS/DCF file ``eds``. canopen reads the file (:func:`canopen.import_od`, ``$NODEID``
resolved with ``node_id``) and its own PDO map reads the communication and mapping records from it
(:meth:`canopen.pdo.PdoMap.read` with ``from_od=True``: a DCF's ``ParameterValue`` where present, else the EDS
``DefaultValue``) — on a network object that is never connected, so nothing reaches a bus.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from drivers.config_drive import DriveCanopen, tpdo_mapping_problem
from acqcore.errors import ConfigError


@dataclass(frozen=True)
class PassiveTpdo:
    """The TPDO to record: its COB-ID and CiA 301 mapping entries (index << 16 | subindex << 8 | bits)."""

    cob_id: int
    entries: tuple[int, ...]
    source: str  # where it came from, for messages and the session's events


def passive_tpdo(s: DriveCanopen) -> PassiveTpdo:
    """The TPDO ``[drive]`` names (config keys or EDS/DCF); :class:`ConfigError` naming the file and key if the
    file cannot be read or its TPDO cannot be recorded."""
    if s.eds is None:
        assert s.tpdo_cob_id is not None and s.tpdo_mapping is not None  # DriveCanopen's validator
        return PassiveTpdo(s.tpdo_cob_id, tuple(s.tpdo_mapping), "[drive] tpdo_cob_id, tpdo_mapping")
    return tpdo_from_eds(Path(s.eds), s.tpdo, s.node_id)


def tpdo_from_eds(path: Path, tpdo: int, node_id: int) -> PassiveTpdo:
    """TPDO ``tpdo`` (1…4) of node ``node_id`` as the EDS/DCF file ``path`` configures it."""
    import canopen

    where = f"{path}: [drive] eds, TPDO{tpdo}"
    try:
        dictionary = canopen.import_od(str(path), node_id)
    except FileNotFoundError:
        raise ConfigError(f"{path}: [drive] eds: no such file") from None
    except Exception as e:  # noqa: BLE001 - canopen raises KeyError, ValueError, configparser errors …
        raise ConfigError(f"{path}: [drive] eds: not a readable EDS/DCF file ({type(e).__name__}: {e})") from None
    node = canopen.RemoteNode(node_id, dictionary)
    canopen.Network().add_node(node)  # never connected: the PDO map needs a network to subscribe on, no bus
    pdo = node.tpdo[tpdo]
    try:
        pdo.read(from_od=True)
    except (KeyError, TypeError) as e:
        raise ConfigError(f"{where}: the file has no complete communication/mapping record 0x{0x1800 + tpdo - 1:04X}/"
                          f"0x{0x1A00 + tpdo - 1:04X} ({e})") from None
    if not pdo.enabled:
        raise ConfigError(f"{where}: disabled in the file (COB-ID 0x{pdo.cob_id:X} has the invalid bit 31 set)")
    entries = tuple((v.index << 16) | (v.subindex << 8) | v.length for v in pdo.map)
    problem = tpdo_mapping_problem(list(entries))
    if problem:
        raise ConfigError(f"{where}: mapping [{', '.join(f'0x{e:08X}' for e in entries)}]: {problem}")
    if not 1 <= (pdo.trans_type or 0) <= 240:
        raise ConfigError(f"{where}: transmission type {pdo.trans_type} is not synchronous (1…240): acq pairs each "
                          "TPDO with the SYNC before it")
    return PassiveTpdo(int(pdo.cob_id) & 0x7FF, entries, f"{path.name} TPDO{tpdo}")
