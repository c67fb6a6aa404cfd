"""``acq selftest`` on the simulated bench, correct and misconfigured on purpose ([sim] truth differing from
the stated config): each fault is named with the key to change, and ``acq analyze`` says the same."""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

import acq.commissioning.devices
from acq.commissioning.selftest_checks import Check, sync_jitter_check
from acq.config import DEFAULT_BENCH
from acq.recording.reader import load
from acq.ui.selftest_cli import next_step, selftest_json
from acqcore.errors import DeviceError
from analysis.speed_ratio import SpeedRatio, likely_counts_per_rev, ratio_doubt, ratio_fault
from drivers.nidaq import DRIVER_MISSING
from tests.helpers import run_cli, seeded_profile
from tests.nidaqmx_standin import StandinHardware
from tests.test_nidaq import hardware, write_bench  # noqa: F401 - the stand-in NI 9234 fixture

SIM = DEFAULT_BENCH.read_text()


INERTIA_KNOWN = re.search(r"^inertia_known = true .*\n", SIM, re.M)[0]  # the shipped bench's [nominal] line


def bench_file(tmp_path: Path, sim_lines: str = "", *, channels: str = '["i_a"]', inertia_known: bool = True) -> Path:
    """The default simulated bench with extra ``[sim]`` truth lines (appended: [sim] is the last table);
    ``inertia_known=False``: without its ``[nominal] inertia_known = true``, as a bench whose inertias nobody stated."""
    text = SIM.replace('channels = ["i_a"]', f"channels = {channels}")
    if not inertia_known:
        text = text.replace(INERTIA_KNOWN, "", 1)
    path = tmp_path / "bench.toml"
    path.write_text(text + "\n" + sim_lines + "\n")
    return path


def selftest(capsys: pytest.CaptureFixture[str], bench: Path, *profile: str) -> tuple[int, dict]:
    run = run_cli(capsys, "selftest", "--fast", "--json", "--bench", str(bench), *profile)
    return run.code, json.loads(run.out)


def failed_check(doc: dict) -> dict:
    (fail,) = [c for c in doc["checks"] if c["status"] == "fail"]
    assert doc["checks"][-1] == fail, "the selftest stops at the first failed check"
    return fail


def test_correct_bench_passes_every_check_in_order_with_figures(capsys: pytest.CaptureFixture[str],
                                                                tmp_path: Path) -> None:
    code, doc = selftest(capsys, DEFAULT_BENCH, "--profile", str(seeded_profile(tmp_path)))
    assert code == 0 and doc["passed"] and doc["stopped_at"] is None
    names = [(c["stage"], c["name"]) for c in doc["checks"]]
    assert names == [("devices", "acq devices"), ("devices", "DAQ"), ("devices", "drive"), ("streams", "recording"),
                     ("streams", "DAQ blocks"), ("streams", "drive period"), ("streams", "SYNC jitter"),
                     ("streams", "current at standstill"),
                     ("motion", "encoder speed"), ("motion", "electrical speed"), ("motion", "direction"),
                     ("motion", "phase order"), ("identification", "identification (10 s)"),
                     ("identification", "torque constant")]
    by = {c["name"]: c for c in doc["checks"]}
    assert by["recording"]["values"]["current_lost"] == 0 and by["recording"]["values"]["encoder_lost"] == 0
    assert by["DAQ"]["values"]["rate_hz"] == 25600.0
    assert by["drive period"]["values"]["period_host_s"] == pytest.approx(1e-3, rel=1e-3)
    # the simulated drive latches on its cycle grid ([sim] sync_jitter_s = 0) and stamps it: no jitter
    assert by["SYNC jitter"]["figure"] == ("0.0 µs RMS, largest 0 µs off the 1 ms cycle grid (the drive's own time "
                                           "stamps); bound 500 µs")
    noise = by["current at standstill"]["values"]["i_a"]["white_noise_A"]
    assert noise == pytest.approx(0.01, rel=0.1)  # [sim] current_noise_A
    assert by["electrical speed"]["values"]["ratio"] == pytest.approx(1.0, abs=0.02)
    assert by["encoder speed"]["values"]["ratio"] == pytest.approx(1.0, abs=0.05)
    assert by["identification (10 s)"]["values"]["verdict"] == "ok"
    assert by["identification (10 s)"]["values"]["K_Nm_per_rad"] == pytest.approx(891.0, rel=0.02)
    # the shipped bench states its inertias known (they are its [sim] truth): k_t is checked, and holds
    assert [c["name"] for c in doc["checks"] if c["status"] != "pass"] == []
    assert by["torque constant"]["values"]["ratio"] == pytest.approx(1.0, abs=0.05)


ROBOT = Path(__file__).resolve().parents[1] / "configs" / "benches" / "sim_robot.toml"


