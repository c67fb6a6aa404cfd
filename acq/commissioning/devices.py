"""``acq devices``: what this machine can record from, and why a section is empty when it is.

Four sections: NI-DAQmx devices with their AI channels (needs the NI-DAQmx driver), CAN interfaces
python-can detects (software buses such as ``virtual`` are not hardware and are left out; two probes are not run,
:data:`NOT_PROBED`), serial ports pyserial sees, and the simulated bench, which is always there. Each probe is a small function that
returns a :class:`Section`; a library or driver that is missing empties its section with the reason.
"""

from __future__ import annotations

import logging
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Any

from acq.config import DEFAULT_BENCH
from acqcore.errors import DeviceError
from drivers.nidaq import DRIVER_MISSING, INSTALL_DRIVER, first_line, import_nidaqmx

#: python-can interfaces that are software buses, not something a drive can be wired to.
SOFTWARE_CAN = frozenset({"virtual", "udp_multicast"})
#: python-can interfaces whose detection is not run: ``serial`` "detects" every serial port pyserial sees, whatever
#: is wired to it (it listed /dev/ttyS0 as a CAN interface; the serial section lists the ports), and ``socketcand``
#: listens 3.1 s for a server's UDP beacon (sent every 3 s; a shorter wait would miss servers at random) — 4 s of
#: the command's 4.5 s on a machine without one.
NOT_PROBED = frozenset({"serial", "socketcand"})
CAN_NOT_PROBED = ("not looked for: socketcand servers on the network (finding one waits 3 s for its beacon) and "
                  "serial-line CAN adapters (their ports are under Serial ports)")


@dataclass(frozen=True)
class Section:
    """One kind of device: rows of (name, kind, detail), why there are none if there are none, and what to install
    when a library or driver is what is missing (``install``, "" otherwise)."""

    title: str
    rows: list[tuple[str, str, str]] = field(default_factory=list)
    empty_because: str = ""
    install: str = ""
    note: str = ""  # what the section did not look for

    def to_json_dict(self) -> dict[str, Any]:
        """``{"title", "devices": [{"device", "kind", "detail"}], "empty_because"}``, and ``"note"`` if there is one."""
        devices = [dict(zip(("device", "kind", "detail"), row)) for row in self.rows]
        return {"title": self.title, "devices": devices, "empty_because": self.empty_because,
                **({"note": self.note} if self.note else {})}


def ni_section() -> Section:
    """NI-DAQmx devices and their AI physical channels (nidaqmx imported only here)."""
    title = "NI-DAQmx devices"
    try:
        nidaqmx = import_nidaqmx()
    except DeviceError as e:  # the Python package is missing
        return Section(title, empty_because=str(e), install=f"pip install nidaqmx, then {INSTALL_DRIVER}")
    try:
        system = nidaqmx.system.System.local()
        v = system.driver_version
        rows = [(d.name, d.product_type, ", ".join(ch.name for ch in d.ai_physical_chans) or "no AI channels")
                for d in system.devices]
    except nidaqmx.errors.DaqNotFoundError:
        return Section(title, empty_because=DRIVER_MISSING, install=INSTALL_DRIVER)
    except nidaqmx.errors.DaqError as e:
        return Section(title, empty_because=f"NI-DAQmx: {first_line(e)} (DAQmx error {e.error_code})")
    version = f"{v.major_version}.{v.minor_version}.{v.update_version}"
    return Section(title, rows, "" if rows else f"NI-DAQmx {version} is installed but sees no device "
                                                 "(check the cable, power, or NI MAX)")


@contextmanager
def _quiet(logger_name: str) -> Iterator[None]:
    """Silence a library's warnings about optional vendor back-ends while probing."""
    logger = logging.getLogger(logger_name)
    level = logger.level
    logger.setLevel(logging.CRITICAL)
    try:
        yield
    finally:
        logger.setLevel(level)


def can_section() -> Section:
    """CAN interfaces python-can detects (``can.detect_available_configs``), software buses left out, the
    :data:`NOT_PROBED` interfaces not asked."""
    import can

    with _quiet("can"):
        configs: list[dict[str, Any]] = can.detect_available_configs(
            interfaces=sorted(can.interfaces.VALID_INTERFACES - NOT_PROBED))
    rows = [(str(c.get("channel", "")), str(c["interface"]),
             ", ".join(f"{k}={v}" for k, v in c.items() if k not in ("interface", "channel")))
            for c in configs if c.get("interface") not in SOFTWARE_CAN]
    software = sorted({str(c["interface"]) for c in configs if c.get("interface") in SOFTWARE_CAN})
    because = "python-can detects no CAN interface (no adapter plugged in, or its driver is missing)"
    if software:
        because += f"; only software buses: {', '.join(software)}"
    return Section("CAN interfaces (python-can)", rows, "" if rows else because, note=CAN_NOT_PROBED)


def serial_section() -> Section:
    """Serial ports pyserial sees (``serial.tools.list_ports.comports``); a port it knows nothing more of (its "n/a",
    e.g. a mainboard's /dev/ttyS0) is a "serial port"."""
    from serial.tools import list_ports

    known = {"", "n/a"}
    rows = [(p.device, "serial port" if p.description in known else p.description, "" if p.hwid in known else p.hwid)
            for p in list_ports.comports()]
    return Section("Serial ports (pyserial)", rows, "" if rows else "pyserial sees no serial port")


def sim_section() -> Section:
    """The simulated bench: always available."""
    return Section("Simulated bench", [("sim", "simulated DAQ + drive", str(DEFAULT_BENCH))])


def discover() -> list[Section]:
    """Every section, in display order."""
    return [ni_section(), can_section(), serial_section(), sim_section()]
