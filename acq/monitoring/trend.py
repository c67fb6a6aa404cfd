"""``acq trend``: a joint's stiffness K over time from the catalogue, with a baseline and alarms.

Only sessions whose analysis has verdict ``ok`` are judged; the others are listed as skipped with
their reason. The baseline is the first good session, the mean of the first N good ones, or a pinned
session (sessions before a pinned baseline are shown, not judged). Two alarm rules:

* **threshold** — K below (1 − threshold) × baseline (default −10 %): the action limit;
* **EWMA** — the exponentially weighted moving average z_t = λ K_t + (1 − λ) z_{t−1}, z_0 = baseline,
  below the lower control limit baseline − L σ √(λ/(2−λ) · (1 − (1−λ)^{2t})) (Roberts' chart, L = 3):
  a small but persistent drop, relative to the session-to-session scatter σ of K. σ is the larger of
  the baseline's own 95 % interval (as 1.96 σ) and the standard deviation of the baseline sessions.

A baseline of several sessions that disagree far beyond their own intervals (the joint changed while it was
learned) is called unstable (:func:`baseline_warning`): its limits are too wide to trust.

The alarm state is the latest judged session's: exit code 3 while it is in alarm, so a cron job or a
PLC script can act; re-pin the baseline (``--baseline``) after a repair.

The rules (baseline sessions, threshold, λ) are each the one asked for, else the one ``acq monitor`` judged its
windows by, else acq's defaults (:mod:`acq.monitoring.alarm_rules`). :mod:`acq.monitoring.trend_catalogue` reads a
joint's sessions from the catalogue.
"""

from __future__ import annotations

import json
import math
import statistics
from collections import Counter
from collections.abc import Sequence
from dataclasses import asdict, dataclass, replace
from typing import Any, Literal

from scipy.stats import chi2

from acq.monitoring.alarm_rules import AlarmRules, rules_for
from acq.monitoring.catalogue import Entry
from acq.monitoring.monitor_scope import window_number
from acqcore.errors import ConfigError
from analysis import AnalysisRequest, Z95

EXIT_ALARM = 3
EWMA_L = 3.0
#: A baseline whose sessions scatter about their mean this unlikely by their own intervals is called unstable
#: (χ² test, :func:`baseline_warning`): a stable joint's baseline is called so once in a thousand.
BASELINE_SIGNIFICANCE = 0.001

State = Literal["baseline", "ok", "alarm", "skipped", "before baseline"]


#: Tag of a monitor window (set by :mod:`acq.monitoring.monitor`): machine time at its start, s; the x axis of a monitor's trend.
ELAPSED_TAG = "monitor_elapsed_s"


@dataclass(frozen=True)
class TrendPoint:
    """One session in the trend.

    Attributes
    ----------
    entry : Entry
        The session's analysis from the catalogue.
    state : {"baseline", "ok", "alarm", "skipped", "before baseline"}
        How the session counts.
    reason : str
        Why it was skipped, or which rules raised the alarm ("threshold", "EWMA", "threshold+EWMA").
    change_pct : float or None
        K relative to the baseline, %.
    ewma_change_pct : float or None
        The EWMA of K relative to the baseline, %.
    ewma_limit_pct : float or None
        The EWMA's lower control limit relative to the baseline, %.
    """

    entry: Entry
    state: State
    reason: str = ""
    change_pct: float | None = None
    ewma_change_pct: float | None = None
    ewma_limit_pct: float | None = None

    @property
    def threshold_alarm(self) -> bool:
        """The threshold rule fired here."""
        return self.state == "alarm" and "threshold" in self.reason


@dataclass(frozen=True)
class Trend:
    """A joint's trend: the points in time order, the baseline and the rules' settings (K in N·m/rad)."""

    joint: str
    points: list[TrendPoint]
    baseline_K_Nm_per_rad: float | None
    baseline_note: str
    sigma_K_Nm_per_rad: float | None
    threshold_pct: float
    ewma_lambda: float
    ewma_L: float = EWMA_L
    rules_source: str = AlarmRules.source
    baseline_warning: str | None = None  # the baseline's sessions disagree beyond their intervals (baseline_warning)

    @property
    def judged(self) -> list[TrendPoint]:
        """Points compared with the baseline (ok or alarm)."""
        return [p for p in self.points if p.state in ("ok", "alarm")]

    @property
    def alarm(self) -> bool:
        """True when the latest judged session is in alarm."""
        return bool(self.judged) and self.judged[-1].state == "alarm"


