"""Several acq monitors filing into one catalogue (SQLite and PostgreSQL): two robots whose joints share the name
``joint1`` stay two histories — each monitor's trend, baseline, rules and resume see only its own windows."""

from __future__ import annotations

import json
import shutil
import socket
import sqlite3
import subprocess
import sys
from pathlib import Path

import pytest

from acq.monitoring import monitor_scope
from acq.monitoring.catalogue import Catalogue, Outcome
from tests.conftest import PG_PASSWORD
from tests.helpers import CliRun, run_cli
from tests.pg_server import new_database

ROBOT = Path(__file__).resolve().parents[1] / "configs" / "benches" / "sim_robot.toml"
#: The robot program of this seed excites the joint in the windows at 0, 1, 2 min (test_monitor's EXCITING_SEED).
SEED = 5


def _robot(folder: Path, name: str, k_nm_per_rad: float) -> Path:
    """sim_robot.toml with the exciting seed and the simulated joint's true K (the [sim] section's, not [nominal])."""
    text = ROBOT.read_text().replace("seed = 0 ", f"seed = {SEED} ")
    head, sim = text.split("[sim]")
    path = folder / f"{name}.toml"
    path.write_text(head + "[sim]" + sim.replace("K_Nm_per_rad = 891.0", f"K_Nm_per_rad = {k_nm_per_rad}", 1))
    return path


def _monitor(capsys: pytest.CaptureFixture[str], bench: Path, out: Path, catalogue: Path | str, robot: str,
             minutes: int, baseline: int) -> None:
    run = run_cli(capsys, "monitor", "--bench", str(bench), "--fast", "--window", "10", "--every", "60", "--for",
                  f"{minutes}m", "--baseline-windows", str(baseline), "--out", str(out), "--catalogue",
                  str(catalogue), "--tag", f"robot={robot}")
    assert run.code == 0, run.err


def _windows(doc: dict[str, object]) -> list[tuple[int, str, str]]:
    return [(int(p["tags"]["monitor_window"]), p["tags"]["robot"], p["tags"]["monitor_id"])  # type: ignore[index]
            for p in doc["points"]]  # type: ignore[union-attr]


def test_two_monitors_of_one_joint_name_share_a_catalogue_and_stay_apart(catalogue_location: Path | str,
                                                                           tmp_path: Path,
                                                                           capsys: pytest.CaptureFixture[str]) -> None:
    """Robot r1 (true K 891) and r2 (true K 700) both call their joint joint1. Before, one catalogue held one joint
    joint1: baseline of one robot, latest K of the other (the trial: fleet said ok, the folder's trend ALARM)."""
    r1, r2 = _robot(tmp_path, "r1", 891.0), _robot(tmp_path, "r2", 700.0)
    # baselines of all their windows: nothing judged, no alarm to muddle the exit code (the rules are not tested here)
    _monitor(capsys, r1, tmp_path / "r1", catalogue_location, "r1", 2, baseline=3)
    _monitor(capsys, r2, tmp_path / "r2", catalogue_location, "r2", 2, baseline=2)  # other rules: not r1's to refuse
    _monitor(capsys, r1, tmp_path / "r1", catalogue_location, "r1", 1, baseline=3)  # restart: resumes r1's numbering
    ids = {r: json.loads((tmp_path / r / "monitor.id").read_text())["monitor_id"] for r in ("r1", "r2")}
    assert ids["r1"] != ids["r2"] and not (tmp_path / "r1" / "catalogue.sqlite").exists()
    trends = {}
    for robot, truth, windows in (("r1", 891.0, 3), ("r2", 700.0, 2)):
        run = run_cli(capsys, "trend", "--catalogue", str(catalogue_location), "--joint", "joint1", "--tag",
                      f"robot={robot}", "--json")
        doc = trends[robot] = json.loads(run.out)
        assert _windows(doc) == [(n, robot, ids[robot]) for n in range(windows)]
        assert [p["state"] for p in doc["points"]] == ["baseline"] * windows
        assert doc["baseline"] == f"mean of the first {windows} good sessions"  # each monitor's own rules
        ks = [p["K_Nm_per_rad"] for p in doc["points"]]
        assert ks == [pytest.approx(truth, rel=0.03)] * windows
        assert doc["baseline_K_Nm_per_rad"] == pytest.approx(sum(ks) / windows, rel=1e-12)
    mixed = run_cli(capsys, "trend", "--catalogue", str(catalogue_location), "--joint", "joint1")
    assert mixed.code == 2 and (f"joint joint1 has the windows of 2 monitors ({ids['r1']}, {ids['r2']}) — trend one: "
                                "--tag monitor_id=ID or --tag robot=R (r1, r2)") in mixed.err
    png = tmp_path / "r2.png"
    view = run_cli(capsys, "view", "--trend", "joint1", "--catalogue", str(catalogue_location), "--tag", "robot=r2",
                   "--screenshot", str(png))
    assert view.code == 0 and png.read_bytes()[:4] == b"\x89PNG", view.err
    assert run_cli(capsys, "view", "--trend", "joint1", "--catalogue", str(catalogue_location), "--screenshot",
                   str(png)).code == 2  # the two monitors' windows are never drawn as one trend
    fleet = json.loads(run_cli(capsys, "fleet", "--catalogue", str(catalogue_location), "--json").out)
    rows = sorted((j["robot"], j["joint"], j["monitor_id"], j["baseline_K_Nm_per_rad"]) for j in fleet)
    assert rows == [(r, "joint1", ids[r], pytest.approx(trends[r]["baseline_K_Nm_per_rad"], rel=1e-12))
                    for r in ("r1", "r2")]


