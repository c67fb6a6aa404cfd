"""The rules a trend is judged by (:class:`AlarmRules`: baseline sessions, threshold, EWMA λ) and where each comes from.

Each rule is the one asked for, else the one ``acq monitor`` judged its windows by — it files them with every window
as tags (:data:`RULE_TAGS`) — else acq's defaults: ``acq trend``, ``acq fleet`` and ``acq view --trend`` of a
monitor's windows then raise the alarms the monitor raised (with their own defaults, a baseline of the first window
where the monitor took the mean of five, they alarmed five windows apart).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

from acq.monitoring.catalogue import Entry


@dataclass(frozen=True)
class AlarmRules:
    """How a trend is judged: the baseline is the mean K of the first ``baseline_sessions`` good sessions; an alarm is
    K more than ``threshold_pct`` % below it, or the EWMA of weight ``ewma_lambda`` below its control limit.
    ``source`` says where the rules came from (for the table's caption)."""

    baseline_sessions: int = 1
    threshold_pct: float = 10.0
    ewma_lambda: float = 0.2
    source: str = "acq's defaults"

    def as_tags(self) -> dict[str, float]:
        """The rules as the session tags :func:`rules_for` reads back."""
        return {tag: getattr(self, name) for name, tag in RULE_TAGS.items()}


#: The session tags that carry the alarm rules a session was judged by (set by acq monitor on every window).
RULE_TAGS = {"baseline_sessions": "alarm_baseline_sessions", "threshold_pct": "alarm_threshold_pct",
             "ewma_lambda": "alarm_ewma_lambda"}


def _tagged_rules(entry: Entry) -> AlarmRules | None:
    """The rules ``entry``'s session was filed with, or None (no rule tags, or values that are none)."""
    try:
        values = {name: entry.tags[tag] for name, tag in RULE_TAGS.items()}
        rules = AlarmRules(int(values["baseline_sessions"]), float(values["threshold_pct"]),
                           float(values["ewma_lambda"]), source="as acq monitor judged its windows")
    except (KeyError, TypeError, ValueError):
        return None
    valid = rules.baseline_sessions >= 1 and 0 < rules.threshold_pct <= 100 and 0 < rules.ewma_lambda <= 1
    return rules if valid else None


def filed_rules(entries: Sequence[Entry]) -> AlarmRules | None:
    """The rules the newest of ``entries`` (oldest first) was filed with (:data:`RULE_TAGS`), or None."""
    return next((r for r in map(_tagged_rules, reversed(entries)) if r is not None), None)


def rules_for(entries: Sequence[Entry], *, baseline_sessions: int | None = None, threshold_pct: float | None = None,
              ewma_lambda: float | None = None) -> AlarmRules:
    """The rules to judge ``entries`` (oldest first) by: each one given here, else the newest session's filed ones
    (:data:`RULE_TAGS`), else acq's defaults."""
    filed = filed_rules(entries)
    rules = filed or AlarmRules()
    given = {name: value for name, value in (("baseline_sessions", baseline_sessions), ("threshold_pct", threshold_pct),
                                             ("ewma_lambda", ewma_lambda)) if value is not None}
    if not given:
        return rules
    options = ", ".join(f"--{name.replace('_', '-')}" for name in given)  # the options of acq trend, fleet, view
    if len(given) == len(RULE_TAGS):
        source = "from the command line"
    else:
        rest = "acq's defaults" if filed is None else filed.source
        source = f"{options} from the command line, the rest {rest}"
    return replace(rules, **given, source=source)
