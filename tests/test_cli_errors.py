"""One clear line and the right exit code (README: 1 failed write, 2 bad input) where the new-user trial found
otherwise: failed PNG writes, a monitor on a read-only folder, a batch into a read-only folder, ``--tag`` values,
and the same error given the same exit code by every command."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from acq.monitoring.catalogue import Catalogue, Outcome
from acq.recording.reader import load
from acq.recording.tags import parse_tags, tags_match
from acq.ui.values import interval_text, options_text
from acqcore.errors import ConfigError
from tests.helpers import read_only_view, record_session_in_subprocess, run_cli, seeded_profile

ROBOT = Path(__file__).resolve().parents[1] / "configs" / "benches" / "sim_robot.toml"


def _catalogue(folder: Path, joint: str = "joint1", n: int = 3) -> Path:
    """A catalogue in ``folder`` with ``n`` sessions of ``joint`` of verdict ok (K 890 N·m/rad), as acq analyze files
    them."""
    folder.mkdir(parents=True, exist_ok=True)
    doc = {"options": {}, "K_Nm_per_rad": 890.0, "ci95": {"K_Nm_per_rad": [886.0, 894.0]},
           "quality": {"verdict": "ok", "reasons": []}}
    with Catalogue(folder / "catalogue.sqlite") as c:
        for i in range(n):
            meta = {"session_id": f"s{i}", "joint": joint, "tags": {"pose": "home"},
                    "created_utc": f"2026-11-29T10:0{i}:00+00:00"}
            c.record(Outcome(f"/m/s{i}.h5", f"h{i}", "r", meta, doc, None, 1.0))
    return folder


# ---- 1. a PNG acq cannot write: the cause, exit 1; a PNG path that cannot be one: bad input, exit 2 ------------------
@pytest.mark.parametrize("command", [("trend", "{folder}", "--joint", "joint1", "--png"),
                                     ("fleet", "{folder}", "--png"),
                                     ("view", "--trend", "joint1", "{folder}", "--screenshot")])
def test_a_png_into_a_read_only_folder_is_a_failed_write_naming_the_cause(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], command: tuple[str, ...]) -> None:
    os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")
    folder = _catalogue(tmp_path / "sessions")
    (tmp_path / "ro").mkdir()
    with read_only_view(tmp_path / "ro") as ro:
        png = ro / "out.png"
        run = run_cli(capsys, *(part.format(folder=folder) for part in command), str(png))
        assert (run.code, run.err) == (1, f"acq: error: read-only file system: {png}\n")
        assert not png.exists() and not list(ro.iterdir())  # no temp file left behind either


@pytest.mark.parametrize("command", [("trend", "{folder}", "--joint", "joint1", "--png"),
                                     ("fleet", "{folder}", "--png")])
def test_a_png_in_a_folder_that_takes_no_new_file_says_it_cannot_write_there(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], command: tuple[str, ...]) -> None:
    """/proc exists but takes no new file (ENOENT): it said "folder vanished: /proc/x.png"."""
    os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")
    folder = _catalogue(tmp_path / "sessions")
    run = run_cli(capsys, *(part.format(folder=folder) for part in command), "/proc/acq-test.png")
    assert (run.code, run.err) == (1, "acq: error: cannot write a file there: /proc/acq-test.png\n")


@pytest.mark.parametrize(("name", "message"), [
    ("out.jpg", "--png {png}: acq writes PNG only — name the file *.png, e.g. {stem}.png"),
    ("out", "--png {png}: acq writes PNG only — name the file *.png, e.g. {stem}.png"),
    ("folder", "--png {png}: is a folder — give the PNG's file name, e.g. {png}/out.png")])
def test_a_png_path_that_cannot_be_a_png_is_refused_before_anything_is_drawn(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], name: str, message: str) -> None:
    folder = _catalogue(tmp_path / "sessions")
    (tmp_path / "folder").mkdir()
    png = tmp_path / name
    run = run_cli(capsys, "trend", str(folder), "--joint", "joint1", "--png", str(png))
    assert (run.code, run.out) == (2, "")
    assert run.err == "acq: error: " + message.format(png=png, stem=tmp_path / "out") + "\n"
    run = run_cli(capsys, "view", "--trend", "joint1", str(folder), "--screenshot", str(tmp_path / "out.jpg"))
    assert (run.code, run.err) == (2, f"acq: error: --screenshot {tmp_path / 'out.jpg'}: acq writes PNG only — name "
                                      f"the file *.png, e.g. {tmp_path / 'out.png'}\n")
    assert not (tmp_path / "out.jpg").exists()


def test_a_png_that_can_be_written_is_written(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    folder = _catalogue(tmp_path / "sessions")
    png = tmp_path / "new" / "trend.PNG"  # its folder made, the suffix's case free
    run = run_cli(capsys, "trend", str(folder), "--joint", "joint1", "--png", str(png))
    assert run.code == 0, run.err
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and [p.name for p in png.parent.iterdir()] == ["trend.PNG"]


# ---- 2. acq monitor: a read-only --out is a failed write; a refused start leaves nothing it made --------------------
def test_a_monitor_into_a_read_only_folder_is_one_line_exit_1(tmp_path: Path,
                                                               capsys: pytest.CaptureFixture[str]) -> None:
    (tmp_path / "ro").mkdir()
    with read_only_view(tmp_path / "ro") as ro:
        run = run_cli(capsys, "monitor", "--bench", str(ROBOT), "--window", "4", "--every", "5", "--fast", "--for",
                      "10s", "--out", str(ro / "mon"))
    assert (run.code, run.err) == (1, f"acq: error: read-only file system: {ro / 'mon'}\n")


def test_a_refused_monitor_start_leaves_no_folder_behind(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "new" / "mon"
    bench = ROBOT.with_name("sim_robot_canopen.toml")
    run = run_cli(capsys, "monitor", "--bench", str(bench), "--fast", "--out", str(out))
    assert (run.code, run.err) == (2, "acq: error: --fast: the simulated CANopen drive runs on the bus in real time; "
                                      "run without --fast\n")
    assert list(tmp_path.iterdir()) == []  # neither mon nor the folder new it made above it
    (tmp_path / "kept").mkdir()  # a folder that was there stays
    run = run_cli(capsys, "monitor", "--bench", str(bench), "--fast", "--out", str(tmp_path / "kept"))
    assert run.code == 2 and [p.name for p in tmp_path.iterdir()] == ["kept"]
    assert not list((tmp_path / "kept").iterdir())


# ---- 3. acq analyze of a read-only folder: say so and the way out; trend's advice the way that works -----------------
def test_a_batch_of_a_read_only_folder_names_the_cause_and_the_way_out(tmp_path: Path,
                                                                        capsys: pytest.CaptureFixture[str]) -> None:
    record_session_in_subprocess(tmp_path / "sessions", 3.0)
    with read_only_view(tmp_path / "sessions") as ro:
        run = run_cli(capsys, "analyze", str(ro), "--no-report")
        assert (run.code, run.out) == (1, "")
        assert run.err == (f"acq: error: read-only file system: {ro / 'catalogue.sqlite'} (no catalogue can be made "
                           "there) — --result-dir DIR writes the results and the catalogue elsewhere\n")
        run = run_cli(capsys, "analyze", str(ro), "--no-report", "--catalogue", str(ro / "c.sqlite"))
        assert (run.code, run.err) == (1, f"acq: error: read-only file system: {ro / 'c.sqlite'} (no catalogue can "
                                          "be made there) — give --catalogue a file acq may write\n")
        trend = run_cli(capsys, "trend", str(ro), "--joint", "joint1")
        assert (trend.code, trend.err) == (2, f"acq: error: {ro / 'catalogue.sqlite'}: no catalogue — {ro} is not "
                                              f"writable (read-only file system): fill one with acq analyze {ro}/ "
                                              "--result-dir DIR, then acq trend DIR\n")
        # the advice works
        run = run_cli(capsys, "analyze", str(ro), "--no-report", "--result-dir", str(tmp_path / "results"))
        assert run.code == 0, run.err
    trend = run_cli(capsys, "trend", str(tmp_path / "results"), "--joint", "joint1", "--json")
    assert trend.code == 0 and len(json.loads(trend.out)["points"]) == 1
    with read_only_view(tmp_path / "results") as ro:  # a catalogue there, in a read-only folder: read, not written
        trend = run_cli(capsys, "trend", str(ro), "--joint", "joint1", "--json")
    assert (trend.code, trend.err) == (0, "") and len(json.loads(trend.out)["points"]) == 1


# ---- 4. --tag: one parser, nothing silently changed ------------------------------------------------------------------
def test_tag_values_spelt_as_numbers_are_numbers_and_any_other_spelling_stays_text() -> None:
    tags = parse_tags(["pose=home", "payload_kg=2.5", "temperature_C=31", "offset=-3", "rate=1e3", "serial=007",
                       "plus=+5", "dot=.5", "under=1_000", "eq=a=b", " pad = x y ", "operator=Nan", "mode=INF"])
    assert tags == {"pose": "home", "payload_kg": 2.5, "temperature_C": 31.0, "offset": -3.0, "rate": 1000.0,
                    "serial": "007", "plus": "+5", "dot": ".5", "under": "1_000", "eq": "a=b", "pad": "x y",
                    "operator": "Nan", "mode": "INF"}  # words float() would read as nan/inf stay words (second read)
    assert [type(tags[k]) for k in ("serial", "payload_kg")] == [str, float]
    assert tags_match({"serial": "007", "payload_kg": 2.5}, parse_tags(["serial=007", "payload_kg=2.50"]))
    assert not tags_match({"serial": "007"}, parse_tags(["serial=7"]))


def test_a_number_like_tag_given_today_still_finds_the_number_earlier_acq_stored_for_it() -> None:
    """The second read: earlier acq stored --tag robot=007 as 7.0; today's "007" must still find those sessions."""
    for text, stored in (("robot=007", 7.0), ("robot=+5", 5.0), ("robot=1_000", 1000.0), ("robot=.5", 0.5)):
        assert tags_match({"robot": stored}, parse_tags([text])), text
    assert not tags_match({"robot": 7.0}, parse_tags(["robot=008"]))
    assert not tags_match({"robot": "7"}, parse_tags(["robot=007"]))  # a stored text matches only its own spelling


