"""What makes a monitor's windows comparable, filed with every window so that a restart on another bench is refused.

A monitor's trend compares K of its windows with a baseline learned on its first ones: a restart in the same
``--out`` with another bench (docs/monitoring.md's CANopen example, then its serial one) or another ``--window``
added windows of another measurement to the same series, silently (the new-user trial). :func:`window_facts` are
the bench facts the K of a window depends on, filed as window tags (:data:`FACT_TAGS`, as
:data:`acq.monitoring.alarm_rules.RULE_TAGS` files the alarm rules); :func:`differences` names those a restart would
change.

Chosen, and why:

* **joint** — another joint is another trend;
* **[daq] / [drive] driver** — another transport is another measurement chain (its clock, its time stamps, its
  latency): a jump of K at the switch would be the chain's, not the joint's;
* **[daq] rate_hz, channels; [drive] period_s** — the FRF's resolution, its noise and which phases make the torque;
* **[motor] torque_constant, pole_pairs; [encoder] counts_per_rev; [gear] ratio** — they scale torque and angle:
  another value scales K itself;
* **--window** — the Welch averages, hence the interval and the segment selection of a window.

Not compared: the drive's bus address, port, baud or timeouts (the same chain reached another way); ``[nominal]``
(the fit's starting point, not its result); ``[limits]`` (a listening monitor never moves the joint); and ``[sim]``
— its truth and seed describe the simulated *machine*, not the measurement: a simulated wear series restarts the
monitor with a softer joint, which is what a monitor is for, so refusing it would refuse the one change it must see.

A folder filed before these tags existed has none: a missing tag is "unknown" and never a refusal.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from acq.monitoring.catalogue import Entry
from drivers.config import Bench

if TYPE_CHECKING:
    from acq.recording.recorder import Recorder

#: tag → how the option or bench field is named in the refusal.
FACT_TAGS = {
    "monitor_window_s": "--window",
    "monitor_daq_driver": "[daq] driver",
    "monitor_daq_rate_hz": "[daq] rate_hz",
    "monitor_daq_channels": "[daq] channels",
    "monitor_drive_driver": "[drive] driver",
    "monitor_drive_period_s": "[drive] period_s",
    "monitor_torque_constant_Nm_per_A": "[motor] torque_constant_Nm_per_A",
    "monitor_pole_pairs": "[motor] pole_pairs",
    "monitor_counts_per_rev": "[encoder] counts_per_rev",
    "monitor_gear_ratio": "[gear] ratio",
}


def window_facts(bench: Bench, window_s: float) -> dict[str, Any]:
    """The tags a monitor files with every window (:data:`FACT_TAGS`): the facts its K depends on."""
    return {"monitor_window_s": float(window_s), "monitor_daq_driver": bench.daq.driver,
            "monitor_daq_rate_hz": float(bench.daq.rate_hz), "monitor_daq_channels": ",".join(bench.daq.channels),
            "monitor_drive_driver": bench.drive.driver, "monitor_drive_period_s": float(bench.drive.period_s),
            "monitor_torque_constant_Nm_per_A": float(bench.motor.torque_constant_Nm_per_A),
            "monitor_pole_pairs": int(bench.motor.pole_pairs),
            "monitor_counts_per_rev": int(bench.encoder.counts_per_rev),
            "monitor_gear_ratio": float(bench.gear.ratio)}


def _same(filed: Any, mine: Any) -> bool:
    if isinstance(filed, int | float) and isinstance(mine, int | float):
        return math.isclose(float(filed), float(mine), rel_tol=1e-9)
    return str(filed) == str(mine)


def _text(value: Any) -> str:
    return f"{value:g}" if isinstance(value, float) else str(value)


def differences(windows: Sequence[Entry], bench: Bench, window_s: float) -> list[str]:
    """What differs between the newest of ``windows`` (a folder's windows of any joint, oldest first) and a monitor
    of ``bench`` and ``window_s``: one text per fact ("[drive] driver canopen, now serial"); facts the windows were
    not filed with are unknown and not compared."""
    if not windows:
        return []
    newest = windows[-1]
    found = []
    if newest.joint is not None and newest.joint != bench.joint:
        found.append(f"joint {newest.joint}, now {bench.joint}")
    for tag, value in window_facts(bench, window_s).items():
        if tag in newest.tags and not _same(newest.tags[tag], value):
            found.append(f"{FACT_TAGS[tag]} {_text(newest.tags[tag])}, now {_text(value)}")
    return found


def window_recorder(bench: Bench, out_dir: Path, window_s: float, elapsed_s: float, *, fast: bool,
                    tags: dict[str, Any]) -> Recorder:
    """The passive recorder of one window at machine time ``elapsed_s`` (s) into ``out_dir``, its devices open: the
    window's ``tags``, what the machine says of it (a robot's payload) and :func:`window_facts`. A simulated machine
    runs on machine time (program phase, wear, noise)."""
    from acq.recording.recorder import Recorder  # here: acq trend reads FACT_TAGS without the recorder and drivers
    from drivers.registry import open_bench

    facts = window_facts(bench, window_s)
    if bench.sim is not None:
        bench = bench.model_copy(update={"sim": bench.sim.model_copy(update={"elapsed_s": elapsed_s})})
    current, drive = open_bench(bench, fast=fast)
    machine = getattr(drive, "machine_tags", dict)()
    return Recorder(bench, None, current, drive, out_dir, window_s, tags={**tags, **machine, **facts})
