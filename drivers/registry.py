"""Name → adapter registry. Vendor libraries are imported only when their adapter is chosen.

As python-can's ``can.interfaces`` does: the bench config names a driver, this module imports the
module that implements it and builds it. A bench that uses any simulated part builds one
:class:`drivers.sim.bench.SimBench` and hands it to every simulated part, so current and encoder
come from the same physics. A real adapter with ``simulated_node`` / ``simulated_device`` is built by
the simulator's own factory (:data:`SIMULATED_PEERS`): the plain adapter pointed at a virtual channel or
pty with the simulated drive on the other end. ``drivers.sim`` is named here only as strings, imported
when chosen, so no module outside it imports it.
"""

from __future__ import annotations

import importlib
from typing import Any

from drivers.base import CurrentSource, Drive
from drivers.config import Bench
from acqcore.errors import ConfigError

#: driver name in ``[daq]`` → (module, factory). The factory takes (bench, sim_bench_or_None, fast).
CURRENT_SOURCES: dict[str, tuple[str, str]] = {
    "sim": ("drivers.sim.daq", "open_current_source"),
    "nidaqmx": ("drivers.nidaq", "open_current_source"),
}

#: driver name in ``[drive]`` → (module, factory). The factory takes (bench, sim_bench_or_None, fast).
DRIVES: dict[str, tuple[str, str]] = {
    "sim": ("drivers.sim.drive", "open_drive"),
    "canopen": ("drivers.canopen_drive", "open_drive"),
    "serial": ("drivers.serial_drive", "open_drive"),
}

#: drive driver → (module, factory) of the adapter with its simulated peer, used when ``[drive]`` has
#: ``simulated_node`` (CANopen) or ``simulated_device`` (serial) set. Same factory signature.
SIMULATED_PEERS: dict[str, tuple[str, str]] = {
    "canopen": ("drivers.sim.peers", "open_canopen_with_sim_node"),
    "serial": ("drivers.sim.peers", "open_serial_with_sim_device"),
}

#: (module, class) of the simulated bench all simulated parts share.
SIM_BENCH: tuple[str, str] = ("drivers.sim.bench", "SimBench")


def _has_simulated_peer(bench: Bench) -> bool:
    drive = bench.drive
    return bool(getattr(drive, "simulated_node", False)) or bool(getattr(drive, "simulated_device", False))


def _needs_sim(bench: Bench) -> bool:
    return bench.daq.driver == "sim" or bench.drive.driver == "sim" or _has_simulated_peer(bench)


def _load(entry: tuple[str, str]) -> Any:
    module_name, attr = entry
    return getattr(importlib.import_module(module_name), attr)


def _factory(table: dict[str, tuple[str, str]], name: str) -> Any:
    return _load(table[name])


def open_bench(bench: Bench, *, fast: bool = False, sim_bench: Any = None) -> tuple[CurrentSource, Drive]:
    """Build the current source and the drive a bench config names (not started yet).

    ``fast`` lets simulated parts run as fast as the machine can instead of in real time. ``sim_bench``:
    the :class:`drivers.sim.bench.SimBench` the simulated parts share (built here if None and needed;
    pass one to read its truth afterwards).
    """
    if sim_bench is None and _needs_sim(bench):
        if bench.sim is None:
            raise ConfigError("bench config: a simulated part needs a [sim] section (see configs/benches/sim.toml)")
        sim_bench = _load(SIM_BENCH)(bench, realtime=not fast)
    current = _factory(CURRENT_SOURCES, bench.daq.driver)(bench, sim_bench, fast)
    drives = SIMULATED_PEERS if _has_simulated_peer(bench) else DRIVES
    drive = _factory(drives, bench.drive.driver)(bench, sim_bench, fast)
    return current, drive
