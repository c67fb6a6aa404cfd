"""acq monitor against what a plant does to it: SIGTERM to its process group, a worker killed, a full disk, a
catalogue server restarted — every window filed exactly once, or left for the restart, never lost."""

from __future__ import annotations

import contextlib
import json
import os
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from dataclasses import replace
from pathlib import Path

import pytest



from tests.helpers import run_cli, tmpfs
from tests import test_monitor
from tests.test_monitor import EXCITING_SEED, ROBOT, _bench, _rows

ROOT = Path(__file__).resolve().parents[1]
four_windows = test_monitor.four_windows  # the fixture: a monitor folder of 4 windows


def _env() -> dict[str, str]:
    """The environment of an acq child: this worktree's code first (its workers start without the current folder)."""
    return {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, (str(ROOT), os.environ.get("PYTHONPATH"))))}


@pytest.mark.parametrize(("signum", "reason"), [(signal.SIGTERM, "stopped by SIGTERM"),
                                                (signal.SIGHUP, "stopped by SIGHUP (a hang-up: its terminal closed, or kill -HUP)")])
def test_sigterm_to_the_process_group_lets_the_analysis_under_way_finish_and_be_filed(tmp_path: Path, signum: int,
                                                                                      reason: str) -> None:
    """The trial: ``timeout -s TERM 8 acq monitor …`` (timeout signals its whole group) killed the analysis worker
    too: "2 windows filed (1 analysis failed + 1 interrupted)", reason "worker failed: BrokenProcessPool", and the
    window's K lost for good. The workers ignore SIGTERM now: acq's process files the analysis, then stops them.
    A closed terminal hangs up the whole group (SIGHUP): it killed acq (exit 129, no summary, the window left
    ``recording``, monitor.lock left behind); now it stops the monitor as SIGTERM does."""
    out = tmp_path / "m"
    proc = subprocess.Popen([sys.executable, "-m", "acq", "monitor", "--bench", str(ROBOT), "--window", "10",
                             "--every", "10", "--out", str(out)], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, start_new_session=True, env=_env())
    deadline = time.monotonic() + 120
    while proc.poll() is None and time.monotonic() < deadline and len(list(out.glob("*.h5"))) < 2:
        time.sleep(0.05)  # the second window's capture started: the first one's analysis is under way
    assert proc.poll() is None, proc.communicate()
    first = sorted(out.glob("*.h5"))[0]
    assert not first.with_suffix(".result.json").exists()  # its analysis had not ended (10 s of data take longer)
    os.killpg(proc.pid, signum)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 130, err
    rows = _rows(out)
    assert [(r["window"], r["verdict"]) for r in rows] == [(0, rows[0]["verdict"]), (1, "interrupted")]
    assert rows[0]["verdict"] in ("ok", "not excited", "poor"), rows[0]  # analysed: K or why not
    assert "BrokenProcessPool" not in err and "not analysed" not in json.dumps(rows)
    assert err.splitlines()[-1].startswith(f"acq: {reason}: 2 windows filed (")
    assert not (out / "monitor.lock").exists()


def test_a_window_whose_worker_died_is_left_for_the_restart_and_analysed_there(tmp_path: Path) -> None:
    """A worker killed (out of memory, kill -9) mid-analysis: the window was filed "not analysed" and neither a restart
    nor acq analyze analysed it again. Now it is not filed; the next windows go to a new pool, and the restart
    analyses it."""
    from acq.monitoring.monitor import Monitor, MonitorSettings

    settings = MonitorSettings(bench=_bench(seed=EXCITING_SEED), out_dir=tmp_path, window_s=10.0, every_s=60.0,
                               for_s=180.0, fast=True, baseline_windows=2)
    killed: list[int] = []

    def kill_the_first_worker(status: object) -> None:
        analyses = monitor._analyses
        if not killed and analyses is not None and len(analyses):  # the first window handed to a worker
            deadline = time.monotonic() + 60
            while not analyses._pool._processes and time.monotonic() < deadline:
                time.sleep(0.01)  # the workers start (forked from the forkserver: seconds on a loaded machine)
            for pid in list(analyses._pool._processes):  # at once, while they still import the analysis (≥ 1 s):
                os.kill(pid, signal.SIGKILL)  # the window's worker dies before its analysis can complete
                killed.append(pid)

    monitor = Monitor(settings, on_status=kill_the_first_worker)
    assert monitor.run() == 0
    st = monitor.status
    assert killed and st.unfinished == 1
    assert [(r["window"], r["verdict"]) for r in _rows(tmp_path)] == [(1, "ok"), (2, "ok")]
    assert st.filed_total == 2 and st.filed["analysis failed"] == 0
    assert len(list(tmp_path.glob("*.h5"))) == 3  # its raw window kept for the restart
    # the restart analyses it (and captures one more)
    again = Monitor(replace(settings, for_s=60.0))
    assert again.run() == 0
    assert [(r["window"], r["verdict"]) for r in _rows(tmp_path)] == [(0, "ok"), (1, "ok"), (2, "ok"), (3, "ok")]


