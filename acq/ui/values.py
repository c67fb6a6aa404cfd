"""How a result's numbers read: parameter labels, values, intervals and options as text.

Shared by the terminal's tables (:mod:`acq.ui.display`) and the report picture (:mod:`acq.ui.report_panel`); it imports
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


#: A 95 % interval whose half-width is this share of its value or more leaves the value not determined: it reaches
#: from about zero (or below) to twice the value or beyond, so the data do not tell even its magnitude (the trial's
#: C 0.237, interval 0.0325…1.728: "± 3.6e+02 %").
NOT_DETERMINED_SHARE = 1.0


#: The fit's numbers a ``failed`` verdict leaves: its parameters and the f_a, f_r they give (the result document keeps
#: them, with the verdict; the table and the report panel show them as not a result).
FIT_KEYS: tuple[str, ...] = (*(key for key, _, _ in PARAMS), "antiresonance_hz", "resonance_hz")
NOT_A_RESULT = "not a result"


def fit_failed(doc: dict[str, Any]) -> bool:
    """True when the verdict of result document ``doc`` is ``failed``: its fit's numbers are not a result."""
    return (doc.get("quality") or {}).get("verdict") == "failed"


def not_a_result_note(kept_in: str) -> str:
    """The line under a failed verdict's values: "verdict failed: the fit's K, J_m, J_l, C, f_a and f_r are not a
    result (<kept_in> keeps them)"."""
    names = ", ".join(name for _, name, _ in PARAMS)
    return f"verdict failed: the fit's {names}, f_a and f_r are {NOT_A_RESULT} ({kept_in} keeps them)"


def readable_number(x: float) -> str:
    """``x`` to 2 significant digits, in plain decimals from 0.0001 to below 10⁶ ("0.00049", "120", "360"), else
    in powers of ten ("2.2e+06"): the two ends of a wide interval, read at a glance."""
    if not math.isfinite(x):
        return "—"
    if x == 0.0:
        return "0"
    rounded = float(f"{x:.2g}")
    exponent = math.floor(math.log10(abs(rounded)))
    if not -4 <= exponent < 6:
        return f"{x:.2g}"
    return f"{rounded:.{max(0, 1 - exponent)}f}"


def not_determined(doc: dict[str, Any], key: str) -> bool:
    """True when the 95 % interval of parameter ``key`` is :data:`NOT_DETERMINED_SHARE` of its value or wider."""
    value = doc.get(key)
    lo, hi = (doc.get("ci95", {}).get(key) or (None, None))
    return (value is not None and lo is not None and hi is not None and value != 0
            and 0.5 * (hi - lo) >= NOT_DETERMINED_SHARE * abs(value))


def interval_text(doc: dict[str, Any], key: str, *, relative: bool = False) -> str:
    """The 95 % interval of parameter ``key`` of a result document: "lo – hi", or "± x %" with ``relative``;
    "fixed (nominal)" for a parameter the fit held at the bench's nominal value (a zero-width interval). One that
    does not determine the value (:func:`not_determined`) reads "0.033 – 1.7: not determined" (with ``relative``:
    "not determined"), its ends in :func:`readable_number`."""
    value = doc.get(key)
    lo, hi = (doc.get("ci95", {}).get(key) or (None, None))
    if lo is not None and lo == hi:
        nominal = (doc.get("options", {}).get("nominal") or {}).get(key)
        return "fixed (nominal)" if nominal == value else "fixed"
    if not_determined(doc, key):
        return "not determined" if relative else f"{readable_number(lo)} – {readable_number(hi)}: not determined"
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
