"""What ``acq monitor`` is asked for (:class:`MonitorSettings`) and the figures it shows (:class:`MonitorStatus`).

Apart from the loop (:mod:`acq.monitoring.monitor`) because the command line and the status table
(:mod:`acq.ui.monitor_cli`) deal in these alone.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from acq.monitoring.catalogue import Outcome
from acq.offline.excitation_judge import selection_reason
from analysis import AnalysisRequest
from drivers.config import Bench

@dataclass(frozen=True)
class MonitorSettings:
    """What ``acq monitor`` was asked for (SI units; sizes in bytes)."""

    bench: Bench
    out_dir: Path
    window_s: float
    every_s: float
    for_s: float | None = None
    on_alarm: str | None = None
    keep: int = 10
    max_disk_bytes: int | None = None
    fast: bool = False
    jobs: int = 1
    baseline_windows: int = 5
    threshold_pct: float = 10.0
    ewma_lambda: float = 0.2
    # a robot program excites the joint only in parts: the default request averages only the segments that excite
    # (analysis.segments) where acq did not command the motion — as acq analyze of a window does, under the same key
    request: AnalysisRequest = AnalysisRequest()
    # the catalogue every window is filed into (a SQLite file or a postgresql:// URL, shared with other monitors and
    # benches); None: out_dir/catalogue.sqlite
    catalogue: Path | str | None = None
    tags: dict[str, str | float] = field(default_factory=dict)  # --tag K=V, filed with every window (robot=r1)
    # the way on for a folder whose identity is bound to another host or folder (monitor_scope.bound_identity)
    new_identity: bool = False
    moved: bool = False
    move_catalogue: bool = False  # copy the windows from the catalogue they are filed in to `catalogue` first


#: How a window filed in the catalogue counts (:meth:`MonitorStatus.count`), in the order shown: every filed window is
#: in exactly one, so the counts add up to the catalogue's rows of the run.
FILED_KINDS = ("ok", "poor or failed", "not excited", "skipped", "analysis failed", "interrupted", "write failed")


@dataclass
class MonitorStatus:
    """The live figures of a monitor (shown by :func:`acq.ui.monitor_cli.status_table`)."""

    joint: str
    captured: int = 0  # in this run, captures that completed (an interrupted one is filed, not captured)
    resumed: int = 0  # windows of earlier runs in the folder (a restart resumes them)
    # of them those the catalogue holds: filed by those runs, or by this one's restart (a capture they left cut, an
    # analysis they left undone) — not this run's, which "filed in this run" counted before (the trial)
    earlier_filed: int = 0
    # the windows this run filed in the catalogue, by how they count (FILED_KINDS: verdict ok; poor or failed — a K
    # the trend does not judge; not excited; skipped — the analysis fell behind the capture; analysis failed — a
    # worker died or the analysis raised; interrupted — the capture was cut; write failed — the capture was cut because
    # the folder's storage refused a write: disk full, I/O error, read-only — catalogued as interrupted, with the cause)
    filed: dict[str, int] = field(default_factory=lambda: dict.fromkeys(FILED_KINDS, 0))
    not_captured: int = 0  # not captured: the disk budget would have been exceeded (not filed)
    no_room: int = 0  # not captured: the file system had no room for a window, once retention made what it could
    unfinished: int = 0  # captured, but their analysis did not complete (a worker died): not filed, a restart does
    copied_deleted: int = 0  # raw windows of other monitors copied into the folder, deleted for the disk budget
    # raw files kept as damaged (filed without a K, the file damaged: evidence): never deleted for --keep, last for
    # --max-disk or a full disk (acq.monitoring.retention) — counted so that a disk damaging every window is seen
    damaged_kept: int = 0
    alarms: int = 0
    catalogue_down_since: str | None = None  # the catalogue out of reach since (HH:MM:SS UTC), None: it answers
    catalogue_problem: str = ""  # why, in its driver's words
    waiting: int = 0  # windows waiting for the catalogue (kept in the folder's spool file meanwhile; not yet filed)
    alarm_command_failure: str | None = None  # the last --on-alarm command's problem: "alarm command failed: exit 1"
    machine_time_s: float = 0.0  # the start of the window being captured; its end once it is captured
    disk_bytes: int = 0
    last_K: float | None = None
    last_K_window: int | None = None  # the window last_K is of, as shown (from 1: monitor_scope.window_number)
    last_K_ci: tuple[float | None, float | None] = (None, None)
    change_pct: float | None = None
    baseline_K: float | None = None
    state: str = "starting"
    baseline_warning: str | None = None  # the baseline's windows disagree beyond their intervals (Trend's)
    message: str = ""
    last_excited_fraction: float | None = None  # share of the last analysed window that excites the joint
    last_moves: tuple[dict[str, Any], ...] = ()  # its moves: index, start_s, duration_s, peak_rad_s, excited
    # of a last window whose segment selection did not apply: how many Welch segments it examined, why too few excite
    last_segments: str | None = None
    # of a last window filed "not excited": why, the first of its reasons (its moves may excite 87 % of it, and its
    # coherence between f_a and f_r fall short: the excited share alone contradicted the verdict)
    last_not_excited_why: str | None = None
    excited_fraction_sum: float = 0.0  # over the windows judged for excitation (for the share of the program)
    excitation_judged: int = 0

    @property
    def in_folder(self) -> int:
        """The monitor's windows filed in its catalogue, of earlier runs and this one (a window is counted once it is
        filed: counted at its capture, the figure ran one ahead of the windows filed)."""
        return self.earlier_filed + self.filed_total

    @property
    def filed_total(self) -> int:
        """Windows this run filed in the catalogue (the sum of :attr:`filed`)."""
        return sum(self.filed.values())

    @property
    def analysed(self) -> int:
        """Filed windows the analysis judged: ok, poor or failed, not excited."""
        return self.filed["ok"] + self.filed["poor or failed"] + self.filed["not excited"]

    @property
    def skipped(self) -> int:
        """Captured windows not analysed because the analysis fell behind (back-pressure)."""
        return self.filed["skipped"]

    def count(self, outcome: Outcome, kind: str | None = None, earlier: bool = False) -> None:
        """Count a window just catalogued in one of :data:`FILED_KINDS` (``kind``: the caller's, "skipped" or "write
        failed"; else the verdict's) — or, ``earlier``, as a window of an earlier run (:attr:`earlier_filed`) — and
        which share of it and which moves excite (segment selection; a window the joint did not travel in excites
        nowhere)."""
        verdict = (outcome.doc or {}).get("quality", {}).get("verdict")
        kind = kind or ("ok" if verdict == "ok" else "poor or failed" if verdict in ("poor", "failed") else
                        "not excited" if verdict == "not excited" else "interrupted" if verdict == "interrupted" else
                        "analysis failed")  # an analysis that raised: no result at all
        if earlier:
            self.earlier_filed += 1
        else:
            self.filed[kind] += 1
        excitation = (outcome.doc or {}).get("excitation")
        if excitation is None and verdict != "not excited":
            return
        self.last_excited_fraction = excitation["excited_fraction"] if excitation else 0.0
        self.last_moves = tuple(excitation["moves"]) if excitation else ()
        self.last_segments = selection_reason(excitation) if excitation and not excitation["selection_applied"] else None
        reasons = [r for r in outcome.doc["quality"]["reasons"] if not r.startswith("note: ")] if outcome.doc else []
        self.last_not_excited_why = (reasons[0] if reasons else "no reason given") if verdict == "not excited" else None
        self.excited_fraction_sum += self.last_excited_fraction
        self.excitation_judged += 1

    @property
    def program_excited_fraction(self) -> float | None:
        """Share of the program's windows (time) that excites the joint, over the windows judged so far."""
        return self.excited_fraction_sum / self.excitation_judged if self.excitation_judged else None
