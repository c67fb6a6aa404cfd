"""Name → adapter registry. Vendor libraries are imported only when their adapter is chosen.

As python-can's ``can.interfaces`` does: the bench config names a driver, this module imports the
module that implements it and builds it. A bench that uses any simulated part builds one
:class:`drivers.sim.bench.SimBench` and hands it to every simulated part, so current and encoder
come from the same physics.
"""

from __future__ import annotations

import importlib
from typing import Any

from drivers.base import CurrentSource, Drive
from drivers.config import Bench
from drivers.errors import ConfigError

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


def _needs_sim(bench: Bench) -> bool:
    drive = bench.drive
    return (
        bench.daq.driver == "sim"
        or drive.driver == "sim"
        or bool(getattr(drive, "simulated_node", False))
        or bool(getattr(drive, "simulated_device", False))
    )


def _factory(table: dict[str, tuple[str, str]], name: str) -> Any:
    module_name, attr = table[name]
    return getattr(importlib.import_module(module_name), attr)


def open_bench(bench: Bench, *, fast: bool = False, sim_bench: Any = None) -> tuple[CurrentSource, Drive]:
    """Build the current source and the drive a bench config names (not started yet).

    ``fast`` lets simulated parts run as fast as the machine can instead of in real time. ``sim_bench``:
    the :class:`drivers.sim.bench.SimBench` the simulated parts share (built here if None and needed;
    pass one to read its truth afterwards).
    """
    if sim_bench is None and _needs_sim(bench):
        if bench.sim is None:
            raise ConfigError("bench config: a simulated part needs a [sim] section (see configs/benches/sim.toml)")
        from drivers.sim.bench import SimBench

        sim_bench = SimBench(bench, realtime=not fast)
    current = _factory(CURRENT_SOURCES, bench.daq.driver)(bench, sim_bench, fast)
    drive = _factory(DRIVES, bench.drive.driver)(bench, sim_bench, fast)
    return current, drive
