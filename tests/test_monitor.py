"""acq monitor: passive capture, windows catalogued, not-excited windows, retention, alarm command, resume."""

from __future__ import annotations

import collections
import contextlib
import json
import os
import re
import shutil
import signal
import sqlite3
import subprocess
import sys
import time
from dataclasses import replace
from pathlib import Path

import h5py
import numpy as np
import pytest

import acq.offline.analyze
from acq.config import load_bench
from acq.monitoring.retention import WindowFiles, make_room, parse_size, to_delete
from acq.recording.recorder import Recorder, RecordingResult
from acq.recording.reader import load
from acq.recording.writer import SessionWriter
from drivers.base import CurrentSourceInfo, DriveInfo
from drivers.config import Bench
from acqcore.errors import ConfigError
from drivers.registry import open_bench
from tests.helpers import run_cli

ROBOT = Path(__file__).resolve().parents[1] / "configs" / "benches" / "sim_robot.toml"
#: With this seed the robot program excites the joint in each of the windows at 0, 1, … 5 min (verdict ok);
#: with the shipped seed 0 three of them are "not excited" (measured; the analysis' coherence decides).
EXCITING_SEED = 5


def _bench(**sim: float) -> Bench:
    bench = load_bench(ROBOT)
    return bench.model_copy(update={"sim": bench.sim.model_copy(update=sim)})


def _bench_file(tmp_path: Path, **sim: float) -> Path:
    """sim_robot.toml with some of its [sim] values replaced."""
    lines = ROBOT.read_text().splitlines()
    for key, value in sim.items():
        lines = [f"{key} = {value}" if line.startswith(f"{key} =") else line for line in lines]
    path = tmp_path / "bench.toml"
    path.write_text("\n".join(lines))
    return path


def _restarted_elsewhere(folder: Path, out: Path) -> None:
    """A copy of the monitor ``folder`` at ``out`` that stands for the same monitor restarted (the fixture's folder is
    shared by the tests): its identity bound to ``out``, as a folder moved there is (a copy left bound to ``folder``,
    which still holds it, is refused as a copy)."""
    shutil.copytree(folder, out)
    identity = json.loads((out / "monitor.id").read_text())
    (out / "monitor.id").write_text(json.dumps({**identity, "folder": str(out.resolve())}))


def _rows(folder: Path) -> list[dict[str, object]]:
    db = sqlite3.connect(folder / "catalogue.sqlite")
    db.row_factory = sqlite3.Row
    rows = db.execute("SELECT s.path, s.tags_json, a.verdict, a.K_Nm_per_rad, a.reasons_json, a.truth_json, "
                      "a.excitation_json FROM sessions s JOIN analyses a USING (session_key) "
                      "ORDER BY s.created_utc, s.start_monotonic_ns")
    out = [{**dict(r), "window": json.loads(r["tags_json"])["monitor_window"]} for r in rows]
    db.close()
    return sorted(out, key=lambda r: r["window"])


class _SpyDrive:
    """The simulated drive, counting the motion commands it receives."""

    def __init__(self, drive: object) -> None:
        self._drive, self.motion_commands = drive, []

    def start_motion(self, profile: object) -> None:
        self.motion_commands.append("start")
        self._drive.start_motion(profile)  # type: ignore[attr-defined]

    def stop_motion(self) -> None:
        self.motion_commands.append("stop")
        self._drive.stop_motion()  # type: ignore[attr-defined]

    def __getattr__(self, name: str) -> object:
        return getattr(self._drive, name)


def test_passive_capture_never_commands_motion_and_the_robot_moves_the_joint(tmp_path: Path) -> None:
    bench = _bench()
    current, drive = open_bench(bench, fast=True)
    spy = _SpyDrive(drive)
    result = Recorder(bench, None, current, spy, tmp_path, 3.0).run()  # type: ignore[arg-type]
    assert spy.motion_commands == []
    session = load(result.path)
    assert result.status == "complete" and session.profile is None
    assert (result.current_samples, result.encoder_samples, result.current_gaps, result.encoder_gaps) == (
        76800, 3000, 0, 0)  # 3 s of 25.6 kHz and 1 kHz, nothing lost
    counts = session.encoder.position_counts
    assert abs(counts.max() - counts.min()) > bench.encoder.counts_per_rev  # the robot program moved it > 1 rev


def test_acq_record_on_a_listening_bench_records_passively_without_a_profile(capsys: pytest.CaptureFixture[str],
                                                                           tmp_path: Path) -> None:
    """`acq record` asked for --profile, then refused it with "record without a profile", which the CLI had no way
    to do. Now: no --profile, the machine's own motion recorded and identified on the segments that excite."""
    bench = _bench_file(tmp_path, seed=EXCITING_SEED)
    run = run_cli(capsys, "record", "--bench", str(bench), "--duration", "10", "--fast", "--out", str(tmp_path / "s"))
    assert run.code == 0, run.err
    (path,) = (tmp_path / "s").glob("*.h5")
    session = load(path)
    assert session.profile is None and session.status == "complete"
    assert (session.current.sample_count, session.encoder.position_counts.size) == (256000, 10000)
    (result,) = (tmp_path / "s").glob("*.result.json")
    doc = json.loads(result.read_text())
    assert doc["excitation"]["selection_applied"] is True and doc["quality"]["verdict"] == "ok"
    assert doc["K_Nm_per_rad"] == pytest.approx(891.0, rel=0.02)
    refused = run_cli(capsys, "record", "--bench", str(bench), "--duration", "10", "--profile", "triangle_0.2s",
                      "--out", str(tmp_path / "t"))
    assert (refused.code, refused.err.strip()) == (2, f"acq: error: --profile triangle_0.2s: {bench} has [drive] motion "
                                                      "= \"external\": the machine's own controller moves the joint and acq "
                                                      "never commands motion — leave out --profile to record passively "
                                                      "what the machine does")
    no_length = run_cli(capsys, "record", "--bench", str(bench), "--out", str(tmp_path / "t"))
    assert (no_length.code, no_length.err.strip()) == (2, f"acq: error: {bench} has [drive] motion = \"external\": a "
                                                          "passive recording has no profile to take its length from — "
                                                          "give --duration (seconds)")
    commanded = run_cli(capsys, "record", "--out", str(tmp_path / "t"))
    assert commanded.code == 2 and "Missing option '--profile'" in commanded.err
    assert not (tmp_path / "t").exists()


def test_passive_bench_refuses_a_profile_and_a_commanded_bench_needs_one(tmp_path: Path) -> None:
    from acq.config import load_profile

    bench = _bench()
    current, drive = open_bench(bench, fast=True)
    with pytest.raises(ConfigError, match='motion = "external": acq must not command motion'):
        Recorder(bench, load_profile("triangle_0.2s"), current, drive, tmp_path, 1.0)
    commanded = load_bench(None)
    with pytest.raises(ConfigError, match="without a profile needs"):
        Recorder(commanded, None, current, drive, tmp_path, 1.0)