@pytest.fixture
def six_mb_disk(tmp_path: Path) -> Iterator[Path]:
    """A 6 MiB tmpfs (the trial's), mounted as root and unmounted after; skipped where this process may not mount."""
    folder = tmp_path / "tiny"
    folder.mkdir()
    with tmpfs(folder, "size=6m") as refused:
        if refused is not None:
            pytest.skip(f"needs a real 6 MiB file system, a tmpfs mounted as root: {refused}")
        yield folder


def test_a_max_disk_the_file_system_cannot_hold_is_refused(capsys: pytest.CaptureFixture[str],
                                                          six_mb_disk: Path) -> None:
    """The trial's --max-disk 100MB on a 6 MB tmpfs ran on, losing windows to the full disk."""
    out = six_mb_disk / "m2"
    run = run_cli(capsys, "monitor", "--bench", str(ROBOT), "--window", "4", "--every", "5", "--for", "60s", "--fast",
                  "--out", str(out), "--max-disk", "100MB")
    assert (run.code, run.err) == (2, f"acq: error: --max-disk 100 MB: the file system of {out} has 6.3 MB free — "
                                      "the disk would be full before the budget: give --max-disk 6.2MB or less, or "
                                      "free space there\n")
    assert not out.exists()


def test_a_full_disk_stops_the_monitor_after_the_second_window_it_cannot_store(capsys: pytest.CaptureFixture[str],
                                                                              six_mb_disk: Path) -> None:
    """The trial: "55 s: 12 filed = 3 ok + 1 not excited + 8 interrupted … — done", exit 0, "disk full" never shown,
    the baseline learning for ever. Two 1.04 MB windows of the baseline (kept whatever the disk; the window not
    excited is deleted) leave 4.0 MB: a window needs 4.4 MB (1.7 MB expected, as much again for the writer's last
    flush of a --fast window, and its 1 MiB reserve); retention can free nothing, the window after it is tried, and the
    second failure stops the monitor, exit 1: the baseline cannot be learned on this disk."""
    out = six_mb_disk / "m2"
    run = run_cli(capsys, "monitor", "--bench", str(ROBOT), "--window", "4", "--every", "5", "--for", "60s", "--fast",
                  "--out", str(out))
    lines = run.err.splitlines()
    assert (run.code, lines[-1]) == (1, f"acq: error: disk full: {out} — monitor stopped after window 5 (3 windows "
                                        "kept)")
    assert (f"15 s: 3 filed = 2 ok + 1 not excited, 1 not captured (disk full), excited 93 % of the last window, last "
            f"K 890.9 (window 3), ΔK — %, learning baseline, 2.3 MB — window 4 not captured: disk full: {out} has 4.0 "
            "MB free, a window needs 4.4 MB — the next window is tried once room is made; a second failure stops"
            ) in lines
    assert [r["verdict"] for r in _rows(out)] == ["not excited", "ok", "ok"]