@pytest.mark.parametrize("seed", [5, 0])
def test_a_listening_bench_is_checked_on_the_machines_own_motion_without_commanding_any(
        capsys: pytest.CaptureFixture[str], tmp_path: Path, seed: int) -> None:
    """sim_robot.toml ([drive] motion = "external") failed `✗ devices · open` with "record without a profile", exit 2.
    Now the checks that need no commanded motion run; seed 5's first 10 s excite the joint, seed 0's do not (⚠)."""
    bench = tmp_path / "robot.toml"
    bench.write_text(ROBOT.read_text().replace("seed = 0 ", f"seed = {seed} "))
    code, doc = selftest(capsys, bench)
    assert code == 0 and doc["passed"]
    by = {c["name"]: c for c in doc["checks"]}
    assert [(c["stage"], c["name"], c["status"]) for c in doc["checks"]][:9] == [
        ("devices", "acq devices", "pass"), ("devices", "DAQ", "pass"), ("devices", "drive", "pass"),
        ("streams", "recording", "pass"), ("streams", "DAQ blocks", "pass"), ("streams", "drive period", "pass"),
        ("streams", "SYNC jitter", "pass"), ("motion", "machine's motion", "pass"), ("motion", "electrical speed", "warn")]
    assert by["recording"]["figure"] == "3.0 s: 76800 current + 3000 encoder samples, 0 + 0 lost"
    assert by["machine's motion"]["figure"].endswith(" motor revolutions in 10 s (the machine's own motion; acq "
                                                    "commanded none)")
    assert by["electrical speed"]["fix"] == ("pole_pairs, counts_per_rev and the phase order stay unchecked on a "
                                             "listening bench: take them from the motor's and the encoder's data sheets")
    ident = by["identification (10 s)"]
    if seed == 5:
        assert ident["status"] == "pass" and ident["values"]["K_Nm_per_rad"] == pytest.approx(891.0, rel=0.02)
        assert by["torque constant"]["values"]["ratio"] == pytest.approx(1.0, abs=0.05)
    else:
        assert (ident["status"], ident["figure"]) == ("warn", "not excited: 0 of the record's 12 moves put torque into "
                                                              "10…400 Hz beyond chance; time that does: 3 % of the record; "
                                                              "1 of 38 Welch segments excites — in-band S/N above 1.33, "
                                                              "chance's 99 % point; the selection needs 2; clock "
                                                              "alignment residual 1001 µs exceeds 1000 µs for an "
                                                              "amplitude fit")  # the host stamps' drift (session 13)
        assert ident["fix"] == ("run acq selftest again while the machine runs a program with fast moves of this joint "
                                "(acq commands no motion on a bench with [drive] motion = \"external\")")
    refused = run_cli(capsys, "selftest", "--fast", "--bench", str(bench), "--profile", "triangle_0.2s")
    assert (refused.code, refused.err.strip()) == (2, f"acq: error: --profile triangle_0.2s: {bench} has [drive] motion "
                                                      "= \"external\": acq commands no motion there and checks the bench "
                                                      "on the machine's own motion — leave out --profile")
    assert next_step([], Path("robot.toml"), None) == ("the bench is ready: acq monitor --bench robot.toml, or acq record "
                                                       "--bench robot.toml --duration 10")


def test_a_new_users_first_selftest_on_the_shipped_bench_shows_no_warning(capsys: pytest.CaptureFixture[str]) -> None:
    """``acq selftest`` as README's new user runs it (no --bench): before, its last check was ``⚠ identification ·
    torque constant`` because the shipped config left inertia_known unset although its inertias are the simulator's."""
    run = run_cli(capsys, "selftest", "--fast")
    assert run.code == 0, run.out + run.err
    lines = run.out.splitlines()
    assert [line for line in lines if line.startswith(("⚠", "✗"))] == []  # the checks' own lines
    assert any(line.startswith("✓ identification · torque constant") for line in lines)
    rows = {cells[0]: cells[1:] for line in lines if line.startswith("│")
            for cells in [[c.strip() for c in line.strip("│").split("│")]]}
    assert {stage: (warned, failed, result) for stage, (_, warned, failed, result) in rows.items()} == {
        stage: ("0", "0", "✓") for stage in ("devices", "streams", "motion", "identification")}  # the summary table
    assert lines[-1] == "the bench is ready: acq record --profile triangle_0.2s"


def test_a_jittering_sync_is_a_warning_with_its_figure_against_half_a_cycle(capsys: pytest.CaptureFixture[str],
                                                                             tmp_path: Path) -> None:
    """[sim] sync_jitter_s = 200 µs at a 1 ms cycle: the drive's stamps scatter ≈ 200 µs RMS (clipped at 0.45 of a
    cycle by the simulator, so none reaches half a cycle off the fitted grid), which over the 10 s identification's 10 000
    cycles reaches ≈ 200 · √(2 ln 10⁴) ≈ 860 µs: beyond half a cycle, where the analysis refuses the stamps."""
    code, doc = selftest(capsys, bench_file(tmp_path, "sync_jitter_s = 0.0002"))
    assert code == 0
    check = {c["name"]: c for c in doc["checks"]}["SYNC jitter"]
    assert check["status"] == "warn"
    values = check["values"]
    assert values["sigma_s"] == pytest.approx(200e-6, rel=0.1) and values["bound_s"] == 500e-6
    assert values["largest_s"] < values["bound_s"] <= values["expected_largest_s"]  # only the projection warns
    assert check["figure"] == (f"{1e6 * values['sigma_s']:.1f} µs RMS, largest {1e6 * values['largest_s']:.0f} µs off "
                               "the 1 ms cycle grid (the drive's own time stamps); bound 500 µs")
    assert check["fix"].startswith(f"{1e6 * values['sigma_s']:.0f} µs RMS reaches ≈ "
                                   f"{1e6 * values['expected_largest_s']:.0f} µs in the 10 s identification, half a "
                                   "cycle or more, where the analysis refuses the drive's time stamps")
    assert check["affects"] == "the analysis may refuse a recording's drive time stamps, and TPDOs may miss their SYNC"


