"""How a result's numbers read: parameter labels, values, intervals and options as text.

Shared by the terminal's tables (:mod:`acq.ui.display`) and the report picture (:mod:`acq.ui.plots`); it imports
nothing of ``acq``, so both can use it without importing each other.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

from analysis import PARAM_LABELS, PARAM_NAMES

#: (key in the result document, symbol, SI unit) of each two-mass parameter, in table order.
PARAMS: tuple[tuple[str, str, str], ...] = tuple((key, *PARAM_LABELS[key]) for key in PARAM_NAMES)


def time_unit(span_s: float) -> tuple[str, float]:
    """The unit a time of ``span_s`` seconds reads right in — h from 1 h, min from 2 min, else s — and its seconds."""
    return ("h", 3600.0) if span_s >= 3600.0 else ("min", 60.0) if span_s >= 120.0 else ("s", 1.0)


def clock_text(t_s: float, span_s: float) -> tuple[str, str]:
    """Machine time ``t_s`` as a clock reads it within a run of ``span_s`` seconds, and the clock's unit: "1:20"
    ("h:min") from 1 h, "2:30" ("min:s") from 2 min, else "12.5" ("s"). Decimal hours mislabel a 10 min grid
    (0.17 h read "0.2 h", the third trial); a clock reads every whole minute or second as it is. The unit is
    :func:`time_unit`'s, as in the status line."""
    unit, scale = time_unit(span_s)
    if unit == "s":
        return f"{t_s:.1f}", "s"
    ticks = round(t_s * 60.0 / scale)  # whole minutes of an h:min clock, whole seconds of a min:s one
    return f"{ticks // 60}:{ticks % 60:02d}", {"h": "h:min", "min": "min:s"}[unit]


def duration_text(t_s: float) -> str:
    """``t_s`` in the unit of :func:`time_unit`: "10 s", "2.5 min", "1.25 h"."""
    unit, scale = time_unit(t_s)
    decimals = {"s": 0, "min": 1, "h": 2}[unit]
    return f"{t_s / scale:.{decimals}f} {unit}"


def format_value(x: float | None, spec: str = ".4g", scale: float = 1.0) -> str:
    """``x · scale`` formatted with ``spec``; "—" for a value that is missing, NaN or infinite."""
    return "—" if x is None or not math.isfinite(x) else format(x * scale, spec)


def interval_text(doc: dict[str, Any], key: str, *, relative: bool = False) -> str:
    """The 95 % interval of parameter ``key`` of a result document: "lo – hi", or "± x %" with ``relative``;
    "fixed (nominal)" for a parameter the fit held at the bench's nominal value (a zero-width interval)."""
    value = doc.get(key)
    lo, hi = (doc.get("ci95", {}).get(key) or (None, None))
    if lo is not None and lo == hi:
        nominal = (doc.get("options", {}).get("nominal") or {}).get(key)
        return "fixed (nominal)" if nominal == value else "fixed"
    if not relative:
        return "—" if lo is None and hi is None else f"{format_value(lo)} – {format_value(hi)}"
    if value is None or lo is None or hi is None or value == 0:
        return "—"
    return f"± {50.0 * (hi - lo) / abs(value):.2g} %"


def options_text(doc: dict[str, Any]) -> str:
    """The analysis options a result came from, in one line (torque method, free parameters, fit, band)."""
    opts = doc.get("options", {})
    band = opts.get("band_hz")
    parts = ["paper's chain (--paper)"] if opts.get("pipeline") == "paper" else []
    torque = opts.get("torque_method", "?") or "default"  # None: no chain ran (the joint did not move)
    parts += [f"torque {torque}", f"params {opts.get('params', '?')}",
              f"fit {opts.get('fit', '?')}"]
    if band:
        parts.append(f"band {band[0]:g}–{band[1]:g} Hz")
    if opts.get("pipeline") != "paper" and opts.get("align") is False:
        parts.append("clocks not aligned")
    return " · ".join(parts)


def alarm_rules_line(sources: Sequence[tuple[str, str]]) -> str:
    """Where the alarm rules shown came from, in one line, from (joint, its trend's ``rules_source``) pairs:
    "alarm rules: as acq monitor judged its windows"; joints judged by rules from different places are named after
    their source ("alarm rules: acq's defaults (r1/joint1); as acq monitor judged its windows (r2/joint1)")."""
    joints: dict[str, list[str]] = {}
    for joint, source in sources:
        joints.setdefault(source, []).append(joint)
    if len(joints) == 1:
        return f"alarm rules: {next(iter(joints))}"
    return "alarm rules: " + "; ".join(f"{source} ({', '.join(names)})" for source, names in joints.items())