def test_a_window_cut_by_a_full_disk_is_named_so_and_the_monitor_goes_on_once_there_is_room(
        six_mb_disk: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Another program fills the disk while window 2 is captured and frees it after: window 2 counts "write failed"
    (catalogued interrupted, with the cause), the status line names the disk, and window 3 is captured."""
    from acq.monitoring.monitor import Monitor, MonitorSettings
    from acq.recording.recorder import Recorder

    out = six_mb_disk / "m"
    filler = six_mb_disk / "other_program.bin"
    capture = Recorder.run
    filled: list[int] = []

    def another_program_fills_the_disk(recorder: Recorder) -> object:
        if monitor.status.captured == 1 and not filled:
            filled.append(1)
            free = os.statvfs(six_mb_disk).f_bavail * os.statvfs(six_mb_disk).f_frsize
            filler.write_bytes(b"\0" * (free - 1_500_000))
            try:
                return capture(recorder)
            finally:
                filler.unlink()
        return capture(recorder)

    monkeypatch.setattr(Recorder, "run", another_program_fills_the_disk)
    settings = MonitorSettings(bench=_bench(seed=EXCITING_SEED), out_dir=out, window_s=4.0, every_s=5.0, for_s=15.0,
                               fast=True, baseline_windows=1, keep=0)
    messages: list[str] = []
    monitor = Monitor(settings, on_status=lambda st: messages.append(st.message))
    assert monitor.run() == 0
    rows = _rows(out)
    assert [(r["window"], r["verdict"]) for r in rows] == [(0, "ok"), (1, "interrupted"), (2, "ok")]
    reason = json.loads(rows[1]["reasons_json"])[0]
    assert reason.startswith(f"window capture failed: disk full: {out}/") and reason.endswith(" s kept")
    assert monitor.status.filed == {"ok": 2, "poor or failed": 0, "not excited": 0, "skipped": 0,
                                    "analysis failed": 0, "interrupted": 0, "write failed": 1}
    said = next(m for m in messages if m.startswith("window 2 capture failed"))
    assert said == (f"window 2 capture failed: {reason.removeprefix('window capture failed: ')} — the next window is "
                    "tried once room is made; a second failure stops")


def test_a_window_whose_raw_frame_log_the_disk_refuses_is_filed_failed_with_its_reason(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch) -> None:
    """A monitor on the CANopen robot whose first window's raw frame log (.can.blf) the disk refuses (the disk is the
    hardware faked: the BLF writer's open fails with ENOSPC once). Before: the monitor stopped, exit 1, "raw frame log
    not kept: disk full: …", and the window's file, finished failed, was in no catalogue (the catalogue, empty, was
    even removed): the fleet never learned the window failed. Now it is filed — session status failed, verdict
    interrupted, the file's reason — counted "write failed", and the next window is captured."""
    import errno

    import can

    opened: list[str] = []
    blf_writer = can.BLFWriter

    def refused_once(path: object, *args: object, **kwargs: object) -> object:
        opened.append(str(path))
        if len(opened) == 1:
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(path))
        return blf_writer(path, *args, **kwargs)

    monkeypatch.setattr(can, "BLFWriter", refused_once)
    bench = tmp_path / "canopen.toml"
    bench.write_text((ROBOT.parent / "sim_robot_canopen.toml").read_text()
                     .replace('"acq-sim-robot"', f'"acq-test-rawlog-{os.getpid()}"'))
    out = tmp_path / "m"
    run = run_cli(capsys, "monitor", "--bench", str(bench), "--window", "4", "--every", "4", "--for", "8s", "--out",
                  str(out))
    assert run.code == 0 and "Traceback" not in run.err, run.err
    failed = Path(opened[0]).with_suffix("").with_suffix(".h5")
    rows = _rows(out)
    assert [(r["window"], r["verdict"]) for r in rows][0] == (0, "interrupted") and len(rows) == 2
    assert rows[1]["verdict"] != "interrupted"  # the next window captured (and analysed)
    reason = f"raw frame log not kept: disk full: {opened[0]}"
    assert (rows[0]["path"], json.loads(rows[0]["reasons_json"])) == (str(failed.resolve()),
                                                                       [f"window capture failed: {reason}"])
    import sqlite3

    with contextlib.closing(sqlite3.connect(out / "catalogue.sqlite")) as db:
        assert db.execute("SELECT status FROM sessions WHERE path = ?", (str(failed.resolve()),)).fetchall() == [
            ("failed",)]
    assert "1 write failed" in run.err or "1 write failed" in run.out, run.err