def test_a_monitor_without_tags_keeps_its_windows_from_before_it_had_an_identity(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A folder of a monitor of an earlier acq: no monitor.id, windows without monitor_id in its own catalogue. A
    restart there adopts them (numbering, rules); the same windows in a catalogue given with --catalogue are not its."""
    bench, out = _robot(tmp_path, "r1", 891.0), tmp_path / "old"
    assert run_cli(capsys, "monitor", "--bench", str(bench), "--fast", "--window", "10", "--every", "60", "--for",
                   "2m", "--baseline-windows", "2", "--out", str(out)).code == 0
    (out / "monitor.id").unlink()
    with sqlite3.connect(out / "catalogue.sqlite") as db:  # as an earlier acq filed them
        for key, tags in db.execute("SELECT session_key, tags_json FROM sessions").fetchall():
            tags = json.loads(tags)
            del tags["monitor_id"]
            db.execute("UPDATE sessions SET tags_json = ? WHERE session_key = ?", (json.dumps(tags), key))
        # schema 5, before the monitor_id column: the restart migrates it (the column from the tags: none here)
        db.executescript("DROP INDEX sessions_monitor; ALTER TABLE sessions DROP COLUMN monitor_id; "
                         "PRAGMA user_version = 5;")
    refused = run_cli(capsys, "monitor", "--bench", str(bench), "--fast", "--window", "10", "--every", "60", "--for",
                      "1m", "--baseline-windows", "3", "--out", str(out))
    assert refused.code == 2 and "its windows were judged with --baseline-windows 2" in refused.err
    assert run_cli(capsys, "monitor", "--bench", str(bench), "--fast", "--window", "10", "--every", "60", "--for",
                   "1m", "--baseline-windows", "2", "--out", str(out)).code == 0
    doc = json.loads(run_cli(capsys, "trend", str(out), "--joint", "joint1", "--json").out)
    assert [p["tags"]["monitor_window"] for p in doc["points"]] == [0, 1, 2]
    assert [("monitor_id" in p["tags"]) for p in doc["points"]] == [False, False, True]


def test_a_monitor_tag_that_the_monitor_files_itself_is_refused(tmp_path: Path,
                                                                capsys: pytest.CaptureFixture[str]) -> None:
    run = run_cli(capsys, "monitor", "--bench", str(ROBOT), "--fast", "--for", "1m", "--out", str(tmp_path / "m"),
                  "--tag", "monitor_window=7")
    assert (run.code, run.err) == (2, "acq: error: --tag monitor_window=…: acq monitor files monitor_window itself "
                                      "with every window — choose another key\n")
    assert not (tmp_path / "m").exists()


def _start(capsys: pytest.CaptureFixture[str], bench: Path, out: Path, *options: str, minutes: int = 1,
           every: str = "60") -> CliRun:
    return run_cli(capsys, "monitor", "--bench", str(bench), "--fast", "--window", "10", "--every", every, "--for",
                   f"{minutes}m", "--baseline-windows", "2", "--out", str(out), *options)


def _identity(folder: Path) -> dict[str, str]:
    return json.loads((folder / "monitor.id").read_text())


def test_a_copied_monitor_folder_is_refused_and_a_moved_one_is_the_same_monitor(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch) -> None:
    """The review: a copied folder carried monitor.id along and two monitors filed their windows as one. Bound to host
    and folder: a copy whose original still holds the identity is refused, a moved folder resumes as the same monitor,
    another host is refused until the engineer says which it is (--moved, --new-identity)."""
    bench, first = _robot(tmp_path, "r1", 891.0), tmp_path / "first"
    assert _start(capsys, bench, first).code == 0
    ident = _identity(first)
    mid = ident["monitor_id"]
    assert (ident["host"], ident["folder"], ident["catalogue"]) == (
        socket.gethostname(), str(first.resolve()), str((first / "catalogue.sqlite").resolve()))
    copy = tmp_path / "copy"
    shutil.copytree(first, copy)
    refused = _start(capsys, bench, copy)
    assert (refused.code, refused.err) == (2, f"acq: error: {copy}: this folder looks copied from {first.resolve()} "
                                              f"(its monitor.id is that monitor's, {mid}): two monitors would file "
                                              "their windows as one — start it with --new-identity if this is another "
                                              "monitor (the windows copied here stay that one's), or in a new --out\n")
    (copy / "monitor.id").write_text(mid + "\n")  # as an earlier acq wrote it: the binding is read from the identity
    assert _start(capsys, bench, copy).err == refused.err
    assert _start(capsys, bench, copy, "--new-identity").code == 0
    new = _identity(copy)["monitor_id"]
    assert new != mid and _identity(copy)["folder"] == str(copy.resolve())
    with sqlite3.connect(copy / "catalogue.sqlite") as db:  # the copied window stays the first monitor's
        rows = sorted((json.loads(t)["monitor_window"], m) for t, m in db.execute("SELECT tags_json, monitor_id "
                                                                                   "FROM sessions"))
    assert rows == sorted([(0, mid), (0, new)])
    assert _start(capsys, bench, copy, "--new-identity").code == 0  # bound here now: the flag changes nothing
    assert _identity(copy)["monitor_id"] == new
    moved = tmp_path / "moved"
    first.rename(moved)
    assert _start(capsys, bench, moved).code == 0  # nothing left where it was: the same monitor, bound anew
    assert (_identity(moved)["monitor_id"], _identity(moved)["folder"]) == (mid, str(moved.resolve()))
    doc = json.loads(run_cli(capsys, "trend", str(moved), "--joint", "joint1", "--json").out)
    assert [(p["tags"]["monitor_window"], p["tags"]["monitor_id"]) for p in doc["points"]] == [(0, mid), (1, mid)]
    carried = tmp_path / "carried"  # copied to another host (a new folder there), nothing left here
    shutil.copytree(moved, carried)
    shutil.rmtree(moved)
    monkeypatch.setattr(socket, "gethostname", lambda: "newpc")
    other_host = _start(capsys, bench, carried)
    assert (other_host.code, other_host.err) == (
        2, f"acq: error: {carried}: its monitor.id was made on host {ident['host']} "
           f"for {moved.resolve()} ({mid}) — a copy would file its windows as that monitor's: start it with "
           "--new-identity if this is another monitor (the windows copied here stay that one's), or with --moved if "
           f"the monitor on {ident['host']} no longer runs (the folder moved here)\n")
    assert _start(capsys, bench, carried, "--moved").code == 0
    assert (_identity(carried)["monitor_id"], _identity(carried)["host"]) == (mid, "newpc")


def test_a_container_restart_with_a_new_host_name_is_the_same_monitor_and_another_machine_is_refused(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch) -> None:
    """The host name changes at every container start (Docker's container id, a pod's name): every restart there
    was refused as another host until --moved, which then switched the host check off (the last closing note). The
    folder's own filesystem object (statvfs f_fsid and the inode), which a container's volume keeps and a copy does not, tells it is
    the same folder; a machine-id other than the one recorded tells another machine, even under the same host name
    and path. The machine-id files are the test's own (the machine's is the machine's)."""
    ids = tmp_path / "machine-id"
    monkeypatch.setattr(monitor_scope, "MACHINE_ID_FILES", (str(ids), str(tmp_path / "dbus-machine-id")))
    ids.write_text("0123456789abcdef0123456789abcdef\n")
    monkeypatch.setattr(socket, "gethostname", lambda: "4f2a9c1d7e3b")  # a container's host name: its id
    bench, out = _robot(tmp_path, "r1", 891.0), tmp_path / "volume" / "m"
    assert _start(capsys, bench, out).code == 0
    mid = _identity(out)["monitor_id"]
    assert (_identity(out)["machine_id"], _identity(out)["folder_object"][1]) == (
        "0123456789abcdef0123456789abcdef", out.stat().st_ino)
    monkeypatch.setattr(socket, "gethostname", lambda: "9b8e7d6c5a41")  # the container made anew on the same volume
    restarted = _start(capsys, bench, out)
    assert restarted.code == 0, restarted.err
    ids.unlink()  # and one whose image has no machine-id
    monkeypatch.setattr(socket, "gethostname", lambda: "monitor-5d8f7-x2k4q")
    assert _start(capsys, bench, out).code == 0
    assert (_identity(out)["monitor_id"], _identity(out)["host"], _identity(out)["machine_id"]) == (
        mid, "monitor-5d8f7-x2k4q", None)
    doc = json.loads(run_cli(capsys, "trend", str(out), "--joint", "joint1", "--json").out)
    assert [(p["tags"]["monitor_window"], p["tags"]["monitor_id"]) for p in doc["points"]] == [
        (0, mid), (1, mid), (2, mid)]
    ids.write_text("0123456789abcdef0123456789abcdef\n")
    assert _start(capsys, bench, out).code == 0  # bound to this machine's id again
    # the folder copied to another machine, to the same path under the same host name (a station cloned file by file)
    shutil.copytree(out, tmp_path / "carried")
    shutil.rmtree(out)
    shutil.copytree(tmp_path / "carried", out)
    ids.write_text("fedcba9876543210fedcba9876543210\n")
    refused = _start(capsys, bench, out)
    assert (refused.code, refused.err) == (
        2, f"acq: error: {out}: its monitor.id was made on host monitor-5d8f7-x2k4q (machine-id "
           "0123456789abcdef0123456789abcdef, this one's fedcba9876543210fedcba9876543210) for "
           f"{out.resolve()} ({mid}) — a copy would file its windows as that monitor's: start it with --new-identity "
           "if this is another monitor (the windows copied here stay that one's), or with --moved if the monitor on "
           "monitor-5d8f7-x2k4q no longer runs (the folder moved here)\n")
    assert _start(capsys, bench, out, "--moved").code == 0
    assert (_identity(out)["monitor_id"], _identity(out)["machine_id"]) == (mid, "fedcba9876543210fedcba9876543210")


def test_windows_copied_from_another_monitor_go_first_when_the_disk_budget_needs_room(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A copied folder started with --new-identity: the windows copied along are the first monitor's, and were never
    deleted, yet counted against --max-disk — with the baseline they filled it, and no window was captured again (the
    last closing note). Those the first monitor does not keep go first when the budget needs room (retention's
    docstring says why), and the summary counts them; their catalogue rows stay. Its baseline and alarm windows are
    never deleted (the second read: they were, and the folder copied away had the only raw files): when they leave no
    room the window is not captured, and the status line says why."""
    from acq.recording.reader import load

    bench, first, copy = _robot(tmp_path, "r1", 891.0), tmp_path / "first", tmp_path / "copy"
    assert _start(capsys, bench, first, minutes=3).code == 0  # windows 0, 1 (the baseline), 2 (ok, one of --keep)
    shutil.copytree(first, copy)
    shutil.rmtree(first)  # the copy's are now the only raw files of the first monitor's windows
    copied = {int(load(p).tags["monitor_window"]): p.name for p in copy.glob("*.h5")}
    assert sorted(copied) == [0, 1, 2]
    # the budget of the 2 baseline copies, this monitor's 2 baseline windows and the next (2.6 MB each as written,
    # 3.9 MB expected): the copy of window 2 goes for this monitor's window 1; then no room is left
    run = _start(capsys, bench, copy, "--new-identity", "--max-disk", "12MB", minutes=4)
    assert run.code == 0, run.err
    summary = {" ".join(cells.split("│")[1].split()): cells.split("│")[2].strip()
               for cells in run.err.splitlines() if cells.count("│") == 3}
    assert summary["windows filed (this run)"].startswith("2 = ")
    assert "2 filed = 2 ok, 2 not captured (disk budget)" in run.err
    assert summary["copies of other monitors' windows deleted"] == "1"
    assert ("not captured: the disk budget would be exceeded — 2 windows of another monitor copied here are its "
            "baseline or alarms, never deleted (raise --max-disk or move them out)") in " ".join(run.err.split())
    assert {n for n, name in copied.items() if (copy / name).exists()} == {0, 1}
    assert sum(f.stat().st_size for f in copy.iterdir() if f.is_file()) <= 12_000_000
    with sqlite3.connect(copy / "catalogue.sqlite") as db:
        counts = sorted(n for (n,) in db.execute("SELECT COUNT(*) FROM sessions GROUP BY monitor_id").fetchall())
    assert counts == [2, 3]


def test_a_restart_into_another_catalogue_is_refused_unless_its_windows_move_there(
        catalogue_location: Path | str, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A restart with another --catalogue started over in an empty one (numbering, baseline, alarm) and left the
    history behind. Refused in one line naming both; --move-catalogue (SQLite to PostgreSQL) copies the windows."""
    bench, out = _robot(tmp_path, "r1", 891.0), tmp_path / "m"
    assert _start(capsys, bench, out, minutes=2).code == 0
    old = (out / "catalogue.sqlite").resolve()
    here = str(catalogue_location) if isinstance(catalogue_location, str) else str(catalogue_location.resolve())
    refused = _start(capsys, bench, out, "--catalogue", str(catalogue_location))
    assert (refused.code, refused.err) == (2, f"acq: error: {out}: its windows are filed in {old}, not in {here} "
                                              f"(--catalogue): resume with --catalogue {old}, or add --move-catalogue "
                                              f"to copy them into {here} and file there from now on\n")
    moved = _start(capsys, bench, out, "--catalogue", str(catalogue_location), "--move-catalogue")
    assert moved.code == 0, moved.err
    assert _identity(out)["catalogue"] == here
    doc = json.loads(run_cli(capsys, "trend", "--catalogue", str(catalogue_location), "--joint", "joint1",
                             "--json").out)
    assert [p["tags"]["monitor_window"] for p in doc["points"]] == [0, 1, 2]
    assert [p["state"] for p in doc["points"]] == ["baseline", "baseline", "ok"]  # the baseline came along
    assert _start(capsys, bench, out, "--catalogue", str(catalogue_location)).code == 0  # bound there now


def test_a_refused_start_with_a_new_catalogue_file_leaves_nothing_behind(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A --catalogue naming a SQLite file not there yet was made (with its folder) before the start was refused, and
    stayed behind empty (the last closing note). Each refusal comes before it is made: windows filed elsewhere,
    a copied folder, windows of another --window (judged where they are filed, before --move-catalogue copies them —
    monitor.id was rewritten to the new catalogue before that refusal)."""
    bench, out, new = _robot(tmp_path, "r1", 891.0), tmp_path / "m", tmp_path / "plant" / "new.sqlite"
    assert _start(capsys, bench, out).code == 0
    identity = (out / "monitor.id").read_text()
    refused = _start(capsys, bench, out, "--catalogue", str(new))
    assert refused.code == 2 and refused.err.startswith(f"acq: error: {out}: its windows are filed in ")
    other_window = run_cli(capsys, "monitor", "--bench", str(bench), "--fast", "--window", "20", "--every", "60",
                           "--for", "1m", "--baseline-windows", "2", "--out", str(out), "--catalogue", str(new),
                           "--move-catalogue")
    assert other_window.code == 2 and "its windows were captured with another bench or window" in other_window.err
    shutil.copytree(out, tmp_path / "copy")
    copied = _start(capsys, bench, tmp_path / "copy", "--catalogue", str(new))
    assert copied.code == 2 and "this folder looks copied from" in copied.err
    assert not (tmp_path / "plant").exists()
    assert (out / "monitor.id").read_text() == identity
    assert _start(capsys, bench, out, "--catalogue", str(new), "--move-catalogue").code == 0  # accepted: made now
    with Catalogue(new) as c:
        assert [e.tags["monitor_window"] for e in c.entries()] == [0, 1]


def test_a_restart_with_another_every_goes_on_in_machine_time_from_the_last_window(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """--every spaces the windows, it changes no K: watching a joint more closely is allowed. Machine time was the
    window's number × --every: windows 0, 1 at 0, 60 s, then 2, 3 at 240, 360 s with --every 120 (the simulated wear
    jumped with it); now it goes on from the last window."""
    bench, out = _robot(tmp_path, "r1", 891.0), tmp_path / "m"
    assert _start(capsys, bench, out, minutes=2).code == 0
    assert _start(capsys, bench, out, minutes=4, every="120").code == 0
    doc = json.loads(run_cli(capsys, "trend", str(out), "--joint", "joint1", "--json").out)
    assert [(p["tags"]["monitor_window"], p["tags"]["monitor_elapsed_s"], p["tags"]["monitor_every_s"])
            for p in doc["points"]] == [(0, 0.0, 60.0), (1, 60.0, 60.0), (2, 120.0, 120.0), (3, 240.0, 120.0)]


def test_a_folder_moved_with_its_catalogue_moves_its_windows_from_there(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A folder moved (``mv a b``) with its own catalogue, then started with --catalogue PLANT --move-catalogue: the
    copy opened the catalogue monitor.id names, a/catalogue.sqlite, which no longer exists — it made the folder a and
    an empty catalogue there, copied no window and filed on in PLANT without the history (the third read). The
    windows come from the catalogue the folder carried; a recorded catalogue that is gone and not in the folder is a
    refusal, and nothing is made where it was."""
    bench, first, moved, plant = _robot(tmp_path, "r1", 891.0), tmp_path / "a", tmp_path / "b", tmp_path / "plant.db"
    assert _start(capsys, bench, first, "--keep", "0", minutes=2).code == 0  # window 2's file is not kept: K only filed
    first.rename(moved)
    run = _start(capsys, bench, moved, "--catalogue", str(plant), "--move-catalogue")
    assert run.code == 0, run.err
    assert not first.exists()
    doc = json.loads(run_cli(capsys, "trend", "--catalogue", str(plant), "--joint", "joint1", "--json").out)
    assert [(p["tags"]["monitor_window"], p["state"]) for p in doc["points"]][:3] == [
        (0, "baseline"), (1, "baseline"), (2, "ok")]
    again = tmp_path / "again"  # moved once more, its catalogue deleted: it starts over there, as one deleted in place
    assert _start(capsys, bench, moved, "--catalogue", str(moved / "catalogue.sqlite")).code == 0  # the one it carries
    moved.rename(again)
    (again / "catalogue.sqlite").unlink()
    restarted = _start(capsys, bench, again)
    assert restarted.code == 0, restarted.err
    assert _identity(again)["catalogue"] == str((again / "catalogue.sqlite").resolve())
    other, gone = tmp_path / "c", tmp_path / "gone.db"
    assert _start(capsys, bench, other, "--catalogue", str(gone)).code == 0
    gone.unlink()
    refused = _start(capsys, bench, other, "--catalogue", str(plant), "--move-catalogue")
    assert (refused.code, refused.err) == (
        2, f"acq: error: {other}: its windows are filed in {gone}, which no longer exists: resume once with "
           f"--catalogue set to where that file is now, then move them with --move-catalogue\n")
    assert not gone.exists()


def test_an_empty_identity_file_is_refused_not_made_anew(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """An empty monitor.id was taken for none: a new identity was made silently — the folder's windows became another
    monitor's (numbering from 0, a new baseline) and a copied folder with its monitor.id emptied passed the copy check
    (the third read). Refused like any unreadable identity."""
    bench, out = _robot(tmp_path, "r1", 891.0), tmp_path / "m"
    assert _start(capsys, bench, out).code == 0
    (out / "monitor.id").write_text("")
    refused = _start(capsys, bench, out)
    assert (refused.code, refused.err) == (
        2, f"acq: error: {out / 'monitor.id'}: not a monitor identity (the file is empty) — restore it from a backup, "
           "or move it away to start a new monitor in this folder\n")
    assert (out / "monitor.id").read_text() == ""


def test_windows_an_earlier_acq_filed_after_the_catalogue_was_migrated_stay_the_monitors(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A shared catalogue migrated to schema 6 by one upgraded monitor while another, of an earlier acq, runs on: that
    one files its windows with the monitor_id tag but no monitor_id column (its INSERT names the columns it knows).
    Restarted upgraded, it read its windows by the column: none of those — the windows still in its folder analysed
    again, the rest gone from its trend, the numbering taken up again from the files (two windows 2; the third
    read). A monitor's start fills the column from the tags."""
    bench, out, shared = _robot(tmp_path, "r1", 891.0), tmp_path / "m", tmp_path / "shared.sqlite"
    assert _start(capsys, bench, out, "--catalogue", str(shared), "--keep", "0", minutes=3).code == 0
    with sqlite3.connect(shared) as db:  # as the earlier acq's INSERT left them
        db.execute("UPDATE sessions SET monitor_id = NULL")
    assert _start(capsys, bench, out, "--catalogue", str(shared)).code == 0
    doc = json.loads(run_cli(capsys, "trend", "--catalogue", str(shared), "--joint", "joint1", "--json").out)
    assert [p["tags"]["monitor_window"] for p in doc["points"]] == [0, 1, 2, 3]
    with sqlite3.connect(shared) as db:
        assert db.execute("SELECT COUNT(*) FROM sessions WHERE monitor_id IS NULL").fetchone()[0] == 0


def test_moved_and_new_identity_together_are_refused(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """--moved (the same monitor) and --new-identity (another one) together: --new-identity won silently, splitting
    the history of a monitor its engineer also called the same (the third read)."""
    bench, out = _robot(tmp_path, "r1", 891.0), tmp_path / "m"
    run = _start(capsys, bench, out, "--moved", "--new-identity")
    assert (run.code, run.err) == (2, "acq: error: --moved and --new-identity: a folder is either the same monitor "
                                      "moved here or another one — give one of them\n")
    assert not out.exists()


def test_a_restart_with_another_every_after_an_earlier_acq_goes_on_at_the_spacing_it_captured_with(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Windows of an earlier acq carry no monitor_every_s: their spacing was taken to be the new --every, and the first
    window after the upgrade's restart with --every 120 came at 60 + 120 = 180 s instead of 120 s (the third read). An
    earlier acq placed window n at n × --every: the spacing is read back from the last window's machine time."""
    bench, out = _robot(tmp_path, "r1", 891.0), tmp_path / "m"
    assert _start(capsys, bench, out, minutes=2).code == 0
    with sqlite3.connect(out / "catalogue.sqlite") as db:  # as the earlier acq filed them
        for key, tags in db.execute("SELECT session_key, tags_json FROM sessions").fetchall():
            db.execute("UPDATE sessions SET tags_json = ? WHERE session_key = ?",
                       (json.dumps({k: v for k, v in json.loads(tags).items() if k != "monitor_every_s"}), key))
    assert _start(capsys, bench, out, minutes=4, every="120").code == 0
    doc = json.loads(run_cli(capsys, "trend", str(out), "--joint", "joint1", "--json").out)
    assert [(p["tags"]["monitor_window"], p["tags"]["monitor_elapsed_s"]) for p in doc["points"]] == [
        (0, 0.0), (1, 60.0), (2, 120.0), (3, 240.0)]


def test_the_same_folder_by_another_path_is_not_a_copy(tmp_path: Path) -> None:
    """The folder reached through a bind mount (a service's path and an engineer's) was refused as a copy of itself —
    and the advice, --new-identity, would have split its history (the third read). Run in a private mount namespace
    (unshare -rm: no mount left behind); skipped where the system allows none."""
    if shutil.which("unshare") is None:
        pytest.skip("no unshare")
    bench, real, alias = _robot(tmp_path, "r1", 891.0), tmp_path / "real", tmp_path / "alias"
    real.mkdir()
    alias.mkdir()
    monitor = [sys.executable, "-m", "acq", "monitor", "--bench", str(bench), "--fast", "--window", "10", "--every",
               "60", "--for", "1m", "--baseline-windows", "2", "--out"]
    first = subprocess.run([*monitor, str(real / "m")], capture_output=True, text=True, timeout=300)
    assert first.returncode == 0, first.stderr
    script = f'mount --bind "{real}" "{alias}" || exit 99; exec "$@"'
    again = subprocess.run(["unshare", "-rm", "sh", "-c", script, "sh", *monitor, str(alias / "m")],
                           capture_output=True, text=True, timeout=300)
    if again.returncode == 99 or "unshare:" in again.stderr:
        pytest.skip(f"no bind mount here: {again.stderr.strip()}")
    assert again.returncode == 0, again.stderr
    identity = json.loads((real / "m" / "monitor.id").read_text())
    assert identity["folder"] == str((alias / "m").resolve())
    with sqlite3.connect(real / "m" / "catalogue.sqlite") as db:
        assert {m for (m,) in db.execute("SELECT monitor_id FROM sessions")} == {identity["monitor_id"]}


def test_a_move_from_a_catalogue_with_a_password_in_its_url_reads_the_password_from_libpq_not_monitor_id(
        postgres_server_with_password: str, tmp_path: Path, capsys: pytest.CaptureFixture[str],
        monkeypatch: pytest.MonkeyPatch) -> None:
    """monitor.id keeps the catalogue's URL with its password masked; --move-catalogue connected with the mask as the
    password and failed with libpq's authentication error (the review). The mask is dropped, so libpq reads the
    password from PGPASSWORD or ~/.pgpass; without either: one line naming the catalogue and the way on, nothing
    copied, monitor.id unchanged. The password is never stored."""
    monkeypatch.delenv("PGPASSWORD", raising=False)
    monkeypatch.setenv("PGPASSFILE", str(tmp_path / "no.pgpass"))  # none of the user's own
    url = new_database(postgres_server_with_password)
    masked = url.replace(f":{PG_PASSWORD}@", ":***@")
    bench, out, plant = _robot(tmp_path, "r1", 891.0), tmp_path / "m", tmp_path / "plant.db"
    first = _start(capsys, bench, out, "--catalogue", url, minutes=2)
    assert first.code == 0, first.err
    identity = (out / "monitor.id").read_text()
    assert _identity(out)["catalogue"] == masked and PG_PASSWORD not in identity
    refused = _start(capsys, bench, out, "--catalogue", str(plant), "--move-catalogue")
    # ours exactly, around libpq's reason (its wording is libpq's: "fe_sendauth: no password supplied" here, another
    # version may say it otherwise, with or without the server's address): one line, no password in it
    head = f"acq: error: {out}: its windows are filed in {masked}: cannot open the catalogue ("
    tail = (") — monitor.id keeps no password: put it in ~/.pgpass or PGPASSWORD (libpq reads them), then restart "
            "with --move-catalogue\n")
    assert refused.code == 2 and refused.err.startswith(head) and refused.err.endswith(tail), refused.err
    reason = refused.err[len(head):-len(tail)]
    assert reason.strip() and "\n" not in reason and PG_PASSWORD not in reason, reason
    assert (out / "monitor.id").read_text() == identity
    assert not plant.exists()  # a refusal leaves nothing: the new catalogue is made only once the start is accepted
    monkeypatch.setenv("PGPASSWORD", PG_PASSWORD)
    moved = _start(capsys, bench, out, "--catalogue", str(plant), "--move-catalogue")
    assert moved.code == 0, moved.err
    assert _identity(out)["catalogue"] == str(plant.resolve())
    doc = json.loads(run_cli(capsys, "trend", "--catalogue", str(plant), "--joint", "joint1", "--json").out)
    assert [(p["tags"]["monitor_window"], p["state"]) for p in doc["points"]][:3] == [
        (0, "baseline"), (1, "baseline"), (2, "ok")]


def _window(monitor: str | None, n: int, k: float, *, robot: str = "r1") -> Outcome:
    """A window (or, without ``monitor``, a bench's session) of joint1 as a monitor files it, n minutes in."""
    tags: dict[str, object] = {"robot": robot, "monitor_window": n}
    if monitor is not None:
        tags["monitor_id"] = monitor
    doc = {"options": {}, "analyzed_utc": f"2026-01-02T00:{n:02d}:30+00:00", "acq_version": "t", "K_Nm_per_rad": k,
           "ci95": {"K_Nm_per_rad": [k - 5.0, k + 5.0]}, "quality": {"verdict": "ok", "reasons": []}}
    meta = {"session_id": f"{monitor}-{n}", "joint": "joint1", "created_utc": f"2026-01-02T00:{n:02d}:00+00:00",
            "start_monotonic_ns": n, "status": "complete", "tags": tags}
    return Outcome(f"/m/{monitor}-{n}.h5", f"sha-{monitor}-{n}", "{}", meta, doc, None, 1.0)


def test_trend_and_fleet_read_one_monitor_by_the_catalogue_column(catalogue_location: Path | str,
                                                                 capsys: pytest.CaptureFixture[str]) -> None:
    """acq trend / acq fleet --tag monitor_id=ID read every window of the catalogue and kept the monitor's in Python
    (the last closing note); the query now names the monitor (its column's index). What it returns: the monitor's
    windows and no other's, a window an earlier acq filed without the column (its tag says whose) among them, and a
    monitor whose identity is digits (a monitor.id not made by acq), which the tag's number parsing matched to none."""
    with Catalogue(catalogue_location) as c:
        for n in range(4):
            c.record(_window("r1:/srv/m:0a0b0c0d", n, 890.0 + n))
            c.record(_window("r2:/srv/m:01020304", n, 700.0 + n, robot="r2"))
            c.record(_window("4711", n, 500.0 + n, robot="r3"))
        c.record(_window(None, 9, 100.0))  # a bench's session of the same joint name
        c.record(_window("r1:/srv/m:0a0b0c0d", 4, 894.0))
        c._execute("UPDATE sessions SET monitor_id = NULL WHERE session_id = ?", ("r1:/srv/m:0a0b0c0d-4",))
    where = ["--catalogue", str(catalogue_location)]
    trend = run_cli(capsys, "trend", *where, "--joint", "joint1", "--tag", "monitor_id=r1:/srv/m:0a0b0c0d", "--json")
    assert trend.code == 0, trend.err
    assert [(p["tags"]["monitor_window"], p["K_Nm_per_rad"]) for p in json.loads(trend.out)["points"]] == [
        (0, 890.0), (1, 891.0), (2, 892.0), (3, 893.0), (4, 894.0)]
    digits = run_cli(capsys, "trend", *where, "--joint", "joint1", "--tag", "monitor_id=4711", "--json")
    assert digits.code == 0, digits.err
    assert [p["K_Nm_per_rad"] for p in json.loads(digits.out)["points"]] == [500.0, 501.0, 502.0, 503.0]
    fleet = run_cli(capsys, "fleet", *where, "--tag", "monitor_id=r2:/srv/m:01020304", "--tag", "robot=r2", "--json")
    assert fleet.code == 0, fleet.err
    assert [(r["robot"], r["monitor_id"], r["K_Nm_per_rad"]) for r in json.loads(fleet.out)] == [
        ("r2", "r2:/srv/m:01020304", 703.0)]
    none = run_cli(capsys, "fleet", *where, "--tag", "monitor_id=r2:/srv/m:01020304", "--tag", "robot=r1")
    assert (none.code, none.err) == (2, f"acq: error: {catalogue_location}: no sessions of any joint tagged "
                                        "monitor_id=r2:/srv/m:01020304 robot=r1\n")