@pytest.mark.parametrize(("texts", "message"), [
    (["pose=a", "pose=b"], "--tag pose=b: pose is given twice (pose=a, pose=b) — give each key once"),
    (["payload_kg=-1e400"], "--tag payload_kg=-1e400: -1e400 is not a finite number (a tag's number must be finite)"),
    (["big=1e999"], "--tag big=1e999: 1e999 is not a finite number (a tag's number must be finite)"),
    (["po se=home"], "--tag po se=home: the key 'po se' may hold only letters, digits, _ . - (no spaces)"),
    (["pose="], "--tag pose=: the value is empty — give KEY=VALUE, e.g. pose=home"),
    (["pose=  "], "--tag pose=  : the value is empty — give KEY=VALUE, e.g. pose=home"),
    (["pose"], "--tag pose: must be KEY=VALUE, e.g. payload_kg=2.5"),
    (["=home"], "--tag =home: must be KEY=VALUE, e.g. payload_kg=2.5")])
def test_a_tag_that_would_be_corrupted_or_never_match_is_refused_naming_it(texts: list[str], message: str) -> None:
    with pytest.raises(ConfigError) as refused:
        parse_tags(texts)
    assert str(refused.value) == message


@pytest.mark.parametrize("command", [
    ("record", "--profile", "triangle_0.2s", "--fast", "--duration", "3", "--no-analyze", "--out", "{out}"),
    ("monitor", "--bench", str(ROBOT), "--fast", "--for", "10s", "--out", "{out}"),
    ("trend", "{out}", "--joint", "joint1"),
    ("fleet", "{out}"),
    ("view", "--trend", "joint1", "{out}", "--screenshot", "{out}/t.png")])