def alarm_onsets(trend: Trend) -> set[str]:
    """Session ids of the judged sessions that raised an alarm when the one judged before them had not: the first
    session of each alarm episode (skipped sessions neither start nor end one, as in the monitor's own count)."""
    onsets: set[str] = set()
    in_alarm = False
    for point in trend.judged:
        if point.state == "alarm" and not in_alarm:
            onsets.add(point.entry.session_id)
        in_alarm = point.state == "alarm"
    return onsets


def like_for_like(entries: Sequence[Entry]) -> tuple[list[Entry], dict[str, str]]:
    """One analysis per session, all of the same kind: the sessions' own results (the default request, or the
    monitor's — :meth:`analysis.AnalysisRequest.variant_label` empty), each session's latest; a comparison
    (``--paper``, ``--band``, …) only where no session has its own result, then the kind most sessions have (the
    latest on a tie).

    The kind is what the request asks (its label), not the code that answered it nor whether the segment selection
    was asked for or left to the recording: a monitor that runs on across an upgrade of acq keeps judging its new
    windows against the baseline of its old ones (compared by the full catalogue key, the new windows were "other
    options" and skipped until they outnumbered the old — an alarm lost meanwhile).

    Returns the entries (oldest session first) and, by session key, why a session has none of that kind (its
    latest analysis stands in, to be listed as skipped).
    """
    sessions: dict[str, list[Entry]] = {}
    for e in entries:
        sessions.setdefault(e.session_key, []).append(e)
    kinds = {id(e): _kind(e.request_key) for e in entries}
    own = [e for e in entries if kinds[id(e)] == ""]
    pool = own or list(entries)
    counts = Counter(kinds[id(e)] for e in pool)
    kind = max(counts, key=lambda k: (counts[k], max(e.analyzed_utc for e in pool if kinds[id(e)] == k)))
    chosen, missing = [], {}
    for key, analyses in sessions.items():
        same = [e for e in analyses if kinds[id(e)] == kind]
        chosen.append(same[-1] if same else analyses[-1])
        if not same:
            missing[key] = "analysed only with other options than the trend's — run acq analyze on it again"
    return chosen, missing


def _kind(request_key: str) -> str:
    """What a catalogue row's request (:meth:`analysis.AnalysisRequest.key`) asks, as its variant label ('' for a
    session's own result); a key that is no request (a catalogue of other software) is its own kind."""
    try:
        request = AnalysisRequest.from_json_dict(json.loads(request_key))
    except (ValueError, TypeError, AttributeError):
        return f"other:{request_key}"
    # a selection asked for (the monitor's windows before it became the default where acq does not command the
    # motion) is the default's kind; one refused (select_segments False) is a comparison
    return (replace(request, select_segments=None) if request.select_segments else request).variant_label()


def _skip_reason(e: Entry) -> str | None:
    if e.error is not None:
        return f"analysis failed: {e.error}"
    if e.verdict != "ok" or e.K_Nm_per_rad is None:
        why = [r for r in e.reasons if not r.startswith("note: ")]
        return f"verdict {e.verdict}" + (f": {why[0]}" if why else "")
    return None


def _own_sigma(entry: Entry) -> float | None:
    """The session's own standard deviation of K, from its 95 % interval (None without one)."""
    lo, hi = entry.K_ci95
    return (hi - lo) / (2 * Z95) if lo is not None and hi is not None else None


def _sigma(baseline: Sequence[Entry]) -> float:
    """Session-to-session standard deviation of K: the larger of the intervals' and the baseline's scatter."""
    widths = [w for e in baseline if (w := _own_sigma(e)) is not None]
    from_ci = math.sqrt(statistics.fmean(w * w for w in widths)) if widths else 0.0
    scatter = statistics.stdev(e.K_Nm_per_rad for e in baseline) if len(baseline) > 1 else 0.0  # type: ignore[misc]
    return max(from_ci, scatter)


