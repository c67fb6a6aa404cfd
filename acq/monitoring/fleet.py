"""``acq fleet``: every joint of every robot in one catalogue, worst first.

Each joint — the sessions of one ``joint`` on one robot (the session tag ``robot``; sessions without
it are grouped under ``—``) in one catalogue — is judged by :func:`acq.monitoring.trend.compute_trend`, the same
baseline and alarm rules as ``acq trend``. Its state is, worst first:

* **alarm** — the latest judged session is in alarm (exit code 3, as ``acq trend``);
* **stale** — no session started in the last ``--stale-days`` days (a monitor or bench has stopped);
* **no baseline** — not enough good sessions for a baseline yet (shown as "learning baseline", as acq monitor says);
* **baseline** — a baseline, but no session judged against it yet;
* **ok**.

Within a state the joints with the largest drop of K come first. Several catalogues (``acq fleet plant/r1
plant/r2``) are read as they are and never mixed: a joint of the same robot and name in two of them is two rows,
told apart by their source. Within one catalogue the windows of several monitors of the same robot and joint name
(monitors sharing a catalogue without a ``robot`` tag) are judged apart too, each monitor a row
(:func:`acq.monitoring.monitor_scope.split_by_monitor`). "Excited" sessions are those whose
analysis gave a K with verdict ``ok``; the others (failed, ``poor``: too little excitation, low
coherence …) count as analysed only. The command, table and PNG are :mod:`acq.ui.fleet_display`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from datetime import UTC, datetime, timedelta
from pathlib import Path
from typing import Any, Literal

from acq.monitoring.catalogue import Catalogue, Entry
from acq.monitoring.monitor_scope import monitor_and_tags, split_by_monitor
from acq.monitoring.trend import Trend, TrendPoint, compute_trend
from acq.monitoring.trend_catalogue import catalogue_sources
from acq.recording.tags import tag_group, tags_match
from acqcore.errors import ConfigError

FleetState = Literal["alarm", "stale", "no baseline", "baseline", "ok"]
STATE_ORDER: dict[FleetState, int] = {"alarm": 0, "stale": 1, "no baseline": 2, "baseline": 3, "ok": 4}
UNTAGGED_ROBOT = "—"
_JUDGED_OR_GOOD = ("baseline", "ok", "alarm", "before baseline")


@dataclass(frozen=True)
class JointStatus:
    """One joint of the fleet.

    Attributes
    ----------
    robot, joint : str
        The ``robot`` tag of its sessions (:data:`UNTAGGED_ROBOT` when absent) and the joint's name.
    state : {"alarm", "stale", "no baseline", "baseline", "ok"}
        See the module's docstring.
    source : str
        Where the row comes from when that tells it apart: the catalogue (several given), the monitor (several
        monitors of one robot and joint name in a catalogue); empty otherwise.
    monitor : str or None
        The identity of the monitor whose windows these are (:data:`acq.monitoring.monitor_scope.MONITOR_TAG`).
    trend : Trend
        The joint's trend (baseline, points, rules).
    latest : TrendPoint or None
        The latest judged session (compared with the baseline), or the latest good one without a baseline.
    last_session_utc : datetime or None
        Start of the newest session of any verdict.
    analysed_last_day, excited_last_day : int
        Sessions started in the 24 h before ``now``: all of them, and those with a K of verdict ok.
    """

    robot: str
    joint: str
    state: FleetState
    trend: Trend
    latest: TrendPoint | None
    last_session_utc: datetime | None
    analysed_last_day: int
    excited_last_day: int
    source: str = ""
    monitor: str | None = None

    @property
    def change_pct(self) -> float | None:
        """K of the latest judged session relative to the baseline, %."""
        return None if self.latest is None else self.latest.change_pct

    def history(self) -> list[tuple[datetime, float]]:
        """(session start, ΔK %) of every session compared with the baseline, oldest first."""
        return [(start, p.change_pct) for p in self.trend.points
                if p.change_pct is not None and (start := session_start(p.entry)) is not None]


def session_start(entry: Entry) -> datetime | None:
    """When the session started (UTC), None when unknown or unreadable."""
    try:
        start = datetime.fromisoformat(entry.created_utc or "")
    except ValueError:
        return None
    return start if start.tzinfo else start.replace(tzinfo=UTC)


def fleet_status(entries: Sequence[Entry], *, now: datetime, stale_days: float = 7.0, source: str = "",
                 **trend_options: Any) -> list[JointStatus]:
    """Judge every (robot, joint) of ``entries`` (oldest session first); worst first.

    Parameters
    ----------
    entries : sequence of Entry
        The catalogue's analyses (sessions without a joint are left out).
    now : datetime
        The present, UTC (the last day and staleness are counted back from it).
    stale_days : float
        A joint with no session started within this many days is stale.
    source : str
        The catalogue's label, when several are judged together ('' for one).
    **trend_options
        ``baseline_sessions``, ``threshold_pct``, ``ewma_lambda`` of :func:`acq.monitoring.trend.compute_trend`.
    """
    groups: dict[tuple[str | float, str], list[Entry]] = {}
    for e in entries:  # one robot however its tag was stored (7.0 by earlier acq, "007" today: tag_group)
        if e.joint is not None:
            groups.setdefault((tag_group(e.tags.get("robot", UNTAGGED_ROBOT)), e.joint), []).append(e)
    statuses = []
    for (_, joint), group in groups.items():
        robot = str(group[-1].tags.get("robot", UNTAGGED_ROBOT))  # as its latest session spells it
        by_monitor = split_by_monitor(group)
        for monitor, history in by_monitor.items():
            apart = ([source] if source else []) + ([f"monitor {monitor or '—'}"] if len(by_monitor) > 1 else [])
            statuses.append(_joint_status(robot, joint, history, now, stale_days, trend_options, " · ".join(apart),
                                          monitor))
    return worst_first(statuses)


def worst_first(statuses: Sequence[JointStatus]) -> list[JointStatus]:
    """``statuses`` by state (alarm first), then by the drop of K (largest first)."""
    return sorted(statuses, key=lambda s: (STATE_ORDER[s.state], s.change_pct if s.change_pct is not None
                                           else math.inf, s.robot, s.joint, s.source))


def _joint_status(robot: str, joint: str, entries: list[Entry], now: datetime, stale_days: float,
                  trend_options: dict[str, Any], source: str, monitor: str | None) -> JointStatus:
    name = joint if robot == UNTAGGED_ROBOT else f"{robot}/{joint}"
    trend = compute_trend(f"{name} ({source})" if source else name, entries, **trend_options)
    starts = [(session_start(p.entry), p) for p in trend.points]
    known = [start for start, _ in starts if start is not None]
    last = max(known, default=None)
    day = [p for start, p in starts if start is not None and now - timedelta(days=1) <= start <= now]
    good = [p for p in trend.points if p.state in _JUDGED_OR_GOOD]
    latest = trend.judged[-1] if trend.judged else (good[-1] if good else None)
    state: FleetState
    if trend.alarm:
        state = "alarm"
    elif last is None or now - last > timedelta(days=stale_days):
        state = "stale"
    elif trend.baseline_K_Nm_per_rad is None:
        state = "no baseline"
    elif not trend.judged:  # its latest K is a baseline session's: nothing judged yet (its ΔK is against their mean)
        state = "baseline"
    else:
        state = "ok"
    return JointStatus(robot, joint, state, trend, latest, last, len(day),
                       sum(p.state in _JUDGED_OR_GOOD for p in day), source, monitor)


def fleet_json(statuses: Sequence[JointStatus]) -> list[dict[str, Any]]:
    """The ``--json`` list, worst joint first."""
    docs = []
    for s in statuses:
        entry = None if s.latest is None else s.latest.entry
        docs.append({"robot": s.robot, "joint": s.joint, "source": s.source, "monitor_id": s.monitor,
                     "state": s.state,
                     "reason": "" if s.latest is None or s.state != "alarm" else s.latest.reason,
                     "K_Nm_per_rad": None if entry is None else entry.K_Nm_per_rad,
                     "K_ci95": None if entry is None else list(entry.K_ci95), "change_pct": s.change_pct,
                     "baseline_K_Nm_per_rad": s.trend.baseline_K_Nm_per_rad,
                     "rules": s.trend.rules_source, "baseline_warning": s.trend.baseline_warning,
                     "latest_session_id": None if entry is None else entry.session_id,
                     "last_session_utc": None if s.last_session_utc is None else s.last_session_utc.isoformat(),
                     "analysed_last_day": s.analysed_last_day, "excited_last_day": s.excited_last_day})
    return docs


def load_fleet(folders: Sequence[Path], catalogues: Sequence[Path | str], tags: Sequence[str] = (), *,
               now: datetime, **options: Any) -> list[JointStatus]:
    """:func:`fleet_status` of the sessions tagged ``tags`` (``KEY=VALUE``) of each catalogue — every folder's
    ``FOLDER/catalogue.sqlite`` and every catalogue given (none: ``sessions/catalogue.sqlite``) — judged apart, worst
    first over all of them."""
    monitor, wanted = monitor_and_tags(tags)
    sources = catalogue_sources(folders, catalogues)
    statuses: list[JointStatus] = []
    names = []
    for label, location in sources:
        with Catalogue(location, read_only=True) as catalogue:
            entries = [e for e in catalogue.entries(monitor=monitor) if tags_match(e.tags, wanted)]
            names.append(str(catalogue.path))
        statuses += fleet_status(entries, now=now, source=label if len(sources) > 1 else "", **options)
    if not statuses:
        tagged = f" tagged {' '.join(tags)}" if tags else ""
        raise ConfigError(f"{', '.join(names)}: no sessions of any joint{tagged}")
    return worst_first(statuses)