def test_a_window_cut_in_an_earlier_run_is_filed_as_that_runs_and_the_counts_add_up(
        four_windows: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The trial: after kill -9 the restart said "1 filed in this run (5 in the folder) = 1 interrupted" — the window
    the kill cut, of the earlier run — and "N in the folder" counted a window at its capture, one ahead of those
    filed. Here: 4 windows filed, a fifth cut by kill -9; the restart files it (the earlier run's) and captures one."""
    from acq.recording.writer import SessionWriter
    from drivers.base import CurrentSourceInfo, DriveInfo
    from tests.test_monitor import _bench_file, _restarted_elsewhere

    out = tmp_path / "resumed"
    _restarted_elsewhere(four_windows, out)
    identity = json.loads((out / "monitor.id").read_text())
    writer = SessionWriter(out / "cut.h5", bench=_bench(seed=EXCITING_SEED), profile=None,
                           current_info=CurrentSourceInfo(rate_hz=25600.0, channels=("i_a",), device="sim-daq"),
                           drive_info=DriveInfo(period_s=0.001, counts_per_rev=131072, transport="sim",
                                                timestamp_kind="drive_cycle", device="sim-drive"),
                           host_ns_at_start=0, tags={"monitor_window": 4, "monitor_elapsed_s": 240.0,
                                                     "monitor_id": identity["monitor_id"]})
    writer._file.close()  # as a kill -9 leaves it (the kernel drops its lock: acq.recording.live)
    writer._marker.close()
    run = run_cli(capsys, "monitor", "--bench", str(_bench_file(tmp_path, seed=EXCITING_SEED)), "--fast", "--for",
                  "1m", "--baseline-windows", "2", "--keep", "1", "--out", str(out))
    assert run.code == 0, run.err
    lines = [line.split(", excited")[0] for line in run.err.splitlines() if " filed" in line and line[0].isdigit()]
    assert list(dict.fromkeys(lines)) == ["3.2 min: 0 filed in this run (5 in the folder)",
                                          "4.2 min: 0 filed in this run (5 in the folder)",
                                          "5.2 min: 0 filed in this run (5 in the folder)",
                                          "5.2 min: 1 filed in this run (6 in the folder) = 1 ok"]
    table = " ".join(run.err.split())
    assert "windows filed (this run) │ 1 = 1 ok │" in table and "windows in the folder (earlier runs too) │ 6 │" in table
    assert len(_rows(out)) == 6


@pytest.fixture(scope="module")
def stoppable_postgres() -> Iterator[object]:
    """A PostgreSQL server of these tests alone (they stop and start it), skipped as the catalogue tests' one is."""
    from tests.conftest import _server_binaries_or_skip
    from tests.pg_server import controllable_server

    with controllable_server(_server_binaries_or_skip()) as server:
        yield server


def _pg_windows(url: str) -> list[tuple[int, int]]:
    """(window, rows of its session) of every window filed in the database at ``url``."""
    import psycopg

    with psycopg.connect(url) as db:
        rows = db.execute("SELECT s.tags_json, count(*) FROM sessions s JOIN analyses a USING (session_key) "
                          "GROUP BY s.session_key, s.tags_json").fetchall()
    return sorted((json.loads(tags)["monitor_window"], n) for tags, n in rows)


def test_a_postgresql_restart_mid_run_loses_no_window_and_files_each_once(stoppable_postgres: object,
                                                                         tmp_path: Path) -> None:
    """The trial: ``pg_ctl stop -m fast`` under a running monitor ended it ("acq: error: terminating connection due to
    administrator command", exit 1). Now capture goes on, the windows wait (memory and the spool file), the status
    says since when the catalogue is unreachable, and once the server is back every window is filed exactly once."""
    from acq.monitoring.monitor import Monitor, MonitorSettings
    from tests.pg_server import new_database

    server = stoppable_postgres
    url = new_database(server.url)  # type: ignore[attr-defined]
    seen: list[tuple[str | None, int]] = []

    def operator(st: object) -> None:
        status = monitor.status
        seen.append((status.catalogue_down_since, status.waiting))
        if status.filed_total == 1 and server.running and not status.catalogue_down_since:  # type: ignore[attr-defined]
            server.stop()  # type: ignore[attr-defined]
        elif status.waiting >= 2 and not server.running:  # type: ignore[attr-defined]
            assert (tmp_path / "catalogue-spool.jsonl").read_text().count("\n") == status.waiting
            server.start()  # type: ignore[attr-defined]

    settings = MonitorSettings(bench=_bench(seed=EXCITING_SEED), out_dir=tmp_path, window_s=10.0, every_s=60.0,
                               for_s=360.0, fast=True, baseline_windows=2, catalogue=url)
    monitor = Monitor(settings, on_status=operator)
    assert monitor.run() == 0
    assert _pg_windows(url) == [(n, 1) for n in range(6)]
    downs = [since for since, _ in seen if since is not None]
    assert downs and max(n for _, n in seen) >= 2  # it said so, with windows waiting
    assert monitor.status.filed_total == 6 and monitor.status.waiting == 0
    assert not (tmp_path / "catalogue-spool.jsonl").exists()


def _two_windows_spooled(server: object, out: Path) -> tuple[object, str]:
    """A 3-window monitor run into a new database of ``server`` that stops the server once window 0 is filed: it ends
    with 1 window filed and windows 1, 2 in ``out``'s spool; the server is started again. Its settings and the
    database's URL."""
    from acq.monitoring.monitor import Monitor, MonitorSettings
    from tests.pg_server import new_database

    url = new_database(server.url)  # type: ignore[attr-defined]

    def operator(st: object) -> None:
        if monitor.status.filed_total == 1 and server.running:  # type: ignore[attr-defined]
            server.stop()  # type: ignore[attr-defined]

    settings = MonitorSettings(bench=_bench(seed=EXCITING_SEED), out_dir=out, window_s=10.0, every_s=60.0,
                               for_s=180.0, fast=True, baseline_windows=2, catalogue=url)
    monitor = Monitor(settings, on_status=operator)
    try:
        assert monitor.run() == 0
        assert (monitor.status.filed_total, monitor.status.waiting) == (1, 2)
    finally:
        server.start()  # type: ignore[attr-defined]
    return settings, url


def test_windows_waiting_when_the_monitor_stops_are_filed_by_its_next_start(stoppable_postgres: object,
                                                                          tmp_path: Path,
                                                                          capsys: pytest.CaptureFixture[str]) -> None:
    """Stopped while the server is down, the monitor leaves its windows in the spool file and says so; the next start
    (server back) files them first, then goes on: each window filed once, none analysed twice."""
    from acq.monitoring.monitor import Monitor

    settings, url = _two_windows_spooled(stoppable_postgres, tmp_path)
    spool = [json.loads(line) for line in (tmp_path / "catalogue-spool.jsonl").read_text().splitlines()]
    assert [w["outcome"]["session"]["tags"]["monitor_window"] for w in spool] == [1, 2]
    again = Monitor(replace(settings, for_s=60.0))
    assert again.run() == 0
    assert _pg_windows(url) == [(n, 1) for n in range(4)]
    assert again.status.filed_total == 1 and again.status.earlier_filed == 3
    assert not (tmp_path / "catalogue-spool.jsonl").exists()


def test_a_window_from_the_spool_does_not_replace_a_later_analysis_of_it(stoppable_postgres: object,
                                                                         tmp_path: Path) -> None:
    """While the monitor could not reach the server, window 1 was analysed again elsewhere and filed (as
    ``acq analyze --catalogue`` of its file does, one second after the monitor's analysis; K 2 % higher). The next
    start files the spool: window 1 keeps the later analysis and the status says why; window 2 is filed. Before: the
    spooled analysis replaced the later one."""
    from datetime import datetime, timedelta

    from acq.monitoring.catalogue import Catalogue, Outcome
    from acq.monitoring.monitor import Monitor

    settings, url = _two_windows_spooled(stoppable_postgres, tmp_path)
    spooled = Outcome(**json.loads((tmp_path / "catalogue-spool.jsonl").read_text().splitlines()[0])["outcome"])
    assert spooled.session["tags"]["monitor_window"] == 1 and spooled.doc is not None
    assert spooled.analyzed_utc == spooled.doc["analyzed_utc"]
    later = (datetime.fromisoformat(spooled.doc["analyzed_utc"]) + timedelta(seconds=1)).isoformat()
    K = 1.02 * spooled.doc["K_Nm_per_rad"]
    with Catalogue(url) as catalogue:
        assert catalogue.record(replace(spooled, doc={**spooled.doc, "K_Nm_per_rad": K, "analyzed_utc": later},
                                        analyzed_utc=None)) is None
    messages: list[str] = []
    again = Monitor(replace(settings, for_s=60.0), on_status=lambda st: messages.append(st.message))
    assert again.run() == 0
    assert _pg_windows(url) == [(n, 1) for n in range(4)]
    with Catalogue(url) as catalogue:
        (entry,) = [e for e in catalogue.entries() if e.tags["monitor_window"] == 1]
    assert (entry.K_Nm_per_rad, entry.analyzed_utc) == (K, later)
    name = Path(spooled.path).name
    assert (f"{name}: not filed — the catalogue holds a later analysis of it ({later}; this one "
            f"{spooled.doc['analyzed_utc']})") in messages
    assert not (tmp_path / "catalogue-spool.jsonl").exists()


def test_an_alarm_in_windows_filed_from_the_spool_is_raised_by_the_next_start(stoppable_postgres: object,
                                                                             tmp_path: Path) -> None:
    """K falls 5 % per simulated minute; the server stops once the 2-window baseline is filed, so the windows that
    would alarm wait in the spool and the run ends without judging them. The next start files them and judges each:
    the alarm is raised (counted once, --on-alarm run once) — before, the start took the trend's alarm for one
    announced before the stop, and the episode was never announced."""
    from acq.monitoring.monitor import Monitor, MonitorSettings
    from tests.pg_server import new_database

    server = stoppable_postgres
    url = new_database(server.url)  # type: ignore[attr-defined]
    ran = tmp_path / "alarm-ran"

    def operator(st: object) -> None:
        if monitor.status.filed_total == 2 and server.running:  # type: ignore[attr-defined]
            server.stop()  # type: ignore[attr-defined]

    out = tmp_path / "m"
    settings = MonitorSettings(bench=_bench(seed=EXCITING_SEED, K_decay_pct_per_hour=300.0), out_dir=out,
                               window_s=10.0, every_s=60.0, for_s=300.0, fast=True, baseline_windows=2,
                               catalogue=url, on_alarm=f"echo $ACQ_WINDOW >> {ran}")
    monitor = Monitor(settings, on_status=operator)
    try:
        assert monitor.run() == 0
        assert (monitor.status.filed_total, monitor.status.waiting, monitor.status.alarms) == (2, 3, 0)
    finally:
        server.start()  # type: ignore[attr-defined]
    again = Monitor(replace(settings, for_s=60.0))  # one more window, in the same episode
    code = again.run()
    assert (code, again.status.alarms) == (3, 1)
    assert len(ran.read_text().split()) == 1 and int(ran.read_text()) >= 3  # once, for a spooled window (3…5)


def test_the_status_line_says_since_when_the_catalogue_is_unreachable() -> None:
    from acq.monitoring.monitor_status import MonitorStatus
    from acq.ui.monitor_cli import catalogue_text

    assert catalogue_text(MonitorStatus("joint1", catalogue_down_since="21:30:05", waiting=2)) == (
        "catalogue unreachable since 21:30:05 UTC (2 windows waiting)")
    assert catalogue_text(MonitorStatus("joint1", waiting=1)) == "1 window waiting for the catalogue"


_TRACKER_PID = """
import os, signal, time
from multiprocessing import resource_tracker
from acq.monitoring.analysis_pool import analysis_executor
got = []
signal.signal(signal.SIGHUP, lambda s, f: got.append(s))
with analysis_executor(1, None) as pool:
    tracker = resource_tracker._resource_tracker._pid
    os.kill(tracker, signal.SIGHUP)  # a closed terminal hangs up its whole foreground group
    time.sleep(0.3)
    alive = os.waitpid(tracker, os.WNOHANG) == (0, 0)
    blocked = int(next(l for l in open(f"/proc/{tracker}/status") if l.startswith("SigBlk:")).split()[1], 16)
    print(alive, bool(blocked & (1 << (signal.SIGHUP - 1))), signal.pthread_sigmask(signal.SIG_BLOCK, []) == set())
"""


def test_the_resource_tracker_outlives_a_hangup_and_acq_keeps_its_own() -> None:
    """The review of session 15: a closed terminal's SIGHUP killed the resource tracker ("alive: False"); it now
    starts with SIGHUP blocked, which it keeps (it unblocks only SIGINT and SIGTERM), and acq's own mask is as it was —
    ignored instead, a SIGHUP to acq while the tracker started was lost."""
    run = subprocess.run([sys.executable, "-c", _TRACKER_PID], capture_output=True, text=True, timeout=120, env=_env())
    assert run.stdout.split() == ["True", "True", "True"], run.stderr