def test_the_last_line_of_a_run_with_a_warning_names_it_and_what_it_leaves_in_doubt(
        capsys: pytest.CaptureFixture[str], tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """On a loaded host "⚠ SYNC jitter" was followed by "the bench is ready" alone, which read as a contradiction: the
    last line now says the bench is ready with that warning and what it affects, as it would name any other."""
    monkeypatch.setenv("COLUMNS", "300")
    bench = bench_file(tmp_path, "sync_jitter_s = 0.0002")
    run = run_cli(capsys, "selftest", "--fast", "--bench", str(bench))
    assert run.code == 0, run.out + run.err
    assert [line.split("  ")[0] for line in run.out.splitlines() if line.startswith("⚠")] == ["⚠ streams · SYNC jitter"]
    assert run.out.splitlines()[-1] == (
        "the bench is ready, with 1 warning (SYNC jitter: the analysis may refuse a recording's drive time stamps, and "
        f"TPDOs may miss their SYNC): acq record --profile triangle_0.2s --bench {bench}")
    two = [Check("devices", "DAQ", "pass", "ok"), Check("motion", "phase order", "warn", "x", "y", affects="z"),
           Check("identification", "torque constant", "warn", "x", "y", affects="k_t unchecked")]
    assert next_step(two, None, None) == ("the bench is ready, with 2 warnings (phase order: z; torque constant: k_t "
                                          "unchecked): acq monitor, or acq record --duration 10")


def test_sync_jitter_check_fails_on_a_stamp_half_a_cycle_off_and_only_warns_from_host_stamps() -> None:
    k = np.arange(3000)
    times = k * 1e-3 + 1e-6 * np.sin(k)  # ± 1 µs: a good drive
    assert sync_jitter_check(k, times, 1e-3, "stamps", 10.0, from_drive=True).status == "pass"
    times[1500] += 0.6e-3  # one cycle 0.6 ms late
    assert sync_jitter_check(k, times, 1e-3, "stamps", 10.0, from_drive=True).status == "fail"
    assert sync_jitter_check(k, times, 1e-3, "host", 10.0, from_drive=False).status == "warn"


def test_a_bench_without_known_inertias_is_told_what_to_set_to_check_k_t(capsys: pytest.CaptureFixture[str],
                                                                         tmp_path: Path) -> None:
    code, doc = selftest(capsys, bench_file(tmp_path, inertia_known=False))
    assert code == 0 and doc["passed"]
    warned = [c for c in doc["checks"] if c["status"] != "pass"]
    assert [(c["name"], c["status"]) for c in warned] == [("torque constant", "warn")]
    assert warned[0]["fix"] == ("k_t and the current sensor's scale are not checked (a wrong one scales K, J_m, J_l and "
                                "C alike): set [nominal] Jm_kgm2 and Jl_kgm2 from the datasheet or CAD and "
                                "inertia_known = true")
    assert warned[0]["values"]["ratio"] == pytest.approx(1.0, abs=0.05)


@pytest.mark.parametrize("sim_line", ["pole_pairs = 8", "counts_per_rev = 65536"])
def test_wrong_pole_pairs_or_counts_is_named_by_selftest_and_by_analyze(
        capsys: pytest.CaptureFixture[str], tmp_path: Path, sim_line: str) -> None:
    code, doc = selftest(capsys, bench_file(tmp_path, sim_line))
    fail = failed_check(doc)
    assert code == 1 and not doc["passed"]
    if sim_line.startswith("pole_pairs"):
        # the encoder matches the commanded speed, the current turns twice as fast
        assert doc["stopped_at"] == "motion · electrical speed"
        assert fail["values"]["ratio"] == pytest.approx(2.0, abs=0.04)
        assert re.fullmatch(r"the current turns (1\.9\d|2\.0\d)× faster than pole_pairs·ω \(pole_pairs = 4, "
                            r"counts_per_rev = 131072\)", fail["figure"]), fail["figure"]
        assert fail["fix"] == "check [motor] pole_pairs = 8 or [encoder] counts_per_rev = 65536"
    else:
        # the encoder reports half the commanded speed: the counts per revolution are wrong
        assert doc["stopped_at"] == "motion · encoder speed"
        assert fail["fix"] == "check [encoder] counts_per_rev = 65536"
        assert fail["values"]["ratio"] == pytest.approx(0.5, abs=0.03)

    record = run_cli(capsys, "record", "--profile", "triangle_0.2s", "--bench", str(bench_file(tmp_path, sim_line)),
                     "--fast", "--no-analyze", "--out", str(tmp_path / "s"))
    assert record.code == 0
    (session,) = (tmp_path / "s").glob("*.h5")
    analyzed = run_cli(capsys, "analyze", str(session), "--json", "--no-report")
    result = json.loads(analyzed.out)
    quality = result["quality"]
    assert quality["verdict"] == "failed"
    assert isinstance(result["K_Nm_per_rad"], float)  # the JSON keeps the fit's raw numbers, the verdict failed
    fault, *others = [r for r in quality["reasons"] if not r.startswith("note: ")]
    assert re.fullmatch(r"the current turns 2\.0\d× faster than pole_pairs·ω \(pole_pairs = 4, counts_per_rev = "
                        r"131072\): check \[motor\] pole_pairs = 8 or \[encoder\] counts_per_rev = 65536",
                        fault), fault
    assert others == []  # the wrong constant is the reason: no advice about the motion beside it
    printed = run_cli(capsys, "analyze", str(session), "--no-report")
    words = " ".join(printed.out.split())  # the table's lines wrap at the terminal's width
    assert printed.code == 0 and "check [motor] pole_pairs = 8" in words and "acceleration time" not in words
    assert f"{result['K_Nm_per_rad']:.4g}" not in printed.out  # the table: "—", "not a result" (tests/test_display.py)
    assert re.search(r"^ K \[N·m/rad\] +│ +— │ +not a result │", printed.out, re.M), printed.out


def test_reversed_encoder_is_named(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    code, doc = selftest(capsys, bench_file(tmp_path, "encoder_direction = -1"))
    fail = failed_check(doc)
    assert code == 1 and doc["stopped_at"] == "motion · direction"
    assert fail["figure"] == "the encoder counts down while the drive moves forward"
    assert fail["fix"].startswith("reverse the encoder's counting direction in the drive (CiA 402 polarity 0x607E")


def test_swapped_phases_are_named_with_the_channels_to_set(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    bench = bench_file(tmp_path, 'phase_order = ["i_a", "i_c", "i_b"]', channels='["i_a", "i_b", "i_c"]')
    code, doc = selftest(capsys, bench)
    fail = failed_check(doc)
    assert code == 1 and doc["stopped_at"] == "motion · phase order"
    assert fail["values"]["agreement"] < -0.5
    assert re.fullmatch(r"the phase sequence a/b/c turns against the encoder \(correlation -0\.\d\d\)", fail["figure"])
    assert fail["fix"] == ('set [daq] channels = ["i_a", "i_c", "i_b"] (two phases swapped) or reverse the '
                           "encoder's counting direction")

    record = run_cli(capsys, "record", "--profile", "triangle_0.2s", "--bench", str(bench), "--fast", "--no-analyze",
                     "--out", str(tmp_path / "s"))
    assert record.code == 0
    (session,) = (tmp_path / "s").glob("*.h5")
    quality = json.loads(run_cli(capsys, "analyze", str(session), "--json", "--no-report").out)["quality"]
    assert quality["verdict"] == "failed"
    assert re.fullmatch(r"the phase sequence a/b/c turns against the encoder \(correlation -0\.\d\d\): set \[daq\] "
                        r'channels = \["i_a", "i_c", "i_b"\] \(two phases swapped\) or reverse the encoder\'s counting '
                        r"direction", quality["reasons"][0]), quality["reasons"][0]


def test_correct_three_phases_pass_the_phase_order(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    code, doc = selftest(capsys, bench_file(tmp_path, channels='["i_a", "i_b"]'))
    by = {c["name"]: c for c in doc["checks"]}
    assert code == 0, doc["stopped_at"]
    assert by["phase order"]["status"] == "pass" and by["phase order"]["values"]["agreement"] > 0.5
    assert by["torque constant"]["status"] == "pass"  # two phases, Park torque, known inertia


def test_wrong_sensor_scale_is_named_against_a_known_inertia(capsys: pytest.CaptureFixture[str],
                                                             tmp_path: Path) -> None:
    code, doc = selftest(capsys, bench_file(tmp_path, "current_sensor_gain = 2.0"))
    fail = failed_check(doc)
    assert code == 1 and doc["stopped_at"] == "identification · torque constant"
    assert fail["values"]["ratio"] == pytest.approx(2.0, rel=0.05)
    assert re.search(r", 2\.0\d× \[nominal\] Jm \+ Jl = 0\.01051: the torque reads 2\.0\d× too high$", fail["figure"]), \
        fail["figure"]
    assert re.fullmatch(r"check \[motor\] torque_constant_Nm_per_A = 1\.[45]\d* or the current sensor's scale",
                        fail["fix"]), fail["fix"]


def test_a_bench_that_cannot_be_opened_fails_the_devices_stage_in_one_line(
        capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    text = SIM.replace('driver = "sim"\nperiod_s = 0.001', 'driver = "serial"\nperiod_s = 0.001\nport = "/dev/acq-none"')
    text += "\n[limits]\nmax_speed_rpm = 1200.0\nmax_travel_deg = 135.0\nmax_torque_Nm = 20.0\n"  # a real drive's
    bench = tmp_path / "serial.toml"
    bench.write_text(text)
    run = run_cli(capsys, "selftest", "--fast", "--bench", str(bench))
    assert run.code == 1
    assert "✗ devices · acq devices" in run.out
    assert '[drive] port = "/dev/acq-none" is not there' in run.out
    assert "Traceback" not in run.out + run.err
    # a config the devices refuse at opening is bad input: exit 2, the adapter's own line
    run = run_cli(capsys, "selftest", "--fast", "--json", "--bench", str(DEFAULT_BENCH.parent / "sim_canopen.toml"))
    assert run.code == 2
    assert failed_check(json.loads(run.out))["figure"] == ("--fast: the simulated CANopen drive runs on the bus in "
                                                           "real time; run without --fast")


def test_pole_pairs_3_stated_on_a_4_pole_pair_motor_is_named_on_the_slow_move(
        capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    """The slow move's 3 moves hold 20 crossings through 16.6 half-turns (at pole_pairs = 3): the count allows
    0.81–1.41×, 1 and 1.36 alike, but the crossings' positions sit on the lattice of 4/3 and not on that of 1."""
    path = bench_file(tmp_path, "pole_pairs = 4")  # the motor's truth
    path.write_text(path.read_text().replace("pole_pairs = 4", "pole_pairs = 3", 1))  # [motor] comes first
    code, doc = selftest(capsys, path)
    fail = failed_check(doc)
    assert code == 1 and doc["stopped_at"] == "motion · electrical speed"
    assert fail["figure"] == "the current turns 1.36× faster than pole_pairs·ω (pole_pairs = 3, counts_per_rev = 131072)"
    assert fail["fix"] == "check [motor] pole_pairs = 4 or [encoder] counts_per_rev = 96446"


def test_the_crossings_lattice_rules_out_ratio_1_only_when_it_holds_the_other() -> None:
    # the slow move above: 21 crossings in 3 moves, all on the lattice of 1.36, 6 on that of 1
    wrong = SpeedRatio(1.359, 0.005, 0.0, 10.5, crossings=21, half_turns=16.6, moves=3, moving_s=1.36,
                       on_lattice=(6, 21))
    low, high = wrong.count_range
    assert low <= 1.0 <= high and wrong.lattice_excludes_one and wrong.named
    # a correct bench's lattice of 1 holds as many as any other: 1 not ruled out, whatever the count allows
    assert not replace(wrong, on_lattice=(21, 21)).named
    # one crossing a move in the moves (a 10 ms triangle: 1062 in 487 moves): both lattices hold them by chance
    assert not replace(wrong, crossings=1062, moves=487, on_lattice=(576, 917)).lattice_excludes_one


def test_ratio_fault_words_and_suggestions() -> None:
    assert ratio_fault(SpeedRatio(1.01, 0.001, 0.0, 100.0), 4, 131072) is None
    assert ratio_fault(SpeedRatio(0.5, 0.001, 0.0, 100.0), 4, 131072) == (
        "the current turns 2.00× slower than pole_pairs·ω (pole_pairs = 4, counts_per_rev = 131072): check "
        "[motor] pole_pairs = 2 or [encoder] counts_per_rev = 262144")
    # 4 → 5 pole pairs: no whole-number counts_per_rev nearby a power of two, so the rounded value
    assert ratio_fault(SpeedRatio(1.25, 0.001, 0.0, 100.0), 4, 10000) == (
        "the current turns 1.25× faster than pole_pairs·ω (pole_pairs = 4, counts_per_rev = 10000): check "
        "[motor] pole_pairs = 5 or [encoder] counts_per_rev = 8000")
    # a scattered estimate is not named even if its value is off
    assert ratio_fault(SpeedRatio(1.2, 0.05, 0.0, 3.0), 4, 131072) is None
    assert likely_counts_per_rev(64470.0, 0.05) == 65536 and likely_counts_per_rev(10000.0, 0.02) == 10000
    # 8 pole pairs on a 10 s triangle_0.2s: 1273 crossings in 25 moves through 627 half-turns allow
    # (1273 − 50)/627 − 0.03 = 1.92 … (1273 + 25)/627 + 0.03 = 2.10: one pole-pair count (8), one power of two
    named = SpeedRatio(2.003, 0.001, 0.0, 600.0, crossings=1273, half_turns=627.0, moves=25, moving_s=7.85)
    assert named.named and ratio_doubt(named, 4) is None and ratio_fault(named, 4, 131072).endswith(
        "check [motor] pole_pairs = 8 or [encoder] counts_per_rev = 65536")
    # 1212 crossings allow at most (1212 + 25)/627 + 0.03 = 2.0029 < 2.003: not a rotation ratio, no constant named
    short = replace(named, crossings=1212)
    assert not short.counted and ratio_fault(short, 4, 131072) is None
    assert ratio_doubt(short, 4) == (
        "pole_pairs and counts_per_rev cannot be checked on this record: the current's half-periods read 2.00× "
        "pole_pairs·ω, but its 1212 zero crossings in the moves allow 1.82–2.00× — each of the 25 moves turns the "
        "motor only 3.1 rev (25.1 electrical half-turns at pole_pairs = 4) in 314 ms, so the current's zero "
        "crossings follow its torque's sign changes as much as the rotation")
    # few half-turns per move: 300 crossings in 40 moves through 100 allow 2.15–3.45× (tolerance 5 σ = 0.05): a
    # constant is wrong; 4 × 2.3 is no whole pole-pair count, so the encoder's value is the one offered
    wide = SpeedRatio(2.3, 0.01, 0.0, 100.0, crossings=300, half_turns=100.0, moves=40, moving_s=4.0)
    assert wide.named and ratio_fault(wide, 4, 131072) == (
        "the current turns 2.30× faster than pole_pairs·ω (pole_pairs = 4, counts_per_rev = 131072): check "
        "[encoder] counts_per_rev = 56988")
    # the selftest's slow move with pole_pairs = 2 stated on a 4-pole-pair motor: 20 crossings in 3 moves through
    # 11.1 half-turns allow 1.23–2.11×, which pins neither value — both are offered, the pole pairs first (the
    # review of session 5 found "counts_per_rev = 65536" alone here: a technician following it breaks the encoder)
    slow = SpeedRatio(2.04, 0.005, 0.0, 30.0, crossings=20, half_turns=11.1, moves=3, moving_s=1.5)
    assert slow.named and ratio_fault(slow, 2, 131072).endswith(
        "check [motor] pole_pairs = 4 or [encoder] counts_per_rev = 65536")
    # the same crossings in 100 moves allow 0.95–4.05×, 1 included: neither a fault nor a value
    assert ratio_fault(replace(wide, moves=100), 4, 131072) is None and ratio_doubt(replace(wide, moves=100), 4)


def test_the_summary_at_80_columns_ends_with_the_fix_keys_and_all_or_the_command_for_this_bench(
        capsys: pytest.CaptureFixture[str], tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("COLUMNS", "80")
    run = run_cli(capsys, "selftest", "--fast", "--bench", str(bench_file(tmp_path, "pole_pairs = 8")))
    assert run.code == 1
    assert run.out.splitlines()[-1] == ("stopped at motion · electrical speed: check [motor] pole_pairs = 8 or [encoder] "
                                        "counts_per_rev = 65536")
    passed = [Check("devices", "DAQ", "pass", "ok")]
    assert next_step(passed, Path("lab.toml"), "triangle_0.2s") == ("the bench is ready: acq record --profile "
                                                                    "triangle_0.2s --bench lab.toml")
    assert next_step(passed, None, "fast.toml") == "the bench is ready: acq record --profile fast.toml"


def test_json_document_of_a_stopped_run() -> None:
    checks = [Check("devices", "DAQ", "pass", "ok"), Check("streams", "recording", "fail", "x", "fix it",
                                                            {"v": float("nan")})]
    doc = selftest_json(checks, "b.toml")
    assert doc["passed"] is False and doc["stopped_at"] == "streams · recording"
    assert doc["checks"][1]["values"] == {"v": None}


def test_plain_pytest_collects_the_hardware_suite_and_skips_it_with_the_reason(tmp_path: Path) -> None:
    env = {k: v for k, v in os.environ.items() if k != "ACQ_HW_BENCH"}
    root = Path(__file__).resolve().parent.parent
    run = subprocess.run([sys.executable, "-m", "pytest", "-q", "-rs", "-p", "no:cacheprovider", "tests/hardware"],
                         cwd=root, env=env, capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stdout + run.stderr
    assert re.search(r"\b(\d+) skipped", run.stdout) and " passed" not in run.stdout
    assert "hardware suite: set ACQ_HW_BENCH=path/to/bench.toml to run it against that bench" in run.stdout


def test_ni_daq_missing_device_and_coerced_rate_are_named(capsys: pytest.CaptureFixture[str], tmp_path: Path,
                                                          hardware: StandinHardware) -> None:
    run = run_cli(capsys, "selftest", "--fast", "--json", "--bench",
                  str(write_bench(tmp_path, physical_channels=["cDAQ9Mod1/ai0"])))
    fail = failed_check(json.loads(run.out))
    assert run.code == 1 and fail["name"] == "acq devices"
    assert fail["fix"] == ('[daq] physical_channels = ["cDAQ9Mod1/ai0"]: no device cDAQ9Mod1 — check the cable and '
                           "NI MAX, or the device name")
    run = run_cli(capsys, "selftest", "--fast", "--json", "--bench", str(write_bench(tmp_path, rate_hz=25000)))
    daq = next(c for c in json.loads(run.out)["checks"] if c["name"] == "DAQ")
    assert daq["status"] == "warn" and daq["values"]["rate_hz"] == 25600.0
    assert daq["fix"] == "[daq] rate_hz = 25000: the card runs 25600 Hz — state that rate"


@pytest.mark.parametrize("missing", ["driver", "package"])
def test_a_missing_ni_driver_or_package_gets_the_fix_that_installs_it(capsys: pytest.CaptureFixture[str],
                                                                      tmp_path: Path, hardware: StandinHardware,
                                                                      monkeypatch: pytest.MonkeyPatch,
                                                                      missing: str) -> None:
    """The fix said "no device Dev1 — check the cable and NI MAX": no device can be seen without the driver."""
    if missing == "driver":
        hardware.driver_installed = False
    else:
        def no_package() -> None:
            raise DeviceError("the nidaqmx Python package is missing (No module named 'nidaqmx') — pip install "
                              "nidaqmx, or use configs/benches/sim.toml")
        monkeypatch.setattr(acq.commissioning.devices, "import_nidaqmx", no_package)
    run = run_cli(capsys, "selftest", "--fast", "--json", "--bench",
                  str(write_bench(tmp_path, physical_channels=["Dev1/ai0"])))
    fail = failed_check(json.loads(run.out))
    assert run.code == 1 and fail["name"] == "acq devices"
    install = ("install the NI-DAQmx driver: python -m nidaqmx installdriver (Windows, Linux), or the NI-DAQmx runtime "
               "from ni.com; then acq devices lists the card — or use configs/benches/sim.toml")
    if missing == "driver":
        assert (fail["figure"], fail["fix"]) == (DRIVER_MISSING, install)
    else:
        assert fail["fix"] == f"pip install nidaqmx, then {install}"


FAST_RAMPS = """kind = "triangle"
top_speed_rpm = 1000
accel_time_s = 0.01
decel_time_s = 0.01
dwell_s = 0
duration_s = 5
"""


@pytest.mark.parametrize("sim_line", ["", "pole_pairs = 8"])
def test_ramps_too_fast_to_turn_the_motor_blame_no_bench_constant(
        capsys: pytest.CaptureFixture[str], tmp_path: Path, sim_line: str) -> None:
    """10 ms ramps to 1000 rpm: the motor swings ±0.08 rev (0.66 electrical turns) every 40 ms and the current's zero
    crossings follow the torque's sign changes. The half-periods read 2.99× pole_pairs·ω on the correct bench (3.70×
    with 8 true pole pairs), all alike because the motion repeats — that once read "check [encoder] counts_per_rev =
    44326". The crossings counted in the moves cannot reach such a ratio, so no constant is named: the record says
    why it cannot check them."""
    profile = tmp_path / "fast.toml"
    profile.write_text(FAST_RAMPS)
    strong_motor = "\n[limits]\nmax_speed_rpm = 3000.0\nmax_travel_deg = 360.0\nmax_torque_Nm = 200.0"  # 10 ms ramps: 110 N·m
    record = run_cli(capsys, "record", "--profile", str(profile), "--bench", str(bench_file(tmp_path, sim_line + strong_motor)),
                     "--fast", "--no-analyze", "--out", str(tmp_path / "s"))
    assert record.code == 0
    (session,) = (tmp_path / "s").glob("*.h5")
    quality = json.loads(run_cli(capsys, "analyze", str(session), "--json", "--no-report").out)["quality"]
    assert quality["verdict"] == "failed"
    assert not any("check [encoder]" in r or "check [motor]" in r for r in quality["reasons"]), quality["reasons"]
    doubt, *others = quality["reasons"]
    if not sim_line:
        assert doubt == (
            "pole_pairs and counts_per_rev cannot be checked on this record: the current's half-periods read 2.99× "
            "pole_pairs·ω, but its 480 zero crossings in the moves allow 0.00–2.38× — each of the 240 moves "
            "turns the motor only 0.16 rev (1.3 electrical half-turns at pole_pairs = 4) in 18 ms, so the current's "
            "zero crossings follow its torque's sign changes as much as the rotation; check the constants with acq "
            "selftest")
    else:
        assert re.fullmatch(r"pole_pairs and counts_per_rev cannot be checked on this record: the current's "
                            r"half-periods read 3\.\d\d× pole_pairs·ω, but its \d+ zero crossings in the moves allow "
                            r"0\.\d\d–[23]\.\d\d× — each of the 240 moves turns the motor only 0\.16 rev .*", doubt)
    assert others  # the identification's own findings stay beside it


def test_sync_cycles_count_across_a_wrap_with_the_frame_at_the_top_of_the_count_lost(tmp_path: Path) -> None:
    """The second read: the SYNC counter's wrap was taken from the largest counter seen, so with the frames of counter
    240 lost, 239 → 1 counted one cycle instead of two. The counter's own overflow is used (acq sets 240)."""
    import can

    from acq.commissioning.selftest_checks import sync_times
    from acq.config import load_bench

    drive = load_bench(Path(__file__).resolve().parent.parent / "configs/benches/sim_canopen.toml").drive
    counters = [237, 238, 239, 1, 2]  # 240 lost
    path = tmp_path / "s.blf"
    with can.BLFWriter(str(path)) as writer:
        for n, counter in enumerate(counters):
            writer.on_message_received(can.Message(timestamp=1.0 + 0.001 * n, arbitration_id=0x80, data=[counter],
                                                   is_extended_id=False))
    index, _ = sync_times(path, drive)
    assert index.tolist() == [0, 1, 2, 4, 5]


def _bursty_blf(path: Path, late_tpdo: bool) -> None:
    """A 1 ms bus as a loaded host logs it: the SYNC producer falls behind and catches up the SYNCs it owes, 7 at a
    time 150 µs apart every 7 ms (counter 1…240, 0x1019 = 240); each TPDO 0x181 70 µs after its SYNC, and with
    ``late_tpdo`` every 50th 1.5 ms after (after the next SYNC); the drive's heartbeat every 100 ms."""
    import can

    with can.BLFWriter(str(path)) as writer:
        for k in range(2100):
            t_sync = 10.0 + 0.007 * (k // 7) + 150e-6 * (k % 7)
            if k % 100 == 0:
                writer.on_message_received(can.Message(timestamp=10.0 + 0.001 * k, arbitration_id=0x701, data=[5],
                                                       is_extended_id=False))
            writer.on_message_received(can.Message(timestamp=t_sync, arbitration_id=0x80, data=[k % 240 + 1],
                                                   is_extended_id=False))
            delay = 1.5e-3 if late_tpdo and k % 50 == 0 else 70e-6
            writer.on_message_received(can.Message(timestamp=t_sync + delay, arbitration_id=0x181,
                                                   data=[0x37, 0x02, 0, 0, 0, 0], is_extended_id=False))


def test_the_sync_period_of_a_bursty_log_is_its_rate_and_a_listener_is_not_told_to_set_the_masters_period(
        tmp_path: Path) -> None:
    """A listening selftest printed "SYNC every 0.286 ms ± 1531 µs" on a 1 ms bus (the median and standard deviation
    of consecutive spacings, which bursts of caught-up SYNCs decide: here it read "SYNC every 0.150 ms ± 2080 µs") and advised raising [drive] period_s, the
    master's period. The period is now the slope of the stamps over the SYNC counter; a listener's fix names the
    master."""
    from acq.commissioning.selftest_checks import blf_check
    from acq.config import load_bench

    drive = load_bench(ROBOT.with_name("sim_robot_canopen.toml")).drive
    blf = tmp_path / "bursty.blf"
    _bursty_blf(blf, late_tpdo=False)
    check = blf_check(blf, drive, listens=True)
    assert (check.status, check.figure) == ("pass", "SYNC every 1.000 ms (2100 SYNC frames over 2.1 s), TPDO 70 µs "
                                                    "after SYNC (99 %: 70 µs), heartbeat every 100 ms")
    assert check.values["sync_period_s"] == pytest.approx(1e-3, rel=1e-4)
    late = tmp_path / "late.blf"
    _bursty_blf(late, late_tpdo=True)
    listening = blf_check(late, drive, listens=True)
    assert (listening.status, listening.fix) == (
        "warn", "TPDOs arrive later than one SYNC period (1.000 ms, the machine's master's): acq pairs a TPDO with the "
                "SYNC before it, so one after the next SYNC is placed a cycle late — the SYNC period, the bus load and "
                "the drive's TPDO timing are the master's to set, not acq's (it listens): have the machine's "
                "integrator check them")
    assert "period_s" not in listening.fix
    commanding = blf_check(late, drive, listens=False)
    assert commanding.fix == "TPDOs arrive later than one SYNC period: raise [drive] period_s = 0.001"


def test_a_listening_canopen_selftest_names_what_it_heard_and_verifies_no_profile(
        capsys: pytest.CaptureFixture[str]) -> None:
    """sim_robot_canopen.toml on python-can's virtual bus, real time: the drive line said "Profile Position verified"
    of a drive acq only listens to. The SYNC period is the master's 1 ms."""
    run = run_cli(capsys, "selftest", "--json", "--bench", str(ROBOT.with_name("sim_robot_canopen.toml")))
    doc = json.loads(run.out)
    by = {c["name"]: c for c in doc["checks"]}
    drive = by["drive"]["figure"]
    assert drive.startswith("CANopen node 1 on virtual:acq-sim-robot: canopen, period 1 ms, 131072 counts/rev; "
                            "listening: the machine's master's SYNC heard, TPDO 0x181 as [drive] tpdo_cob_id, "
                            "tpdo_mapping state it (not read back); no NMT, SYNC or motion sent, so no profile verified; "
                            "identity 0x1018 ")
    assert "Profile Position" not in drive
    frames = by["CAN frames"]
    assert frames["values"]["sync_period_s"] == pytest.approx(1e-3, rel=0.01)
    assert frames["figure"].startswith("SYNC every 1.0") or frames["figure"].startswith("SYNC every 0.99")
    assert "period_s" not in frames["fix"] and "period_s" not in by["SYNC jitter"]["fix"]


def test_the_drive_period_from_host_stamps_a_stalled_reader_delivers_in_bursts_is_the_drives(tmp_path: Path) -> None:
    """Under load a listening selftest failed "drive period 1.0103 ms on the host clock … set period_s to the drive's
    cycle" on a 1 ms bus: a reader held off up to 60 ms and then draining its queue tilts a least-squares line through
    every stamp. The slope under the least-delayed arrivals is the drive's period."""
    from acq.commissioning.selftest_checks import drive_period_check
    from acq.recording.reader import load
    from tests.test_one_phase_doubt import recorded_window

    session = load(recorded_window(tmp_path, ["i_a"], seed=0, elapsed_s=0.0, window_s=3.0))
    k = session.encoder.index
    rng = np.random.default_rng(1)
    # the reader wakes every 5 ms, or after a stall of up to 200 ms — more often as the record goes on (a host loaded
    # more and more) — and takes every frame sent by then
    wakes, t = [], 0.0
    while t < (k[-1] + 1) * 1e-3 + 0.2:
        t += rng.uniform(0.0, 0.2) if rng.random() < 0.8 * t / (k[-1] * 1e-3) else 0.005
        wakes.append(t)
    arrival_s = np.asarray(wakes)[np.searchsorted(wakes, k * 1e-3)]
    bursty = replace(session, encoder=replace(session.encoder, host_ns=np.rint(arrival_s * 1e9).astype(np.int64)))
    least_squares = np.polyfit(k - k[0], arrival_s - arrival_s[0], 1)[0]
    assert abs(least_squares / 1e-3 - 1.0) > 0.01  # what the check measured before: a "wrong" period_s (fail)
    check = drive_period_check(bursty)
    assert check.status == "pass", check.figure
    assert check.values["period_host_s"] == pytest.approx(1e-3, rel=1e-3)


def test_ctrl_c_during_the_identification_is_an_interruption_by_the_user_not_a_failed_bench(tmp_path: Path) -> None:
    """A real ``acq selftest`` on the simulated CANopen bench (real time), SIGINT as the terminal sends it once the
    identification's session has samples: exit 130 and one line saying the user stopped it — no ✗, no fix."""
    keep = tmp_path / "keep"
    proc = subprocess.Popen([sys.executable, "-m", "acq", "selftest", "--bench",
                             str(DEFAULT_BENCH.parent / "sim_canopen.toml"), "--keep", str(keep)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True,
                            env={**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parent.parent)})
    deadline = time.monotonic() + 120
    while not _has_samples([p for p in keep.glob("*.h5") if _tag(p) == "identification"]):
        assert proc.poll() is None and time.monotonic() < deadline, proc.communicate()
        time.sleep(0.05)
    os.killpg(proc.pid, signal.SIGINT)  # what the terminal does on Ctrl-C
    out, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, err
    assert err == ("acq: selftest interrupted during identification (interrupted by user (Ctrl-C)): no verdict on the "
                   "bench — run acq selftest again to check it\n")
    assert "✓ motion · phase order" in out and "✗" not in out and "identification ·" not in out


def _tag(path: Path) -> str | None:
    try:
        return load(path).meta.tags.get("selftest")
    except Exception:  # noqa: BLE001 - the file may be mid-creation
        return None


def _has_samples(paths: list[Path]) -> bool:
    try:
        return bool(paths) and load(paths[0]).current.sample_count > 0
    except Exception:  # noqa: BLE001 - the file may be mid-creation
        return False