#: The way on from an unstable baseline, in commands that exist wherever the warning is shown (the monitor, acq trend,
#: acq fleet, acq view --trend): "re-baseline with --baseline" sent a monitor's user to an option acq monitor has not.
REBASELINE = ("re-baseline: acq trend --baseline SESSION_ID judges against a session of the joint in a known state; "
              "a monitor learns a new baseline in a new --out")


def baseline_warning(baseline: Sequence[Entry]) -> str | None:
    """Why a baseline of several sessions cannot be trusted, or None: their K disagree far beyond their own intervals.

    A joint that changed while its baseline was learned (a monitor started on a joint already softening) gives a
    mean between old and new and a scatter σ that widens the EWMA's limit: the alarm comes late or never. Test:
    χ² = Σ (K_i − K̄)² / σ_i² about the inverse-variance weighted mean K̄, σ_i the session's 95 % half-width
    / 1.96, against χ² with n − 1 degrees of freedom at :data:`BASELINE_SIGNIFICANCE` — no tuned constant: each session's
    own interval says how much it may scatter. It assumes those intervals are honest (Gaussian about the truth);
    sessions without an interval are left out, and with fewer than two the test is not made."""
    known = [(e.K_Nm_per_rad, own) for e in baseline
             if e.K_Nm_per_rad is not None and (own := _own_sigma(e)) is not None and own > 0]
    if len(known) < 2:
        return None
    weights = [1.0 / own ** 2 for _, own in known]
    mean = sum(w * k for w, (k, _) in zip(weights, known)) / sum(weights)
    statistic = sum(w * (k - mean) ** 2 for w, (k, _) in zip(weights, known))
    if chi2.sf(statistic, len(known) - 1) >= BASELINE_SIGNIFICANCE:
        return None
    ks = [k for k, _ in known]
    scatter_pct = 100 * statistics.stdev(ks) / statistics.fmean(ks)
    known_pct = 100 * max(Z95 * own / k for k, own in known)  # the 95 % half width
    return (f"baseline unstable: its {len(known)} sessions scatter {scatter_pct:.1f} % while each is known to within "
            f"±{known_pct:.1f} % — the joint changed while the baseline was learned, and its alarm limits are too "
            f"wide; {REBASELINE}")