def test_every_command_taking_tags_refuses_a_duplicate_key_in_one_line(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], command: tuple[str, ...]) -> None:
    os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")
    out = tmp_path / "out"
    if command[0] in ("trend", "fleet", "view"):
        _catalogue(out)
    before = sorted(tmp_path.rglob("*"))
    run = run_cli(capsys, *(part.format(out=out) for part in command), "--tag", "pose=a", "--tag", "pose=b")
    assert (run.code, run.out) == (2, "")
    assert run.err == "acq: error: --tag pose=b: pose is given twice (pose=a, pose=b) — give each key once\n"
    assert sorted(tmp_path.rglob("*")) == before  # nothing made


@pytest.mark.parametrize(("command", "option", "given", "byte"), [
    (("record", "--profile", "triangle_0.2s", "--fast", "--duration", "3", "--no-analyze", "--out", "{out}"),
     "--operator", b"Ren\xe9", "e9"),
    (("record", "--profile", "triangle_0.2s", "--fast", "--duration", "3", "--no-analyze", "--out", "{out}"),
     "--tag", b"site=K\xf6ln", "f6"),
    (("monitor", "--bench", str(ROBOT), "--fast", "--for", "10s", "--out", "{out}"), "--tag", b"site=K\xf6ln", "f6")])