def test_monitor_refuses_a_bench_that_commands_motion(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    sim = Path(__file__).resolve().parents[1] / "configs" / "benches" / "sim.toml"
    run = run_cli(capsys, "monitor", "--bench", str(sim), "--fast", "--for", "1m", "--out", str(tmp_path))
    assert run.code == 2 and 'acq monitor listens only — set [drive] motion = "external"' in run.err


@pytest.fixture(scope="module")
def four_windows(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A --fast monitor of 4 windows (all four excite), baseline 2 windows, raw files of the last 1 kept."""
    from acq.ui.cli import main

    out = tmp_path_factory.mktemp("monitor")
    bench = _bench_file(tmp_path_factory.mktemp("bench"), seed=EXCITING_SEED)
    with pytest.raises(SystemExit) as exc:
        main(["monitor", "--bench", str(bench), "--fast", "--window", "10", "--every", "60", "--for", "4m",
              "--baseline-windows", "2", "--keep", "1", "--out", str(out)])
    assert exc.value.code == 0
    return out


def test_a_short_fast_monitor_catalogues_every_window_with_K_near_the_truth(four_windows: Path) -> None:
    rows = _rows(four_windows)
    assert [r["window"] for r in rows] == [0, 1, 2, 3]
    for r in rows:
        assert r["verdict"] == "ok"
        truth = json.loads(r["truth_json"])["K_Nm_per_rad"]
        assert r["K_Nm_per_rad"] == pytest.approx(truth, rel=0.03)


def test_trend_and_fleet_judge_a_monitors_windows_by_the_monitors_rules(four_windows: Path,
                                                                        capsys: pytest.CaptureFixture[str]) -> None:
    """The monitor ran with --baseline-windows 2: acq trend and acq fleet take its baseline (the mean of the first two
    windows) unless told otherwise, and say whose rules they judged by (the trial: trend's own default, the first
    window, alarmed five windows before the monitor did)."""
    rows = _rows(four_windows)
    monitors = (rows[0]["K_Nm_per_rad"] + rows[1]["K_Nm_per_rad"]) / 2
    trend = run_cli(capsys, "trend", str(four_windows), "--joint", "joint1", "--json")
    doc = json.loads(trend.out)
    assert doc["baseline_K_Nm_per_rad"] == pytest.approx(monitors, rel=1e-9)
    assert (doc["baseline"], doc["rules"]) == ("mean of the first 2 good sessions", "as acq monitor judged its windows")
    assert (doc["threshold_pct"], doc["ewma_lambda"]) == (10.0, 0.2)
    fleet = json.loads(run_cli(capsys, "fleet", str(four_windows), "--json").out)
    assert [(j["baseline_K_Nm_per_rad"], j["rules"]) for j in fleet] == [(pytest.approx(monitors, rel=1e-9),
                                                                          "as acq monitor judged its windows")]
    mine = json.loads(run_cli(capsys, "trend", str(four_windows), "--joint", "joint1", "--json",
                              "--baseline-sessions", "1").out)
    assert mine["baseline_K_Nm_per_rad"] == pytest.approx(rows[0]["K_Nm_per_rad"], rel=1e-9)
    assert mine["rules"] == "--baseline-sessions from the command line, the rest as acq monitor judged its windows"


def test_retention_keeps_the_baseline_and_the_last_windows_and_every_catalogue_row(four_windows: Path) -> None:
    rows = _rows(four_windows)
    present = [Path(r["path"]).exists() for r in rows]
    assert present == [True, True, False, True]  # baseline 0, 1; window 2 deleted; the last (3) kept
    assert not Path(rows[2]["path"]).with_suffix(".result.json").exists()
    assert len(list(four_windows.glob("*.h5"))) == 3


def test_restart_resumes_numbering_and_marks_an_interrupted_window(four_windows: Path, tmp_path: Path) -> None:
    out = tmp_path / "resumed"
    _restarted_elsewhere(four_windows, out)
    bench = _bench(seed=EXCITING_SEED)
    # a window whose capture was cut (the monitor killed): status stays "recording"
    writer = SessionWriter(out / "cut.h5", bench=bench, profile=None,
                           current_info=CurrentSourceInfo(rate_hz=25600.0, channels=("i_a",), device="sim-daq"),
                           drive_info=DriveInfo(period_s=0.001, counts_per_rev=131072, transport="sim",
                                                timestamp_kind="drive_cycle", device="sim-drive"),
                           host_ns_at_start=0, tags={"monitor_window": 4, "monitor_elapsed_s": 240.0})
    writer._file.close()  # as a kill -9 leaves it (the kernel drops its lock: acq.recording.live)
    writer._marker.close()
    with pytest.raises(SystemExit) as exc:
        from acq.ui.cli import main

        main(["monitor", "--bench", str(_bench_file(tmp_path, seed=EXCITING_SEED)), "--fast", "--for", "1m",
              "--baseline-windows", "2", "--keep", "1", "--out", str(out)])
    assert exc.value.code == 0
    rows = _rows(out)
    assert [r["window"] for r in rows] == [0, 1, 2, 3, 4, 5]
    assert rows[4]["verdict"] == "interrupted" and rows[4]["K_Nm_per_rad"] is None
    assert "stopped during this window's capture" in rows[4]["reasons_json"]
    assert [r["K_Nm_per_rad"] for r in rows[:4]] == [r["K_Nm_per_rad"] for r in _rows(four_windows)]
    assert not (out / "cut.h5").exists()  # marked, then its raw file went (not baseline, not the last)


def _fifth_window_recorded(four_windows: Path, out: Path) -> RecordingResult:
    """The four windows' folder copied to ``out`` (:func:`_restarted_elsewhere`) with a fifth window, 10 s of the
    robot recorded there by the real recorder as the monitor tags it; its :class:`RecordingResult`."""
    _restarted_elsewhere(four_windows, out)
    bench = _bench(seed=EXCITING_SEED)
    current, drive = open_bench(bench, fast=True)
    return Recorder(bench, None, current, drive, out, 10.0,
                    tags={"monitor_window": 4, "monitor_elapsed_s": 240.0}).run()


def test_a_window_the_analysis_refuses_as_damaged_keeps_its_raw_file(four_windows: Path, tmp_path: Path) -> None:
    """A window found on a restart (recorded by the real recorder, 10 s of the robot) whose cycle index chunk of rows
    2 000–2 499 the storage zeroed: its analysis refuses it as damaged, the catalogue row holds why and no K. Before:
    filed "failed", then deleted by --keep 1 as an analysed window (not baseline, not the last), its raw file the
    only copy of what it recorded; now kept, and --keep still keeps the last window with a K."""
    out = tmp_path / "resumed"
    result = _fifth_window_recorded(four_windows, out)
    assert result.status == "complete"
    with h5py.File(result.path, "r") as f:
        info = f["encoder/index"].id.get_chunk_info_by_coord((2000,))
    with result.path.open("r+b") as fh:  # zero bytes, data and checksum, as storage that lost them leaves them
        fh.seek(info.byte_offset)
        fh.write(bytes(info.size))
    assert load(result.path).damage == ("encoder: samples 2 000–2 499 zeroed on disk",)
    with pytest.raises(SystemExit) as exc:
        from acq.ui.cli import main

        main(["monitor", "--bench", str(_bench_file(tmp_path, seed=EXCITING_SEED)), "--fast", "--for", "1m",
              "--baseline-windows", "2", "--keep", "1", "--out", str(out)])
    assert exc.value.code == 0
    db = sqlite3.connect(out / "catalogue.sqlite")
    (error, k), = db.execute("SELECT a.error, a.K_Nm_per_rad FROM sessions s JOIN analyses a USING (session_key) "
                             "WHERE s.path = ?", (str(result.path.resolve()),)).fetchall()
    db.close()
    assert k is None and error == (f"{result.path.resolve()}: damaged (encoder: samples 2 000–2 499 zeroed on disk) "
                                   "— run acq check, or use --partial to analyse the intact part")
    rows = _rows(out)
    assert [r["window"] for r in rows] == [0, 1, 2, 3, 4, 5]
    assert [(out / Path(r["path"]).name).exists() for r in rows] == [True, True, False, False, True, True]


def test_a_window_killed_during_its_capture_and_found_damaged_keeps_its_raw_file(
        four_windows: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A window whose capture the monitor was killed in (its footer unwritten: status ``recording``, no counts) and
    whose encoder chunk of rows 2 000–2 499 the storage zeroed: found on the restart, not repaired (damaged), filed
    interrupted. Before: --keep 1 then deleted its raw file as any done window (kept only when an analysis had
    refused it): the evidence of the damage and the only copy of what it recorded gone. Now kept, and counted in the
    status line ("1 damaged kept")."""
    out = tmp_path / "resumed"
    result = _fifth_window_recorded(four_windows, out)
    with h5py.File(result.path, "r+") as f:  # the footer as a kill -9 leaves it: never written
        f.attrs.modify("status", np.array(b"recording", dtype=f.attrs.get_id("status").dtype))
        for name in ("current_samples", "encoder_samples"):
            f.attrs.modify(name, np.int64(-1))
        info = f["encoder/index"].id.get_chunk_info_by_coord((2000,))
    with result.path.open("r+b") as fh:  # zero bytes, data and checksum, as storage that lost them leaves them
        fh.seek(info.byte_offset)
        fh.write(bytes(info.size))
    killed = load(result.path)
    assert (killed.status, killed.damage) == ("recording", ("encoder: samples 2 000–2 499 zeroed on disk",))
    run = run_cli(capsys, "monitor", "--bench", str(_bench_file(tmp_path, seed=EXCITING_SEED)), "--fast", "--for",
                  "1m", "--baseline-windows", "2", "--keep", "1", "--out", str(out))
    assert run.code == 0, run.err
    rows = _rows(out)
    assert [(r["window"], r["verdict"]) for r in rows][4:] == [(4, "interrupted"), (5, "ok")]
    assert [(out / Path(r["path"]).name).exists() for r in rows] == [True, True, False, False, True, True]
    (done,) = [ln for ln in run.err.splitlines() if ln.endswith(" — done")]
    assert ", 1 damaged kept, " in done


def test_a_restart_with_other_alarm_rules_is_refused(four_windows: Path, tmp_path: Path,
                                                    capsys: pytest.CaptureFixture[str]) -> None:
    """The second trial: a restart with --baseline-windows 5 --threshold-pct 20 re-baselined on the windows already
    judged (the alarming ones in it) and cleared the alarm, saying nothing."""
    out = tmp_path / "other_rules"
    _restarted_elsewhere(four_windows, out)
    run = run_cli(capsys, "monitor", "--bench", str(_bench_file(tmp_path, seed=EXCITING_SEED)), "--fast", "--for",
                  "1m", "--baseline-windows", "5", "--threshold-pct", "20", "--out", str(out))
    assert (run.code, run.err) == (2, f"acq: error: {out}: its windows were judged with --baseline-windows 2 "
                                      "--threshold-pct 10 --ewma-lambda 0.2: resume with the same, or start a new "
                                      "--out\n")
    assert sorted(r["window"] for r in _rows(out)) == [0, 1, 2, 3] and not (out / "monitor.lock").exists()


def test_a_window_of_a_paused_robot_is_not_excited_and_has_no_K(capsys: pytest.CaptureFixture[str],
                                                                  tmp_path: Path) -> None:
    bench = _bench_file(tmp_path, robot_idle_fraction=1.0)
    run = run_cli(capsys, "monitor", "--bench", str(bench), "--fast", "--for", "1m", "--out", str(tmp_path / "m"))
    assert run.code == 0
    (row,) = _rows(tmp_path / "m")
    assert row["verdict"] == "not excited" and row["K_Nm_per_rad"] is None
    idle = ("the joint travelled 0 counts, less than half an electrical revolution (16384 counts): the machine did "
            "not move it in this window")
    assert json.loads(row["reasons_json"]) == [idle]
    # acq analyze of the window gives the monitor's own result (the trial: exit 2, "the motor never turns half an
    # electrical revolution within 20 ms"), and a batch over the folder counts it analysed, not failed
    (window,) = (tmp_path / "m").glob("*.h5")
    run = run_cli(capsys, "analyze", str(window), "--json", "--no-report")
    assert run.code == 0, run.err
    assert json.loads(run.out)["quality"] == {"verdict": "not excited", "reasons": [idle]}
    assert not window.with_suffix(".report.png").exists()
    window.with_suffix(".result.json").unlink()
    run = run_cli(capsys, "analyze", str(tmp_path / "m"), "--json", "--no-report", "--catalogue",
                  str(tmp_path / "batch.sqlite"))
    assert run.code == 0, run.err
    assert json.loads(run.out) == [{"path": str(window), "outcome": "analysed", "K_Nm_per_rad": None,
                                    "verdict": "not excited", "error": None}]
    # damaged: the travel of the readable part says nothing of the rows lost, and the reason says so (the second read)
    from tests.test_integrity import _flip_a_byte_in_chunk

    damaged = tmp_path / "damaged.h5"
    shutil.copyfile(window, damaged)
    first, rows = _flip_a_byte_in_chunk(damaged, 1, "encoder/position_counts")
    run = run_cli(capsys, "analyze", str(damaged), "--json", "--no-report", "--partial")
    assert run.code == 0, run.err
    reasons = json.loads(run.out)["quality"]["reasons"]
    assert reasons[-1] == (f"the joint travelled 0 counts, less than half an electrical revolution (16384 counts): the "
                           f"machine did not move it in this window's readable part ({(10000 - rows) * 0.001:.1f} s; "
                           f"encoder: samples {first:_}–{first + rows - 1:_} unreadable)".replace("_", " "))


def test_on_alarm_runs_with_the_documented_environment_and_exit_code_3(capsys: pytest.CaptureFixture[str],
                                                                       tmp_path: Path,
                                                                       monkeypatch: pytest.MonkeyPatch) -> None:
    """The command gets the user's environment and the ACQ_ variables: not the BLAS threads acq set for its
    workers (it had them, and the allocator's MALLOC_* variables), and a BLAS setting of the user's as it was."""
    # K falls 5 % per simulated minute: windows at 0, 1, 2, 3 min have K −0, −5, −10, −15 %
    bench = _bench_file(tmp_path, K_decay_pct_per_hour=300.0, seed=EXCITING_SEED)
    env_file = tmp_path / "alarm.env"
    monkeypatch.setenv("OPENBLAS_NUM_THREADS", "3")
    for name in ("OMP_NUM_THREADS", "MKL_NUM_THREADS"):
        monkeypatch.delenv(name, raising=False)
    users = dict(os.environ)
    run = run_cli(capsys, "monitor", "--bench", str(bench), "--fast", "--for", "4m", "--baseline-windows", "2",
                  "--keep", "0", "--out", str(tmp_path / "m"),
                  "--on-alarm", f"env -0 > {env_file}")  # a shell's redirection: the command runs through sh -c
    assert run.code == 3
    seen = dict(item.split("=", 1) for item in env_file.read_text().split("\0") if item)
    env = {name: value for name, value in seen.items() if name.startswith("ACQ_")}
    assert set(env) == {"ACQ_JOINT", "ACQ_K", "ACQ_BASELINE_K", "ACQ_CHANGE_PCT", "ACQ_SESSION", "ACQ_WINDOW"}
    assert {name: value for name, value in seen.items() if name not in env and name not in ("PWD", "SHLVL", "_")} \
        == {name: value for name, value in users.items() if name not in ("PWD", "SHLVL", "_")}
    assert seen["OPENBLAS_NUM_THREADS"] == "3"
    rows = _rows(tmp_path / "m")
    alarming = next(r for r in rows if r["path"] == env["ACQ_SESSION"])
    assert env["ACQ_WINDOW"] == str(alarming["window"] + 1)  # numbered from 1, as the status lines and acq trend
    assert env["ACQ_JOINT"] == "joint1" and float(env["ACQ_K"]) == pytest.approx(alarming["K_Nm_per_rad"], rel=1e-5)
    baseline = (rows[0]["K_Nm_per_rad"] + rows[1]["K_Nm_per_rad"]) / 2
    assert float(env["ACQ_BASELINE_K"]) == pytest.approx(baseline, rel=1e-5)
    assert Path(env["ACQ_SESSION"]).exists()  # an alarming window's raw file is kept even with --keep 0
    assert "ALARM" in run.err


def test_on_alarm_runs_through_the_shell_and_its_failure_is_reported(capsys: pytest.CaptureFixture[str],
                                                                      tmp_path: Path,
                                                                      monkeypatch: pytest.MonkeyPatch) -> None:
    """docs/monitoring.md's own example: the shell expands $ACQ_K (it printed "K $ACQ_K" literally, run without a
    shell), and a command that fails (here: not found, exit 127) is said in the status line and the final summary (it
    said nothing)."""
    bench = _bench_file(tmp_path, K_decay_pct_per_hour=300.0, seed=EXCITING_SEED)
    monkeypatch.setenv("COLUMNS", "200")  # the final table unwrapped
    said = tmp_path / "said.txt"
    run = run_cli(capsys, "monitor", "--bench", str(bench), "--fast", "--for", "4m", "--baseline-windows", "2",
                  "--keep", "0", "--out", str(tmp_path / "m"), "--on-alarm",
                  f'echo "joint $ACQ_JOINT: K $ACQ_K (baseline $ACQ_BASELINE_K)" | tee {said} && acq-no-such-notifier')
    assert run.code == 3
    rows = _rows(tmp_path / "m")
    baseline = (rows[0]["K_Nm_per_rad"] + rows[1]["K_Nm_per_rad"]) / 2
    assert said.read_text() == f"joint joint1: K {rows[3]['K_Nm_per_rad']:.6g} (baseline {baseline:.6g})\n"
    failure = ("alarm command failed: exit 127 (command not found): echo \"joint $ACQ_JOINT: K $ACQ_K (baseline "
               f"$ACQ_BASELINE_K)\" | tee {said} && acq-no-such-notifier")
    status_lines = [line for line in run.err.splitlines() if " filed = " in line]
    assert any(line.endswith(f" — {failure}") for line in status_lines)  # the status line when it failed
    summary = " ".join(run.err.split())  # the final table: the failure beside "alarms raised"
    assert "alarms raised │ 1 · alarm command failed: exit 127 (command not found) │" in summary


def test_a_joint_that_stays_in_alarm_keeps_the_raw_window_that_raised_it_not_every_one(
        capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    """Every alarming window used to be kept: a joint in alarm for a weekend grew the folder by each window (under
    --max-disk its capture stopped once the budget was full). Kept now: the baseline and the window that raised the
    alarm; the catalogue keeps every window's K."""
    # K falls 5 % per simulated minute: windows at 0 … 5 min have K −0 … −25 %
    bench = _bench_file(tmp_path, K_decay_pct_per_hour=300.0, seed=EXCITING_SEED)
    run = run_cli(capsys, "monitor", "--bench", str(bench), "--fast", "--for", "6m", "--baseline-windows", "2",
                  "--keep", "0", "--out", str(tmp_path / "m"))
    assert run.code == 3
    rows = _rows(tmp_path / "m")
    assert [r["window"] for r in rows] == [0, 1, 2, 3, 4, 5]
    trend = json.loads(run_cli(capsys, "trend", str(tmp_path / "m"), "--joint", "joint1", "--json").out)
    states = [p["state"] for p in trend["points"]]
    assert [p["window"] for p in trend["points"]] == [1, 2, 3, 4, 5, 6]  # as the table and the alarm line number them
    first_alarm = states.index("alarm")
    # a window the robot's program leaves unexcited is skipped (no K): it neither ends nor restarts the alarm
    assert states[:2] == ["baseline", "baseline"] and set(states[first_alarm:]) <= {"alarm", "skipped"}
    assert states.count("alarm") >= 2
    kept = [Path(r["path"]).exists() for r in rows]
    assert kept == [w in (0, 1, first_alarm) for w in range(6)]
    assert sorted(p.name for p in (tmp_path / "m").glob("*.h5")) == sorted(
        Path(rows[w]["path"]).name for w in (0, 1, first_alarm))


def test_a_restart_in_alarm_does_not_announce_the_same_alarm_again(capsys: pytest.CaptureFixture[str],
                                                                   tmp_path: Path) -> None:
    """The third trial: after a restart the monitor forgot it was in alarm, ran --on-alarm again for the same episode
    and counted it as a new alarm."""
    # K falls 5 % per simulated minute: windows at 0 … 5 min have K −0 … −25 %
    bench = _bench_file(tmp_path, K_decay_pct_per_hour=300.0, seed=EXCITING_SEED)
    said = tmp_path / "said.txt"
    args = ["monitor", "--bench", str(bench), "--fast", "--baseline-windows", "2", "--keep", "0",
            "--out", str(tmp_path / "m"), "--on-alarm", f"echo $ACQ_SESSION >> {said}"]
    first = run_cli(capsys, *args, "--for", "4m")
    assert first.code == 3 and len(said.read_text().splitlines()) == 1
    again = run_cli(capsys, *args, "--for", "2m")
    assert again.code == 3  # still in alarm
    rows = _rows(tmp_path / "m")
    assert [r["window"] for r in rows] == [0, 1, 2, 3, 4, 5]
    trend = json.loads(run_cli(capsys, "trend", str(tmp_path / "m"), "--joint", "joint1", "--json").out)
    assert [p["state"] for p in trend["points"]][-1] == "alarm"
    assert len(said.read_text().splitlines()) == 1  # announced once, when it was raised
    assert "alarms raised │ 0" in " ".join(again.err.split())


def test_retention_rules() -> None:
    windows = [WindowFiles(i, Path(f"w{i}.h5"), done=i < 5, protected=i in (0, 3)) for i in range(6)]
    assert [w.index for w in to_delete(windows, keep=2)] == [1, 2]  # 0, 3 protected; 4, 5 the last two
    assert [w.index for w in to_delete(windows, keep=0)] == [1, 2, 4]  # 5 is not analysed yet


def test_disk_budget_frees_the_oldest_unprotected_windows_or_refuses(tmp_path: Path) -> None:
    windows = []
    for i in range(4):
        path = tmp_path / f"w{i}.h5"
        path.write_bytes(b"x" * 1000)
        windows.append(WindowFiles(i, path, done=True, protected=i == 0))
    victims, fits = make_room(windows, tmp_path, need_bytes=1500, budget_bytes=4000)
    assert fits and [w.index for w in victims] == [1, 2]
    victims, fits = make_room(windows, tmp_path, need_bytes=3500, budget_bytes=4000)
    assert not fits  # even without 1, 2, 3 the protected window 0 leaves no room


def test_a_window_refused_as_damaged_never_goes_for_keep_and_goes_last_for_the_budget(tmp_path: Path) -> None:
    """Retention's docstring: a window the analysis refused as damaged is not deleted for --keep nor counted among the
    last --keep; the budget takes it only after every other unprotected window of this monitor."""
    windows = []
    for i in range(5):
        path = tmp_path / f"w{i}.h5"
        path.write_bytes(b"x" * 1000)
        windows.append(WindowFiles(i, path, done=True, protected=i == 0, key=path.stem, refused=i in (1, 4)))
    assert [w.key for w in to_delete(windows, keep=1)] == ["w2"]  # 3 the last with a K; 1, 4 refused
    victims, fits = make_room(windows, tmp_path, need_bytes=2000, budget_bytes=5000)
    assert fits and [w.key for w in victims] == ["w2", "w3"]
    victims, fits = make_room(windows, tmp_path, need_bytes=3000, budget_bytes=5000)
    assert fits and [w.key for w in victims] == ["w2", "w3", "w1"]
    victims, fits = make_room(windows, tmp_path, need_bytes=4500, budget_bytes=5000)
    assert not fits  # the baseline window 0 stays


def test_windows_of_another_monitor_copied_here_go_first_for_the_budget_and_never_for_keep(tmp_path: Path) -> None:
    """Retention's docstring: copies of another monitor's windows are none of this monitor's last --keep (and without
    a budget are left alone), and those that monitor does not keep go before any of its own windows when the budget
    needs room; those it keeps (its baseline, its alarms) are never deleted."""
    windows = []
    for i, copied in ((0, False), (1, False), (6, True), (7, True), (8, True)):
        path = tmp_path / f"w{i}{'c' if copied else ''}.h5"
        path.write_bytes(b"x" * 1000)
        # window 0 this monitor's baseline, the copy of window 6 the other's (the second read: it was deleted)
        windows.append(WindowFiles(i, path, done=True, protected=i in (0, 6), key=path.stem, copied=copied))
    assert [w.key for w in to_delete(windows, keep=1)] == []  # window 1 is the last of its own, 0 protected
    victims, fits = make_room(windows, tmp_path, need_bytes=2000, budget_bytes=5000)
    assert fits and [w.key for w in victims] == ["w7c", "w8c"]
    victims, fits = make_room(windows, tmp_path, need_bytes=3000, budget_bytes=5000)
    assert fits and [w.key for w in victims] == ["w7c", "w8c", "w1"]
    victims, fits = make_room(windows, tmp_path, need_bytes=3000, budget_bytes=4999)
    assert not fits  # the protected copy stays, as this monitor's baseline does


def test_a_disk_budget_that_cannot_hold_one_window_is_refused_before_anything_is_captured(
        capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    """It ran on, capturing nothing ("not captured: the disk budget would be exceeded" every window), exit 0; and a
    budget below the baseline's windows and one more skipped every window after the first (the second trial)."""
    from acq.monitoring.monitor import Monitor, MonitorSettings

    out = tmp_path / "monitor"
    run = run_cli(capsys, "monitor", "--bench", str(ROBOT), "--fast", "--for", "1m", "--max-disk", "6MB",
                  "--out", str(out))
    assert (run.code, run.err) == (2, "acq: error: --max-disk 6 MB: the 5 baseline windows acq keeps and the next "
                                      "one, 10 s each, need 23.3 MB (3.9 MB a window: current 25600 Hz × 1 "
                                      "channel(s), encoder 1000 Hz, with the files' overhead) — raise --max-disk, "
                                      "shorten --window or lower --baseline-windows\n")
    assert not out.exists() or not list(out.glob("*.h5"))
    # the size named is the one the capture loop asks room for: 6 × 3.872 MB is enough, a byte less is not
    settings = MonitorSettings(bench=_bench(), out_dir=out, window_s=10.0, every_s=60.0, max_disk_bytes=23_300_000)
    with pytest.raises(ConfigError, match="need 23.3 MB"):
        Monitor(replace(settings, max_disk_bytes=6 * 3_872_000 - 1))
    Monitor(replace(settings, max_disk_bytes=6 * 3_872_000))
    Monitor(replace(settings, baseline_windows=1, max_disk_bytes=2 * 3_872_000))


def test_sizes_parse_and_a_bad_one_is_named() -> None:
    assert parse_size("2GB") == 2_000_000_000 and parse_size("1.5MiB") == 1_572_864
    with pytest.raises(ValueError, match="'2 parsecs' is not a size"):
        parse_size("2 parsecs")


def test_a_stop_request_ends_the_monitor_after_the_window_under_way(tmp_path: Path) -> None:
    from acq.monitoring.monitor import Monitor, MonitorSettings

    settings = MonitorSettings(bench=_bench(seed=EXCITING_SEED), out_dir=tmp_path, window_s=10.0, every_s=60.0,
                               for_s=3600.0, fast=True, baseline_windows=2)

    def stop_after_first(status: object) -> None:
        if monitor.status.captured == 1:
            monitor.request_stop("interrupted by user (Ctrl-C)")

    monitor = Monitor(settings, on_status=stop_after_first)
    assert monitor.run() == 130 and monitor.stopped_by == "interrupted by user (Ctrl-C)"
    rows = _rows(tmp_path)
    assert [r["window"] for r in rows] == [0]  # analysed before ending; no second window captured
    assert monitor.status.message == "stopped: interrupted by user (Ctrl-C)"
    # one good window of the two the baseline needs: its K is shown while the baseline is learned
    assert rows[0]["verdict"] == "ok" and monitor.status.state == "learning baseline"
    assert monitor.status.last_K == rows[0]["K_Nm_per_rad"] and monitor.status.change_pct is None


def test_the_status_counts_every_window_filed_once_and_they_add_up_to_the_catalogue(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The new-user trial: after Ctrl-C "captured 26 / 19 / 26" and "not excited · skipped · interrupted 7 · 0 · 1"
    while the catalogue held 27 windows. Here a Ctrl-C as the third window's capture starts: 2 ok + 1 interrupted."""
    from rich.console import Console

    from acq.monitoring.monitor import Monitor, MonitorSettings
    from acq.ui.monitor_cli import status_table

    capture = Recorder.run

    def ctrl_c_at_the_third(recorder: Recorder) -> object:
        if monitor.status.captured == 2:
            monitor.request_stop("interrupted by user (Ctrl-C)")
        return capture(recorder)

    monkeypatch.setattr(Recorder, "run", ctrl_c_at_the_third)
    settings = MonitorSettings(bench=_bench(seed=EXCITING_SEED), out_dir=tmp_path, window_s=10.0, every_s=60.0,
                               for_s=3600.0, fast=True, baseline_windows=2)
    monitor = Monitor(settings)
    assert monitor.run() == 130
    rows, st = _rows(tmp_path), monitor.status
    assert [r["verdict"] for r in rows] == ["ok", "ok", "interrupted"]
    assert st.filed == {"ok": 2, "poor or failed": 0, "not excited": 0, "skipped": 0, "analysis failed": 0,
                        "interrupted": 1, "write failed": 0}
    assert st.filed_total == sum(st.filed.values()) == len(rows) == 3
    assert (st.captured, st.analysed) == (2, 2)  # the interrupted one is filed, not captured whole nor analysed
    console = Console(width=120, record=True)
    console.print(status_table(st))
    assert "│ windows filed (this run) │ 3 = 2 ok + 1 interrupted │" in [
        " ".join(line.split()) for line in console.export_text().splitlines()]


def test_a_ctrl_c_while_a_complete_window_is_shut_down_still_ends_the_monitor(tmp_path: Path,
                                                                            monkeypatch: pytest.MonkeyPatch) -> None:
    """The flaky hang: a Ctrl-C the recorder's handler took once both streams were complete (while it shut the window
    down) left the window complete and the monitor capturing on (1 run of 30, SIGINT 0.1…10 s in). Here a real SIGINT
    arrives at that moment of every window."""
    from acq.monitoring.monitor import Monitor, MonitorSettings

    shut_down = Recorder._shut_down

    def ctrl_c_then_shut_down(recorder: Recorder, *args: object) -> object:
        os.kill(os.getpid(), signal.SIGINT)  # handled in this (the main) thread before the next line
        return shut_down(recorder, *args)

    monkeypatch.setattr(Recorder, "_shut_down", ctrl_c_then_shut_down)
    settings = MonitorSettings(bench=_bench(seed=EXCITING_SEED), out_dir=tmp_path, window_s=10.0, every_s=60.0,
                               for_s=180.0, fast=True, baseline_windows=2)
    monitor = Monitor(settings)
    assert monitor.run() == 130 and monitor.stopped_by == "interrupted by user (Ctrl-C)"
    rows = _rows(tmp_path)  # the window was complete: captured and analysed, and no other captured
    assert [(r["window"], r["verdict"]) for r in rows] == [(0, "ok")]
    assert monitor.status.captured == monitor.status.analysed == 1


def test_ctrl_c_ends_the_monitor_with_exit_130_and_one_line_of_what_it_kept(tmp_path: Path) -> None:
    """README's exit codes: 130 interrupted (the monitor exited 0); the windows catalogued stay, a restart resumes."""
    out = tmp_path / "monitor"
    proc = subprocess.Popen([sys.executable, "-m", "acq", "monitor", "--bench", str(ROBOT), "--fast", "--window", "2",
                             "--every", "5", "--out", str(out)], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, start_new_session=True)
    deadline = time.monotonic() + 120
    while proc.poll() is None and time.monotonic() < deadline and not (
            (out / "catalogue.sqlite").exists() and _rows_or_none(out)):
        time.sleep(0.1)
    assert proc.poll() is None, proc.communicate()
    os.killpg(proc.pid, signal.SIGINT)  # the terminal's Ctrl-C: to the monitor and its analysis workers
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 130, err
    assert "Traceback" not in err and "Error" not in err, err
    rows = _rows(out)
    assert len(rows) >= 1
    windows = "window" if len(rows) == 1 else "windows"  # "1 windows captured" (the new-user trial)
    # every window the catalogue holds counted once, under its verdict ("captured 26" of 27 in the new-user trial)
    counts = collections.Counter(r["verdict"] for r in rows)
    names = {"ok": "ok", "poor": "poor or failed", "failed": "poor or failed", "not excited": "not excited",
             "interrupted": "interrupted"}
    parts = collections.Counter()
    for verdict, n in counts.items():
        parts[names[verdict]] += n
    kinds = ("ok", "poor or failed", "not excited", "skipped", "analysis failed", "interrupted")
    said = " + ".join(f"{parts[k]} {k}" for k in kinds if parts[k])
    assert err.splitlines()[-1] == (f"acq: interrupted by user (Ctrl-C): {len(rows)} {windows} filed ({said}), all "
                                    f"kept in {out / 'catalogue.sqlite'} (trend state: learning baseline); the same "
                                    "command resumes")
    assert not (out / "monitor.lock").exists()  # released and removed on Ctrl-C too


def _processes_of_session(sid: int) -> dict[int, int]:
    """The live processes (not zombies) of session ``sid``: pid → parent pid, from /proc."""
    found = {}
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()  # after "pid (comm)": state ppid pgrp session …
        except (OSError, IndexError):
            continue  # ended meanwhile
        if int(fields[3]) == sid and fields[0] != "Z":
            found[int(stat.parent.name)] = int(fields[1])
    return found


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")
def test_kill_9_of_the_monitor_ends_its_workers_forkserver_and_resource_tracker(tmp_path: Path) -> None:
    """The trial: after kill -9 of acq monitor its analysis worker, the forkserver and the resource tracker lived on
    (re-parented to PID 1, ≈ 270 MB per killed monitor). Now the worker ends with the monitor, and the rest after."""
    proc = subprocess.Popen([sys.executable, "-m", "acq", "monitor", "--bench", str(ROBOT), "--fast", "--window", "2",
                             "--every", "5", "--out", str(tmp_path / "monitor")], stdout=subprocess.DEVNULL,
                            stderr=subprocess.PIPE, text=True, start_new_session=True)
    try:
        deadline = time.monotonic() + 120
        while proc.poll() is None and time.monotonic() < deadline:
            processes = _processes_of_session(proc.pid)
            workers = [pid for pid, ppid in processes.items() if ppid != proc.pid and pid != proc.pid]
            if workers:  # a child of the forkserver: an analysis worker
                break
            time.sleep(0.1)
        assert proc.poll() is None, proc.communicate()
        assert workers and len(processes) >= 4, processes  # monitor, resource tracker, forkserver, worker(s)
        proc.kill()
        proc.wait()
        deadline = time.monotonic() + 5.0
        while _processes_of_session(proc.pid) and time.monotonic() < deadline:
            time.sleep(0.05)
        assert _processes_of_session(proc.pid) == {}
    finally:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(proc.pid, signal.SIGKILL)
        proc.communicate()


def _rows_or_none(folder: Path) -> list[dict[str, object]] | None:
    try:
        return _rows(folder)
    except sqlite3.OperationalError:  # the catalogue's tables not made yet
        return None


def test_low_coherence_is_not_excited_only_when_the_clocks_are_aligned() -> None:
    from acq.offline.excitation_judge import not_excited

    weak = {"verdict": "failed", "mean_coherence": 0.2, "excitation_coherence": 0.1}
    assert not_excited({"quality": weak, "clock": {"residual_s": 20e-6}})
    assert not not_excited({"quality": weak, "clock": {"residual_s": 3e-3}})  # misaligned: the analysis' verdict
    assert not not_excited({"quality": weak, "clock": {"residual_s": None, "failure": "clock: no alignment found"}})
    assert not not_excited({"quality": {**weak, "verdict": "ok"}, "clock": {"residual_s": 20e-6}})
    strong = {"verdict": "poor", "mean_coherence": 0.9, "excitation_coherence": 0.95}
    assert not not_excited({"quality": strong, "clock": {"residual_s": 20e-6}})  # poor for another reason


def test_a_window_whose_segments_do_not_excite_is_not_excited_whatever_its_clock_residual() -> None:
    """The analysis' segment selection decides first: fewer than two segments that excite (selection not applied)."""
    from acq.offline.excitation_judge import not_excited

    strong = {"verdict": "failed", "mean_coherence": 0.9, "excitation_coherence": 0.95}
    still = {"excited_fraction": 0.0, "selection_applied": False}
    moving = {"excited_fraction": 0.8, "selection_applied": True}
    assert not_excited({"quality": strong, "clock": {"residual_s": 1.75e-3}, "excitation": still})
    assert not not_excited({"quality": strong, "clock": {"residual_s": 1.75e-3}, "excitation": moving})
    assert not not_excited({"quality": strong, "clock": {"failure": "clock: no alignment found"}, "excitation": still})
    assert not not_excited({"quality": {**strong, "verdict": "ok"}, "clock": {}, "excitation": still})


def test_a_window_the_joint_barely_moved_in_is_not_excited_and_not_counted_as_excited(
        capsys: pytest.CaptureFixture[str], tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The shipped seed 0 at 0 and 12 min: too few segments excite in either. The window at 12 min came out `failed`
    with K 31 084 N·m/rad (truth 891) and the advice "remove interference at its source (PWM ripple…)", and was
    counted excited: its clock residual (1753 µs, little motion to align on) kept it from `not excited`. The reasons
    and the log line say how many Welch segments the analysis examined and why too few excite (they said nothing of
    the segments): the analysis' own figures (its result's excitation), 1 of 38 above the F limit in each."""
    monkeypatch.setenv("COLUMNS", "120")
    run = run_cli(capsys, "monitor", "--bench", str(ROBOT), "--fast", "--every", "12m", "--for", "13m",
                  "--out", str(tmp_path / "m"))
    assert run.code == 0
    rows = _rows(tmp_path / "m")
    assert [(r["verdict"], r["K_Nm_per_rad"]) for r in rows] == [("not excited", None)] * 2
    # session 13: the drift the host stamps give (37 ppm, truth 40) replaced the angle stage's 168 ± 95 ppm: the
    # window at 12 min reads as with the simulator's true clock (1 of 38 segments, 3 % of the window)
    segments = "1 of 38 Welch segments excites — in-band S/N above 1.33, chance's 99 % point; the selection needs 2"
    reasons = json.loads(rows[1]["reasons_json"])
    assert [r for r in reasons if not r.startswith("note: ")] == [
        "0 of the window's 12 moves put torque into 10…400 Hz beyond chance; time that does: 3 % of the window",
        segments, "clock alignment residual 1775 µs exceeds 1000 µs for an amplitude fit"]
    notes = reasons[3:]  # the analysis' notes follow its reasons
    assert all(n.startswith("note: ") for n in notes) and "note: using 0.065–9.972 s, where both streams have data" \
        in notes, notes
    assert json.loads(rows[0]["reasons_json"])[1] == ("1 of 38 Welch segments excites — in-band S/N above 1.33, "
                                                      "chance's 99 % point; the selection needs 2")
    excitation = json.loads(rows[1]["excitation_json"])
    assert (excitation["segments"], excitation["segments_excited"], excitation["segments_needed"]) == (38, 1, 2)
    assert excitation["snr_limit"] == pytest.approx(1.33, abs=0.005)
    log = " ".join(run.err.split())
    assert (f"12.2 min: 2 filed = 2 not excited, last window not excited (0 of the window's 12 moves put torque into "
            f"10…400 Hz beyond chance; time that does: 3 % of the window; {segments}), last K —") in log
    assert "windows filed (this run) │ 2 = 2 not excited │" in log
    trend = run_cli(capsys, "trend", str(tmp_path / "m"), "--joint", "joint1")
    assert "31084" not in trend.out and "PWM" not in trend.out


@pytest.fixture(scope="module")
def repeating_window(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The first window of the shipped sim_robot bench (seed 0): moves so alike that the phase of i_a matches the
    encoder's angle at wrong relations stretched by percents (the clock fit once took offset −0.609 s and drift
    −31 730 ppm, truth +0.037 s and +40 ppm, and the window was catalogued "not excited")."""
    from acq.ui.cli import main

    out = tmp_path_factory.mktemp("repeating")
    with pytest.raises(SystemExit) as exc:
        main(["monitor", "--bench", str(ROBOT), "--fast", "--for", "1m", "--keep", "1", "--out", str(out)])
    assert exc.value.code == 0
    return out


def test_a_clock_fit_of_implausible_drift_is_rejected_and_the_host_stamps_align_the_window(
        repeating_window: Path) -> None:
    from acq.offline.analyze import recording_from_session
    from analysis.fit import Z95
    from analysis.stream_spans import spans_and_clock

    (row,) = _rows(repeating_window)
    clock = spans_and_clock(recording_from_session(load(row["path"]))).clock
    assert clock.method == "angle" and not clock.failure
    assert abs(clock.offset_s - 0.037) < 1e-3  # the truth, not a wrong lag 0.6 s away
    assert abs(clock.drift_ppm - 40.0) <= Z95 * clock.drift_std_ppm  # −28 ± 227 ppm (95 %): few fast moves
    rejected = [n for n in clock.notes if n.startswith("clock: rejected a fit of the electrical angle")]
    assert len(rejected) == 1 and "beyond the ±200 ppm two crystal clocks can differ" in rejected[0]
    drift = float(rejected[0].split("drift of ")[1].split(" ±")[0].replace(" ", ""))
    assert abs(drift) > 1000.0
    # aligned, the window is honestly not excited: its moves put no torque into the band
    assert row["verdict"] == "not excited" and row["K_Nm_per_rad"] is None
    assert "moves put torque into 10…400 Hz beyond chance; time that does: " in json.loads(row["reasons_json"])[0]


def test_without_shared_host_stamps_the_window_fails_on_its_clock_and_is_not_called_not_excited(
        repeating_window: Path) -> None:
    from dataclasses import replace

    from acq.offline.excitation_judge import not_excited
    from acq.offline.analyze import recording_from_session
    from analysis import AnalysisRequest, analyze

    (row,) = _rows(repeating_window)
    rec = replace(recording_from_session(load(row["path"])), host_clock_shared=False)  # as two separate tools
    doc = analyze(rec, AnalysisRequest(select_segments=True)).to_json_dict()
    failure = doc["clock"]["failure"]
    assert failure.startswith("clock: no alignment found — the phase of the current against the encoder's angle fits")
    assert "beyond the ±200 ppm two crystal clocks can differ" in failure
    assert abs(float(failure.split("drift of ")[1].split(" ±")[0].replace(" ", ""))) > 1000.0
    assert doc["quality"]["verdict"] == "failed" and doc["quality"]["reasons"][0] == failure
    assert doc["clock"]["residual_s"] is None
    assert not not_excited(doc)  # the clock failed, not the motion


def test_each_window_says_which_share_and_which_moves_excite_the_joint(four_windows: Path) -> None:
    db = sqlite3.connect(four_windows / "catalogue.sqlite")
    rows = [json.loads(r[0]) for r in db.execute("SELECT excitation_json FROM analyses")]
    db.close()
    assert len(rows) == 4
    for exc in rows:  # the monitor asks for segment selection: every analysed window reports it
        assert 0 < exc["excited_fraction"] <= 1 and exc["excited_fraction"] == exc["segments_used"] / exc["segments"]
        assert exc["moves"] and any(m["excited"] for m in exc["moves"])
        starts = [m["start_s"] for m in exc["moves"]]
        assert starts == sorted(starts) and all(0 <= t < 10 for t in starts)  # moves inside the 10 s window


def test_the_status_table_shows_the_excited_share_and_the_moves() -> None:
    from rich.console import Console

    from acq.monitoring.monitor import MonitorStatus
    from acq.ui.monitor_cli import status_table

    moves = ({"index": 0, "start_s": 0.45, "duration_s": 0.3, "peak_rad_s": 125.66, "excited": True},
             {"index": 1, "start_s": 2.0, "duration_s": 1.4, "peak_rad_s": 4.19, "excited": False})
    st = MonitorStatus("joint1", last_excited_fraction=0.12, last_moves=moves, excited_fraction_sum=0.9,
                       excitation_judged=3)
    console = Console(width=120, record=True)
    console.print(status_table(st))
    text = console.export_text()
    assert "excited share: last window · all windows" in text and "12 % · 30 %" in text
    assert "moves of the last window: 1 of 2 excite" in text
    assert "1200" in text and "40" in text and "yes" in text  # peak speeds in rpm



def test_a_window_filed_not_excited_reads_not_excited_with_why_not_its_excited_share() -> None:
    """The new user's log: "excited 87 % of the last window" for a window filed "not excited" (its moves excite 87 % of
    it, its coherence between f_a and f_r is 0.66): the line and the table say the verdict and why."""
    from rich.console import Console

    from acq.monitoring.catalogue import Outcome
    from acq.monitoring.monitor import MonitorStatus
    from acq.offline.excitation_judge import judged
    from acq.ui.monitor_cli import status_line, status_table

    moves = [{"index": i, "start_s": 0.8 * i, "duration_s": 0.7, "peak_rad_s": 100.0, "excited": i < 10}
             for i in range(12)]
    analysed = {"K_Nm_per_rad": 950.0, "clock": {"residual_s": 20e-6}, "options": {"band_hz": [10.0, 400.0]},
                "session": {"tags": {"monitor_window": 3}},
                "quality": {"verdict": "poor", "mean_coherence": 0.8, "excitation_coherence": 0.66,
                            "reasons": ["coherence 0.66 between f_a 55 Hz and f_r 102 Hz", "note: using 0.06–9.97 s"]},
                "excitation": {"excited_fraction": 0.87, "selection_applied": True, "moves": moves}}
    filed = judged(analysed)  # as the monitor files it
    assert filed["quality"]["verdict"] == "not excited"
    st = MonitorStatus("joint1", machine_time_s=40.0)
    st.count(Outcome("w.h5", "0", "{}", {}, filed, None, 1.0))
    why = ("10 of the window's 12 moves put torque into 10…400 Hz beyond chance; time that does: 87 % of the window, "
           "but too little between f_a and f_r (coherence 0.66, below 0.7)")
    assert status_line(st) == (f"40 s: 1 filed = 1 not excited, last window not excited ({why}), last K —, ΔK — %, "
                               "starting, 0.0 MB")
    console = Console(width=240, record=True)  # the reason on one line
    console.print(status_table(st))
    assert re.search(rf"│ the last window is filed not excited +│ +{re.escape(why)} │", console.export_text())
    # a window filed ok after it: its excited share, as before
    ok = {**analysed, "quality": {**analysed["quality"], "verdict": "ok", "excitation_coherence": 0.9}}
    st.count(Outcome("w2.h5", "1", "{}", {}, ok, None, 1.0))
    assert ", excited 87 % of the last window, last K" in status_line(st) and "not excited (" not in status_line(st)


def test_machine_time_reads_in_seconds_minutes_or_hours() -> None:
    """A 10 s run showed "machine time 0.00 h"."""
    from rich.console import Console

    from acq.monitoring.monitor import MonitorStatus
    from acq.ui.monitor_cli import status_table
    from acq.ui.values import duration_text

    assert [duration_text(t) for t in (0.0, 10.0, 119.0, 150.0, 3599.0, 3600.0, 5400.0, 8 * 3600.0)] == [
        "0 s", "10 s", "119 s", "2.5 min", "60.0 min", "1.00 h", "1.50 h", "8.00 h"]
    console = Console(width=120, record=True)
    console.print(status_table(MonitorStatus("joint1", machine_time_s=10.0)))
    assert [[cell.strip() for cell in line.split("│")[1:3]] for line in console.export_text().splitlines()
            if "machine time" in line] == [["machine time", "10 s"]]


def test_a_short_monitor_says_its_machine_time_in_seconds_and_leaves_no_lock(
        capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    """One 10 s window: every line said "0.00 h", and `monitor.lock` stayed in the folder after the monitor ended."""
    out = tmp_path / "monitor"
    run = run_cli(capsys, "monitor", "--bench", str(ROBOT), "--fast", "--window", "10", "--every", "10", "--for", "10s",
                  "--out", str(out))
    assert run.code == 0, run.err
    lines = [line for line in run.err.splitlines() if " filed" in line and line[0].isdigit()]
    assert lines and all(line.startswith("10 s: ") for line in lines), lines
    assert lines[-1].startswith("10 s: 1 filed = 1 "), lines
    assert [[cell.strip() for cell in line.split("│")[1:3]] for line in run.err.splitlines()
            if "machine time" in line] == [["machine time", "10 s"]]
    assert sorted(p.name for p in out.iterdir() if not p.name.endswith((".h5", ".json"))) == [
        "catalogue.sqlite", "monitor.id"]  # no monitor.lock; the identity stays (a restart is the same monitor)


def test_the_folder_lock_is_removed_on_error_and_never_held_by_two_monitors(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The lock file is removed while it is still locked; a monitor that opened it just before (and locks it just
    after the first let it go) must not run beside a third that made the file anew."""
    import acq.monitoring.folder_lock as folder_lock

    with pytest.raises(RuntimeError), folder_lock.folder_lock(tmp_path):
        with pytest.raises(ConfigError, match=f"^{tmp_path}: another acq monitor is writing there$"), \
                folder_lock.folder_lock(tmp_path):
            pass
        raise RuntimeError("the monitor fails")
    assert list(tmp_path.iterdir()) == []

    first = folder_lock.folder_lock(tmp_path)
    first.__enter__()
    real_open, opened = os.open, []

    def open_then_the_first_ends(*args: object, **kwargs: object) -> int:
        fd = real_open(*args, **kwargs)  # type: ignore[arg-type]
        opened.append(fd)
        if len(opened) == 1:
            first.__exit__(None, None, None)  # removes the file this second monitor has just opened, unlocks it
        return fd

    with monkeypatch.context() as m:
        m.setattr(folder_lock.os, "open", open_then_the_first_ends)
        second = folder_lock.folder_lock(tmp_path)
        second.__enter__()
    assert len(opened) == 2  # it locked the removed file, let it go and took the one at the path
    with pytest.raises(ConfigError, match="another acq monitor is writing there"), folder_lock.folder_lock(tmp_path):
        pass
    second.__exit__(None, None, None)
    assert list(tmp_path.iterdir()) == []


def test_the_payload_tag_is_catalogued_and_changes_the_truth_only_with_robot_payload_inertia(
        four_windows: Path, tmp_path: Path) -> None:
    def truth_and_payload(rows: list[dict[str, object]]) -> list[tuple[float, float]]:
        return [(json.loads(str(r["truth_json"]))["Jl_kgm2"], json.loads(str(r["tags_json"]))["payload_kg"]) for r in rows]

    off = truth_and_payload(_rows(four_windows))  # default: the payload changes the gravity load only
    assert [jl for jl, _ in off] == [0.00748] * 4 and len({p for _, p in off}) > 1
    from acq.ui.cli import main

    bench = _bench_file(tmp_path, seed=EXCITING_SEED, robot_payload_inertia="true")
    with pytest.raises(SystemExit) as exc:
        main(["monitor", "--bench", str(bench), "--fast", "--every", "60", "--for", "2m", "--out", str(tmp_path / "m")])
    assert exc.value.code == 0
    rows = _rows(tmp_path / "m")
    on = truth_and_payload(rows)
    tip_m, ratio = 2 * 0.375, 10.0  # the payload is a point mass at the arm's tip, twice the centre of mass's distance
    assert [jl for jl, _ in on] == [pytest.approx(0.00748 + p * (tip_m / ratio) ** 2, rel=1e-12) for _, p in on]
    assert [p for _, p in on] == [p for _, p in off[:2]]  # the same program cycles, the same payloads
    assert on[1][0] > 2.0 * on[0][0]  # window 1 carries 1.8 kg: J_l more than doubles
    db = sqlite3.connect(tmp_path / "m" / "catalogue.sqlite")
    ((verdict, jl, lo, hi),) = db.execute("SELECT verdict, Jl_kgm2, Jl_lo, Jl_hi FROM analyses a JOIN sessions s USING "
                                          "(session_key) WHERE s.tags_json LIKE '%\"monitor_window\": 0%'").fetchall()
    db.close()
    assert verdict == "ok" and lo <= on[0][0] <= hi and jl == pytest.approx(on[0][0], rel=0.02)


def test_a_window_whose_moves_excite_the_band_says_which_coherence_was_too_low() -> None:
    from acq.offline.excitation_judge import _but

    between = {"quality": {"excitation_coherence": 0.61, "mean_coherence": 0.9}}
    band = {"quality": {"excitation_coherence": 0.95, "mean_coherence": 0.5}}
    assert _but(between, 14) == ", but too little between f_a and f_r (coherence 0.61, below 0.7)"
    assert _but(band, 3) == ", but too little over the band (mean coherence 0.50, below 0.72)"
    assert _but(between, 0) == ""  # no move excites: the count says it all
    at_the_limit = {"quality": {"excitation_coherence": 0.95, "mean_coherence": 0.7184}}  # not "0.72, below 0.72"
    assert _but(at_the_limit, 3) == ", but too little over the band (mean coherence 0.718, below 0.72)"


def test_a_window_judged_not_excited_after_its_analysis_keeps_no_K_beside_it(tmp_path: Path,
                                                                            monkeypatch: pytest.MonkeyPatch) -> None:
    """Seed 0's first 10 s: the robot barely excites the joint, the analysis fails on coherence and the monitor
    catalogues `not excited` without numbers; the `.result.json` beside the window says the same (it showed the
    failed fit's K 12 707 N·m/rad)."""
    from acq.monitoring.window_judge import analyse_window
    from acq.offline.analyze import sha256_of
    from acq.recording.recorder import Recorder
    from analysis import AnalysisRequest
    from drivers.registry import open_bench
    from drivers.sim.bench import SimBench

    bench = _bench(seed=0)
    current, drive = open_bench(bench, fast=True, sim_bench=SimBench(bench, realtime=False))
    path = Recorder(bench, None, current, drive, tmp_path, 10.0).run().path
    written: list[Path] = []
    write = acq.offline.analyze.write_text_atomically

    def counted(target: Path | str, text: str) -> None:
        written.append(Path(target))
        write(target, text)

    monkeypatch.setattr(acq.offline.analyze, "write_text_atomically", counted)
    outcome = analyse_window(str(path), sha256_of(path), AnalysisRequest())
    beside = json.loads(path.with_name(path.stem + ".result.json").read_text())
    assert outcome.doc["quality"]["verdict"] == beside["quality"]["verdict"] == "not excited"
    assert "K_Nm_per_rad" not in beside and beside == outcome.doc
    assert written == [path.with_name(path.stem + ".result.json")]  # once, as judged: never the refused K first


def test_a_passive_record_of_a_joint_at_rest_is_not_excited_in_acq_analyze_too(tmp_path: Path) -> None:
    """The second trial: acq record / acq analyze of a robot's first 10 s (seed 0: the joint barely moves) read K
    +468 % with "interference on the phase current … PWM ripple" where the monitor said "not excited". acq analyze
    now judges it as the monitor judges a window (acq.offline.excitation_judge): not excited, no K, no hardware advice."""
    from acq.offline.analyze import analyze_session

    bench = _bench()
    current, drive = open_bench(bench, fast=True)
    path = Recorder(bench, None, current, drive, tmp_path, 10.0).run().path
    done = analyze_session(path, write=False, report=False)
    quality = done.json_dict["quality"]
    assert quality["verdict"] == "not excited" and done.result is None and "K_Nm_per_rad" not in done.json_dict
    assert re.fullmatch(r"0 of the record's 12 moves put torque into 10…400 Hz beyond chance; time that "
                        r"does: \d+ % of the record", quality["reasons"][0])
    assert quality["reasons"][1] == ("1 of 38 Welch segments excites — in-band S/N above 1.33, chance's 99 % point; "
                                     "the selection needs 2")
    assert not any("interference" in r or "ripple" in r or "play" in r for r in quality["reasons"])


def test_alarm_commands_run_in_a_session_of_their_own_and_share_one_wait_at_the_end(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The review: the Ctrl-C that stops the monitor reached its alarm commands (same process group), and N slow
    commands held the exit N × 30 s. Two commands still running: one shared wait, both said, both left running."""
    import acq.monitoring.alarm_command as alarm_module
    from acq.monitoring.catalogue import Entry
    from acq.monitoring.monitor import Monitor, MonitorSettings
    from acq.monitoring.trend import Trend

    monkeypatch.setattr(alarm_module, "ALARM_WAIT_S", 0.6)
    sid_file = tmp_path / "sid"
    # written under another name and renamed: the test waits for the name, which then has its whole content (a file
    # opened for writing exists before its text is in it: CI once read it empty)
    command = (f"{sys.executable} -c 'import os; f = open(\"{sid_file}.tmp\", \"w\"); f.write(str(os.getsid(0))); "
               f"f.close(); os.replace(\"{sid_file}.tmp\", \"{sid_file}\")'; sleep 5")
    m = Monitor(MonitorSettings(bench=_bench(), out_dir=tmp_path, window_s=10.0, every_s=60.0, on_alarm=command))
    entry = Entry("k", "k", str(tmp_path / "w.h5"), "joint1", None, {}, "ok", [], None, 700.0, (690.0, 710.0), None,
                  None, "{}", "2026-11-30T00:00:00+00:00", None)
    trend = Trend("joint1", [], 890.0, "first good session", 2.0, 10.0, 0.2)
    for _ in range(2):
        m._alarm.raise_alarm(entry, trend)
    started = list(m._alarms._running)
    try:
        deadline = time.monotonic() + 3.0
        while not sid_file.exists() and time.monotonic() < deadline:
            time.sleep(0.02)
        assert int(sid_file.read_text()) != os.getsid(0)  # not the monitor's session: a Ctrl-C does not reach it
        start = time.monotonic()
        m._alarms.reap(wait=True)
        assert time.monotonic() - start < 1.0  # one 0.6 s wait for both, not 0.6 s each
        assert m.status.alarm_command_failure.startswith(
            "alarm command still running after 0.6 s when the monitor ended (pid ")
        assert "failed" not in m.status.alarm_command_failure and "failed" not in m.status.message
    finally:
        for proc in started:  # left running by the monitor, as a mail mid-send would be; not by the test
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()


def test_a_restart_with_another_bench_or_window_is_refused_but_not_another_simulated_machine(
        four_windows: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The new-user trial: README's (now docs/monitoring.md's) CANopen monitor, then its serial one, in the same
    default folder — one series of windows from two measurement chains, no notice; a changed --window was accepted
    too. Another [sim] truth or seed (a simulated wear series: the machine, not the measurement) resumes."""
    out = tmp_path / "other_bench"
    _restarted_elsewhere(four_windows, out)
    same = _bench_file(tmp_path, seed=EXCITING_SEED)
    geared = tmp_path / "geared.toml"
    geared.write_text(same.read_text().replace("ratio = 10.0", "ratio = 12.5"))
    other_joint = tmp_path / "joint2.toml"
    other_joint.write_text(same.read_text().replace('joint = "joint1"', 'joint = "joint2"'))
    cases = [(["--bench", str(same), "--window", "5"], "--window 10, now 5"),
             (["--bench", str(geared)], "[gear] ratio 10, now 12.5"),
             (["--bench", str(other_joint)], "joint joint1, now joint2")]
    for options, why in cases:
        run = run_cli(capsys, "monitor", *options, "--fast", "--for", "1m", "--baseline-windows", "2", "--out", str(out))
        assert (run.code, run.err) == (2, f"acq: error: {out}: its windows were captured with another bench or window "
                                          f"({why}): their K is not comparable — start a new --out (or resume with the "
                                          "same bench and --window)\n")
    assert sorted(r["window"] for r in _rows(out)) == [0, 1, 2, 3]
    worn = tmp_path / "worn"
    worn.mkdir()
    run = run_cli(capsys, "monitor", "--bench", str(_bench_file(worn, seed=7, K_Nm_per_rad=850.0)), "--fast", "--for",
                  "1m", "--baseline-windows", "2", "--keep", "1", "--out", str(out))
    assert run.code == 0, run.err
    assert [r["window"] for r in _rows(out)] == [0, 1, 2, 3, 4]


def test_a_folder_filed_before_the_bench_tags_resumes(four_windows: Path, tmp_path: Path,
                                                      capsys: pytest.CaptureFixture[str]) -> None:
    """A missing bench tag is unknown, not a refusal: the folders of earlier monitors resume (with --window 5 here,
    which the tags would have refused)."""
    from acq.monitoring.window_bench import FACT_TAGS

    out = tmp_path / "old"
    _restarted_elsewhere(four_windows, out)
    db = sqlite3.connect(out / "catalogue.sqlite")
    for key, tags in db.execute("SELECT session_key, tags_json FROM sessions").fetchall():
        old = {k: v for k, v in json.loads(tags).items() if k not in FACT_TAGS}
        db.execute("UPDATE sessions SET tags_json = ? WHERE session_key = ?", (json.dumps(old), key))
    db.commit()
    db.close()
    run = run_cli(capsys, "monitor", "--bench", str(_bench_file(tmp_path, seed=EXCITING_SEED)), "--window", "5",
                  "--fast", "--for", "1m", "--baseline-windows", "2", "--keep", "1", "--out", str(out))
    assert run.code == 0, run.err
    assert [r["window"] for r in _rows(out)] == [0, 1, 2, 3, 4]


def test_a_restart_says_both_counts_and_goes_on_from_the_resumed_machine_time(
        four_windows: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """After a restart the summary counted only this run's windows while the trend had all, and the first status line
    said "0 s" of machine time, then jumped to 5 min."""
    out = tmp_path / "resumed"
    _restarted_elsewhere(four_windows, out)
    run = run_cli(capsys, "monitor", "--bench", str(_bench_file(tmp_path, seed=EXCITING_SEED)), "--fast", "--for",
                  "2m", "--baseline-windows", "2", "--keep", "1", "--out", str(out))
    assert run.code == 0, run.err
    lines = [line for line in run.err.splitlines() if " filed" in line and line[0].isdigit()]
    assert lines[0].startswith("3.2 min: 0 filed in this run (4 in the folder), "), lines
    assert lines[-1].startswith("5.2 min: 2 filed in this run (6 in the folder) = 2 ok, "), lines
    table = " ".join(run.err.split())
    assert "windows filed (this run) │ 2 = 2 ok │" in table
    assert "windows in the folder (earlier runs too) │ 6 │" in table


def test_windows_not_captured_for_the_disk_budget_are_in_the_summary(tmp_path: Path) -> None:
    """They were counted nowhere: "not excited · skipped · interrupted" 0 · 0 · 0 while 4 windows were missing. The
    baseline window and the one that raised the alarm are kept (protected) and fill a budget of two windows."""
    from rich.console import Console

    from acq.monitoring.monitor import Monitor, MonitorSettings
    from acq.ui.monitor_cli import status_table

    settings = MonitorSettings(bench=_bench(seed=EXCITING_SEED, K_decay_pct_per_hour=300.0), out_dir=tmp_path,
                               window_s=10.0, every_s=60.0, for_s=360.0, fast=True, baseline_windows=1,
                               max_disk_bytes=2 * 3_872_000)
    monitor = Monitor(settings)
    assert monitor.run() == 3
    st = monitor.status
    assert (st.captured, st.not_captured, st.skipped, st.in_folder) == (2, 4, 0, 2)
    console = Console(width=120, record=True)
    console.print(status_table(st))
    assert [" ".join(line.split()) for line in console.export_text().splitlines() if "not captured" in line] == [
        "│ not captured: the disk budget (--max-disk) was full │ 4 │"]


def test_status_shows_the_latest_K_in_alarm_and_which_window_it_is_from(capsys: pytest.CaptureFixture[str],
                                                                        tmp_path: Path) -> None:
    """Every line after the alarm repeated "ALARM: K <the K that raised it>" while K fell on; and "K 889.8" beside
    "excited 0 % of the last window" was an earlier window's K without saying so."""
    bench = _bench_file(tmp_path, K_decay_pct_per_hour=300.0, seed=EXCITING_SEED)
    run = run_cli(capsys, "monitor", "--bench", str(bench), "--fast", "--for", "6m", "--baseline-windows", "2",
                  "--keep", "0", "--out", str(tmp_path / "m"))
    assert run.code == 3
    rows = {r["window"] + 1: r["K_Nm_per_rad"] for r in _rows(tmp_path / "m")}  # shown from 1, filed from 0
    alarms = [line for line in run.err.splitlines() if "— ALARM: K" in line]
    assert len(alarms) >= 2
    for line in alarms:
        k, n = re.search(r"ALARM: K ([0-9.]+) N·m/rad in window (\d+) ", line).groups()  # type: ignore[union-attr]
        assert float(k) == pytest.approx(rows[int(n)], abs=0.05)
        assert f", last K {k} (window {n}), " in line
    assert len({re.search(r"ALARM: K ([0-9.]+)", line).group(1) for line in alarms}) >= 2  # type: ignore[union-attr]


def test_max_disk_needs_a_unit(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    """--max-disk 2 was 2 bytes."""
    with pytest.raises(ValueError, match="'2' has no unit"):
        parse_size("2")
    assert parse_size("123B") == 123
    run = run_cli(capsys, "monitor", "--bench", str(ROBOT), "--fast", "--for", "1m", "--max-disk", "2", "--out",
                  str(tmp_path / "m"))
    assert (run.code, run.err) == (2, "acq: error: --max-disk 2: '2' has no unit — give one of B, kB, MB, GB, TB, "
                                      "KiB, MiB, GiB, TiB (e.g. 2GB)\n")


def test_a_monitor_whose_devices_fail_to_open_leaves_no_catalogue(capsys: pytest.CaptureFixture[str],
                                                                  tmp_path: Path) -> None:
    """An empty catalogue.sqlite was left in --out when the bench's devices could not be opened."""
    canopen = ROBOT.parent / "sim_robot_canopen.toml"
    bench = tmp_path / "no_bus.toml"
    bench.write_text(canopen.read_text().replace('interface = "virtual"', 'interface = "socketcan"')
                     .replace('channel = "acq-sim-robot"', 'channel = "acq-no-such-bus"')
                     .replace("simulated_node = true", "simulated_node = false"))
    out = tmp_path / "m"
    run = run_cli(capsys, "monitor", "--bench", str(bench), "--for", "10s", "--window", "4", "--every", "5",
                  "--out", str(out))
    assert run.code != 0 and "acq-no-such-bus" in run.err, run.err
    assert not (out / "catalogue.sqlite").exists()
    # a --catalogue other monitors share (they may start together and write to it meanwhile) is never removed
    shared = tmp_path / "plant.sqlite"
    run = run_cli(capsys, "monitor", "--bench", str(bench), "--for", "10s", "--window", "4", "--every", "5",
                  "--out", str(tmp_path / "m2"), "--catalogue", str(shared))
    assert run.code != 0 and shared.exists()


def test_readmes_two_monitor_benches_differ_in_their_drive_and_not_in_their_simulated_machine() -> None:
    """docs/monitoring.md's CANopen example, then its serial one, in the default folder: one series from two
    measurement chains. What the refusal names, from the benches shipped (the [sim] sections, which differ in nothing
    that counts, are not compared)."""
    from acq.monitoring.catalogue import Entry
    from acq.monitoring.window_bench import differences, window_facts

    benches = ROBOT.parent
    canopen, serial = (load_bench(benches / f"sim_robot_{t}.toml") for t in ("canopen", "serial"))
    filed = [Entry("k", "k", "w.h5", "joint1", None, {"monitor_window": 0, **window_facts(canopen, 4.0)}, "ok", [],
                   None, 890.0, (880.0, 900.0), None, None, "{}", "2026-11-30T00:00:00+00:00", None)]
    assert differences(filed, serial, 4.0) == ["[drive] driver canopen, now serial"]
    assert differences(filed, serial, 5.0) == ["--window 4, now 5", "[drive] driver canopen, now serial"]
    worn = canopen.model_copy(update={"sim": canopen.sim.model_copy(update={"K_Nm_per_rad": 700.0, "seed": 9})})
    assert differences(filed, worn, 4.0) == []


def test_the_status_table_says_an_unstable_baseline_and_which_window_the_last_K_is_from() -> None:
    """The monitor showed state "ok" under a baseline learned on a softening joint, and a K of an earlier window beside
    the last window's share without saying so."""
    from rich.console import Console

    from acq.monitoring.monitor import MonitorStatus
    from acq.ui.monitor_cli import status_table

    warning = "baseline unstable: its 5 sessions scatter 12.6 % while each is known to within ±0.6 %"
    st = MonitorStatus("joint1", last_K=889.8, last_K_ci=(880.0, 899.6), last_K_window=3, baseline_warning=warning,
                       message="done")
    console = Console(width=140, record=True)
    console.print(status_table(st))
    text = " ".join(console.export_text().split())
    assert "last K N·m/rad (95 %) · its window │ 889.8 (880.0 … 899.6) · window 3 │" in text
    assert f"{warning} done" in text  # the caption: the warning, then the message