def compute_trend(joint: str, entries: Sequence[Entry], *, baseline_sessions: int | None = None,
                  baseline_id: str | None = None, threshold_pct: float | None = None,
                  ewma_lambda: float | None = None) -> Trend:
    """Judge a joint's sessions (oldest first) against a baseline with the threshold and EWMA rules.

    Parameters
    ----------
    joint : str
        The joint's name (for the heading).
    entries : sequence of Entry
        The sessions' analyses, oldest session first (see :func:`like_for_like`).
    baseline_sessions : int, optional
        Baseline = mean K of the first this many good sessions.
    baseline_id : str, optional
        Baseline = this session (its id or a unique prefix); overrides ``baseline_sessions``.
    threshold_pct : float, optional
        Alarm when K drops more than this below the baseline, %.
    ewma_lambda : float, optional
        Weight of the newest session in the EWMA, 0 < λ ≤ 1.

    A rule not given is the one the sessions were filed with, else acq's default (:func:`rules_for`).
    """
    entries, missing = like_for_like(entries)
    judged_by = rules_for(entries, baseline_sessions=baseline_sessions, threshold_pct=threshold_pct,
                          ewma_lambda=ewma_lambda)
    baseline_sessions, threshold_pct = judged_by.baseline_sessions, judged_by.threshold_pct
    ewma_lambda = judged_by.ewma_lambda
    skip = {id(e): missing.get(e.session_key) or _skip_reason(e) for e in entries}
    good = [e for e in entries if skip[id(e)] is None]
    if baseline_id is not None:
        pinned = [e for e in entries if (e.session_id or "").startswith(baseline_id)]
        if len(pinned) != 1:
            raise ConfigError(f"--baseline {baseline_id}: {'no' if not pinned else 'more than one'} session of "
                              f"joint {joint} has that id")
        if skip[id(pinned[0])] is not None:
            raise ConfigError(f"--baseline {baseline_id}: cannot be the baseline ({skip[id(pinned[0])]})")
        baseline, first = pinned, entries.index(pinned[0])
        note = f"session {pinned[0].session_id}"
    else:
        baseline = good[:baseline_sessions]
        first = entries.index(baseline[0]) if baseline else len(entries)
        note = (f"mean of the first {baseline_sessions} good sessions" if baseline_sessions > 1 else
                "first good session")
    if len(baseline) < (1 if baseline_id else baseline_sessions):
        points = [TrendPoint(e, "skipped", skip[id(e)] or "") if skip[id(e)] else TrendPoint(e, "before baseline")
                  for e in entries]
        wanted = f"{baseline_sessions} session{'s' if baseline_sessions > 1 else ''} of verdict ok"
        return Trend(joint, points, None, f"it needs {wanted}, {len(good)} so far", None,
                     threshold_pct, ewma_lambda, rules_source=judged_by.source)
    base = statistics.fmean(e.K_Nm_per_rad for e in baseline)  # type: ignore[misc]
    sigma = _sigma(baseline)
    warning = baseline_warning(baseline)
    z, var_z, points = base, 0.0, []
    for i, e in enumerate(entries):
        if skip[id(e)] is not None:
            points.append(TrendPoint(e, "skipped", skip[id(e)] or ""))
            continue
        if i < first:
            points.append(TrendPoint(e, "before baseline"))
            continue
        k = e.K_Nm_per_rad
        assert k is not None  # good entries have K
        change = 100.0 * (k / base - 1.0)
        if any(e is b for b in baseline):
            points.append(TrendPoint(e, "baseline", change_pct=change))
            continue
        z = ewma_lambda * k + (1.0 - ewma_lambda) * z
        # the EWMA's variance from each session's own σ, never below the baseline's: with every σ_i = σ this is the
        # textbook σ²·λ/(2 − λ)·(1 − (1 − λ)^2t); a session known only to ±3.3 % judged with the ±0.6 % of a
        # one-window baseline raised an EWMA alarm at −1.0 % (the third trial's fleet)
        var_z = (1.0 - ewma_lambda) ** 2 * var_z + (ewma_lambda * max(sigma, _own_sigma(e) or 0.0)) ** 2
        limit = EWMA_L * math.sqrt(var_z)
        rules = ["threshold"] if change < -threshold_pct else []
        rules += ["EWMA"] if z < base - limit else []
        points.append(TrendPoint(e, "alarm" if rules else "ok", "+".join(rules), change,
                                 100.0 * (z / base - 1.0), -100.0 * limit / base))
    return Trend(joint, points, base, note, sigma, threshold_pct, ewma_lambda, rules_source=judged_by.source,
                 baseline_warning=warning)


def trend_json(trend: Trend) -> dict[str, Any]:
    """The ``--json`` document: settings, baseline, alarm and every point (a monitor's window with the number its
    table, status and alarm lines give it, ``window``; null for a session of no monitor)."""
    return {"joint": trend.joint, "alarm": trend.alarm, "baseline_K_Nm_per_rad": trend.baseline_K_Nm_per_rad,
            "baseline": trend.baseline_note, "sigma_K_Nm_per_rad": trend.sigma_K_Nm_per_rad,
            "threshold_pct": trend.threshold_pct, "ewma_lambda": trend.ewma_lambda, "ewma_L": EWMA_L,
            "rules": trend.rules_source, "baseline_warning": trend.baseline_warning,
            "points": [{**asdict(p.entry), "window": window_number(p.entry.tags), "state": p.state, "reason": p.reason, "change_pct": p.change_pct,
                        "ewma_change_pct": p.ewma_change_pct, "ewma_limit_pct": p.ewma_limit_pct}
                       for p in trend.points]}
