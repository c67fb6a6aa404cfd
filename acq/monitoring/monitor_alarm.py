"""A monitor's trend read into its status figures, and the alarm it raises: counted, said, its ``--on-alarm`` command
started (:class:`acq.monitoring.alarm_command.AlarmCommands`) — once per episode; the windows filed whose alarm is still
to judge."""

from __future__ import annotations

from acq.monitoring.alarm_command import AlarmCommands
from acq.monitoring.catalogue import Entry
from acq.monitoring.monitor_scope import window_number
from acq.monitoring.monitor_status import MonitorStatus
from acq.monitoring.trend import Trend


class AlarmState:
    """Whether the monitor is in alarm (:attr:`active`), and the figures of ``status`` its trend gives."""

    def __init__(self, status: MonitorStatus, commands: AlarmCommands) -> None:
        self.status = status
        self.commands = commands
        self.active = False
        #: windows filed whose alarm was not judged yet (the trend could not be read after their write, or they were
        #: filed from the spool at start), in filing order
        self.unjudged: list[str] = []

    def judge(self, trend: Trend, key: str) -> None:
        """Update the status from ``trend`` after window ``key`` (session id; "" after a restart: figures only) was
        filed; entering alarm counts it and starts the command, staying in alarm says the latest K."""
        st = self.status
        st.baseline_K = trend.baseline_K_Nm_per_rad
        with_k = [p for p in trend.points if p.state in ("before baseline", "baseline", "ok", "alarm")]
        if with_k:  # while the baseline is learned too: a person watching wants to see K from the first good window
            last = with_k[-1]
            st.last_K, st.last_K_ci, st.change_pct = last.entry.K_Nm_per_rad, last.entry.K_ci95, last.change_pct
            st.last_K_window = window_number(last.entry.tags)
        st.baseline_warning = trend.baseline_warning
        st.state = "alarm" if trend.alarm else ("ok" if trend.judged else
                                                "baseline" if trend.baseline_K_Nm_per_rad else "learning baseline")
        point = next((p for p in trend.points if p.entry.session_id == key), None)
        if point is None or point.state not in ("ok", "alarm"):
            return
        if point.state == "alarm" and not self.active:
            st.alarms += 1
            self.raise_alarm(point.entry, trend)
        elif point.state == "alarm":  # still in alarm: the latest K (the one that raised it stays in the catalogue)
            st.message = alarm_message(point.entry)
        self.active = point.state == "alarm"

    def judge_unjudged(self, trend: Trend) -> None:
        """Judge the alarm after each window filed and not yet judged (:attr:`unjudged`), in filing order (an alarm in
        any of them is raised once, as if the trend had been read after each)."""
        for key in self.unjudged:
            self.judge(trend, key)
        self.unjudged.clear()

    def raise_alarm(self, entry: Entry, trend: Trend) -> None:
        """Start ``on_alarm`` (:class:`AlarmCommands`: through ``sh -c``, in the background) with the alarm's figures
        in its environment."""
        self.status.message = alarm_message(entry)
        self.commands.start({
            "ACQ_JOINT": trend.joint, "ACQ_K": f"{entry.K_Nm_per_rad:.6g}",
            "ACQ_BASELINE_K": f"{trend.baseline_K_Nm_per_rad:.6g}", "ACQ_SESSION": entry.path,
            "ACQ_WINDOW": str(window_number(entry.tags) or ""),
            "ACQ_CHANGE_PCT": f"{100 * (entry.K_Nm_per_rad / trend.baseline_K_Nm_per_rad - 1):.3g}"})  # type: ignore


def alarm_message(entry: Entry) -> str:
    """The status line of a window in alarm: its K, its number and its file."""
    number = window_number(entry.tags)
    window = f" in window {number}" if number is not None else ""
    return f"ALARM: K {entry.K_Nm_per_rad:.1f} N·m/rad{window} ({entry.path})"