def test_text_from_a_latin_1_shell_is_refused_naming_the_option_and_the_byte(
        tmp_path: Path, command: tuple[str, ...], option: str, given: bytes, byte: str) -> None:
    """The bytes a shell or terminal in Latin-1 passes (é is the one byte 0xe9), as the real argv of a child process:
    Python reads them as lone surrogates. Before: --operator gave "acq: error: 'utf-8' codec can't encode character
    '\\udce9' in position 3: surrogates not allowed: <file>", and a --tag was recorded exit 0, stored escaped
    ({"site": "K\\udcf6ln"}). Now one line naming the option and the byte, exit 2, nothing made."""
    out = tmp_path / "out"
    argv = [sys.executable, "-m", "acq", *(part.format(out=out) for part in command), option, given]
    run = subprocess.run(argv, capture_output=True, timeout=120, cwd=tmp_path)
    shown = given.decode("latin-1").encode("ascii", "backslashreplace").decode()
    assert (run.returncode, run.stdout) == (2, b"")
    assert run.stderr.decode() == (f"acq: error: {option} '{shown}': byte 0x{byte} is not UTF-8 (a shell or terminal "
                                   "in Latin-1 sends é as 0xe9) — give the text in UTF-8\n")
    assert not out.exists()


def test_a_recorded_tag_keeps_its_spelling(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "sessions"
    run = run_cli(capsys, "record", "--profile", str(seeded_profile(tmp_path)), "--fast", "--duration", "4", "--out",
                  str(out), "--tag", "serial=007", "--tag", "payload_kg=2.5", "--no-analyze")
    assert run.code == 0, run.err
    (path,) = out.glob("*.h5")
    assert load(path).tags == {"serial": "007", "payload_kg": 2.5}


# ---- 5, 6. one exit code per error, small refusals, readable empty results ------------------------------------------
def test_no_catalogue_is_the_same_error_and_exit_code_for_trend_and_view(tmp_path: Path,
                                                                       capsys: pytest.CaptureFixture[str]) -> None:
    os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")
    message = (f"acq: error: {tmp_path / 'catalogue.sqlite'}: no catalogue — fill one with acq analyze {tmp_path}/ "
               "first\n")
    trend = run_cli(capsys, "trend", str(tmp_path), "--joint", "joint1")
    view = run_cli(capsys, "view", "--trend", "joint1", str(tmp_path), "--screenshot", str(tmp_path / "t.png"))
    assert (trend.code, trend.err) == (view.code, view.err) == (2, message)
    # the trial: acq trend nosuchfolder advised filling a catalogue in a folder that is not there
    missing = tmp_path / "nosuchfolder"
    for command in (["trend", str(missing), "--joint", "joint1"], ["fleet", str(missing)],
                    ["trend", "--catalogue", str(missing / "catalogue.sqlite"), "--joint", "joint1"],
                    ["fleet", "--catalogue", str(missing / "catalogue.sqlite")]):
        run = run_cli(capsys, *command)
        assert (run.code, run.err) == (2, f"acq: error: {missing / 'catalogue.sqlite'}: no catalogue — the folder "
                                          f"{missing} does not exist\n"), command
    # a file where the folder should be: said so, not advised to fill a catalogue inside it
    afile = tmp_path / "notes.txt"
    afile.write_text("x")
    for command in (["trend", "--catalogue", str(afile / "c.sqlite"), "--joint", "joint1"],
                    ["fleet", "--catalogue", str(afile / "c.sqlite")]):
        run = run_cli(capsys, *command)
        assert (run.code, run.err) == (2, f"acq: error: {afile / 'c.sqlite'}: no catalogue — {afile} is a file, not a "
                                          "folder\n"), command
    run = run_cli(capsys, "trend", str(afile), "--joint", "joint1")  # as FOLDER: refused before any catalogue
    assert (run.code, run.err) == (2, f"acq: error: {afile}: is a file, not a folder\n")


@pytest.mark.parametrize("command", [("analyze", "{session}", "--no-report", "--catalogue", "{folder}"),
                                     ("trend", "--catalogue", "{folder}", "--joint", "joint1"),
                                     ("fleet", "--catalogue", "{folder}")])
def test_a_catalogue_that_is_a_folder_is_named_so(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                                  command: tuple[str, ...]) -> None:
    """The trial: acq analyze S.h5 --catalogue sessions (a folder) said "cannot open the catalogue (unable to open
    database file)"; acq trend --catalogue sessions "no catalogue — fill it with acq analyze FOLDER/ --catalogue
    sessions". Refused before any analysis (the session here is an empty file, which would say so)."""
    folder = tmp_path / "sessions"
    folder.mkdir()
    (tmp_path / "s.h5").write_bytes(b"")
    run = run_cli(capsys, *(part.format(session=tmp_path / "s.h5", folder=folder) for part in command))
    assert (run.code, run.out, run.err) == (2, "", f"acq: error: {folder}: is a folder, not a catalogue file — give the "
                                                   f"file, e.g. {folder / 'catalogue.sqlite'}\n")


def test_a_folder_where_a_batch_puts_its_catalogue_is_named_so(tmp_path: Path,
                                                               capsys: pytest.CaptureFixture[str]) -> None:
    """A folder named catalogue.sqlite where acq analyze FOLDER/ files its results: SQLite said "unable to open
    database file"."""
    (tmp_path / "catalogue.sqlite").mkdir()
    (tmp_path / "s.h5").write_bytes(b"")  # a batch opens its catalogue before it reads a session
    run = run_cli(capsys, "analyze", str(tmp_path), "--no-report")
    assert (run.code, run.err) == (2, f"acq: error: {tmp_path / 'catalogue.sqlite'}: is a folder, not a catalogue "
                                      "file\n")


@pytest.mark.parametrize("command", ["analyze", "info", "check"])
def test_a_session_that_is_no_regular_file_is_named_so(capsys: pytest.CaptureFixture[str], command: str) -> None:
    """The trial: acq analyze /dev/zero said "empty (0 bytes)" (a character device's size is 0)."""
    run = run_cli(capsys, command, "/dev/zero")
    assert (run.code, run.err) == (2, "acq: error: /dev/zero: not a regular file (a device, pipe or socket), not a "
                                      "session file\n")


@pytest.mark.parametrize("command", [("analyze",), ("analyze", "{other}"), ("info",), ("check",),
                                     ("export", "--csv", "{folder}/csv"), ("view", "--screenshot", "{folder}/v.png")],
                         ids=["analyze", "batch", "info", "check", "export", "view"])
def test_a_catalogue_given_for_a_session_is_named_so_with_the_commands_that_read_it(
        tmp_path: Path, capsys: pytest.CaptureFixture[str], command: tuple[str, ...]) -> None:
    """The report: acq analyze sessions/catalogue.sqlite said "not a readable HDF5 session file (no HDF5 signature:
    another kind of file)", which neither said what the file is nor what reads it (a batch listed it as a failed
    session)."""
    catalogue = _catalogue(tmp_path / "monitor") / "catalogue.sqlite"
    other = tmp_path / "s.h5"
    other.touch()
    name, *rest = command
    run = run_cli(capsys, name, str(catalogue), *(a.format(folder=tmp_path, other=other) for a in rest))
    assert (run.code, run.out) == (2, "")
    assert run.err == (f"acq: error: {catalogue}: is a catalogue (SQLite) file, not a session file — read it with "
                       f"acq fleet --catalogue {catalogue} (every joint's latest K) or acq trend --joint NAME "
                       f"--catalogue {catalogue} (one joint over time)\n")
    fleet = run_cli(capsys, "fleet", "--catalogue", str(catalogue))  # what it names reads it
    trend = run_cli(capsys, "trend", "--joint", "joint1", "--catalogue", str(catalogue))
    assert (fleet.code, trend.code) == (0, 0) and "joint1" in fleet.out and "890.0" in trend.out


def test_view_refuses_a_tag_without_a_trend(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    run = run_cli(capsys, "view", str(tmp_path / "s.h5"), "--tag", "pose=x", "--screenshot", str(tmp_path / "v.png"))
    assert (run.code, run.out) == (2, "")
    assert run.err == "acq: error: --tag pose=x: only with --trend JOINT (it selects the trend's sessions)\n"


def test_a_result_without_numbers_reads_as_such() -> None:
    """A window where the joint did not move: no interval ("—", not "— – —"), no torque method chosen
    ("default", not "None")."""
    doc = {"K_Nm_per_rad": None, "ci95": {"K_Nm_per_rad": None},
           "options": {"pipeline": "acq", "torque_method": None, "params": "K,Jm,Jl", "fit": "amplitude"}}
    assert interval_text(doc, "K_Nm_per_rad") == "—"
    assert interval_text(doc, "K_Nm_per_rad", relative=True) == "—"
    assert options_text(doc) == "torque default · params K,Jm,Jl · fit amplitude"
    doc = {"K_Nm_per_rad": 890.0, "ci95": {"K_Nm_per_rad": [886.0, 894.0]}, "options": {"torque_method": "encoder"}}
    assert interval_text(doc, "K_Nm_per_rad") == "886 – 894" and options_text(doc).startswith("torque encoder ·")


def test_a_catalogue_url_of_another_scheme_names_it_and_the_ones_acq_reads(capsys: pytest.CaptureFixture[str]) -> None:
    """The trial: --catalogue mysql://x/y read as a path, "mysql:/x/y: no catalogue …"."""
    for command in (["trend", "--joint", "joint1"], ["fleet"], ["monitor", "--bench", "sim_robot", "--for", "1s"]):
        run = run_cli(capsys, *command, "--catalogue", "mysql://u:secret@x/y")
        assert (run.code, run.err) == (2, "acq: error: --catalogue mysql://u:***@x/y: mysql:// is not a catalogue acq "
                                          "can use — give a SQLite file's path or a postgresql:// URL (or "
                                          "postgres://)\n"), command


@pytest.mark.parametrize(("typed", "error"), [
    ("analyse", "No such command 'analyse'. Did you mean analyze?"),
    ("ANALYZE", "No such command 'ANALYZE'. Did you mean analyze?"),
    ("recrod", "No such command 'recrod'. Did you mean record?"),
    ("xport", "No such command 'xport'. (Possible commands: export, import)"),
    ("xyz", "No such command 'xyz'."),
])
def test_a_mistyped_command_names_the_one_meant(capsys: pytest.CaptureFixture[str], typed: str, error: str) -> None:
    """`acq analyse x` said only "No such command 'analyse'." (click suggests for options, not commands)."""
    run = run_cli(capsys, typed, "x")
    assert (run.code, run.out, run.err) == (2, "", f"acq: error: {error}\n")
