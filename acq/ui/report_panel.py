"""The report's side panel: :class:`SessionFigure`, one session as the report draws it (its figure data and
identified values), and the panel's text of those values (HTML: values with 95 % intervals, f_a, f_r, clock,
verdict, why the phase is or is not shown, the options the result came from).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from html import escape
from typing import Any

from acq.ui.plot_style import COLORS
from acq.ui.values import (NOT_A_RESULT, PARAMS, fit_failed, format_value, interval_text, not_a_result_note,
                           not_determined, options_text, readable_number)
from analysis import FigureData, Thresholds


@dataclass(frozen=True)
class SessionFigure:
    """One session to draw.

    Attributes
    ----------
    name : str
        Label in the legend and the side panel.
    figures : FigureData
        The analysis's figure data (SI units).
    values : dict
        The identification as in ``<session>.result.json`` (empty: no values shown).
    """

    name: str
    figures: FigureData
    values: dict[str, Any] = field(default_factory=dict)


def values_html(sessions: Sequence[SessionFigure]) -> str:
    """The side panel: identified values with 95 % intervals, f_a, f_r, clock and verdict, one block per session."""
    parts = ["<h3>Identified two-mass model (motor side)</h3>"]  # K, J through the gear as the motor sees them
    for i, s in enumerate(sessions):
        color = COLORS[i % len(COLORS)]
        parts.append(f"<p><b style='color:{color}'>{escape(s.name)}</b></p>")
        v = s.values
        if not v:
            parts.append("<p>no identified values</p>")
            continue
        failed = fit_failed(v)  # the fit's numbers are not a result: "—", "not a result" (result.json keeps them)
        rows = []
        for key, name, unit in PARAMS:
            rows.append((name, None if failed else format_value(v.get(key)),
                         NOT_A_RESULT if failed else interval_text(v, key, relative=True), unit))
        clock = v.get("clock", {})
        rows += [(name, None if failed else format_value(v.get(key)), NOT_A_RESULT if failed else "", "Hz")
                 for name, key in (("f_a", "antiresonance_hz"), ("f_r", "resonance_hz"))]
        rows += [("clock offset", format_value(clock.get("offset_s"), scale=1e3), "", "ms"),
                 ("clock drift", format_value(clock.get("drift_ppm")), "", "ppm"),
                 ("clock residual", format_value(clock.get("residual_s"), scale=1e6), "", "µs")]
        quality = v.get("quality", {})
        table = "".join(f"<tr><td nowrap>{escape(n)}</td><td align='right'>{'—' if val is None else f'<b>{val}</b>'}"
                        f"</td><td align='right' nowrap>{ci}</td><td nowrap>{escape(u)}</td></tr>"
                        for n, val, ci, u in rows)
        parts.append("<table cellspacing='0' cellpadding='2'><tr><th></th><th>value</th><th>95 % CI</th><th></th></tr>"
                     f"{table}</table>")
        # a value the data do not determine: its interval, whose ends the relative "± 360 %" hid
        wide = [f"{name} {format_value(v.get(key))} {escape(unit)}: its 95 % interval "
                f"{' – '.join(readable_number(b) for b in v['ci95'][key])} does not determine it"
                for key, name, unit in PARAMS if not failed and not_determined(v, key)]
        if failed:
            parts.append(f"<p>{escape(not_a_result_note('the .result.json'))}</p>")
        elif wide:
            parts.append(f"<p>{'<br>'.join(wide)}</p>")
        parts.append(f"<p>verdict <b>{escape(str(quality.get('verdict', '—')))}</b>, mean γ² in band "
                     f"{format_value(quality.get('mean_coherence'), '.3g')}</p>")
        parts.append(f"<p>{escape(phase_text(s))}</p><p><i>{escape(options_text(v))}</i></p>")
        reasons = [r for r in quality.get("reasons", []) if not r.startswith("note: ")]
        if reasons:
            parts.append("<ul>" + "".join(f"<li>{escape(r)}</li>" for r in reasons) + "</ul>")
    return "".join(parts)


def phase_text(s: SessionFigure) -> str:
    """Why the phase is shown or not: the clock residual against the limit a complex fit accepts."""
    limit_us = 1e6 * Thresholds().clock_residual_complex_s
    residual = s.values.get("clock", {}).get("residual_s")
    if s.figures.phase_valid:
        return f"phase shown: clocks aligned to {1e6 * residual:.0f} µs (limit {limit_us:.0f} µs)"
    if residual is None:
        return "phase not shown: the clocks were not aligned"
    return f"phase not shown: clock residual {1e6 * residual:.0f} µs exceeds {limit_us:.0f} µs"
