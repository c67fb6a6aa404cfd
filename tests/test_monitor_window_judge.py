"""One judgement of a monitor's window, by the monitor and by a later ``acq analyze`` (acq.offline.excitation_judge):
the same verdict, reasons and (absent) K, and the monitor's catalogue row left as it was (the trial: acq analyze of a
window the monitor filed ``not excited`` printed ``verdict failed``, K 1.039e+04, and replaced the row)."""

from __future__ import annotations

import json
import sqlite3
from pathlib import Path

import pytest

from tests.helpers import run_cli

ROBOT = Path(__file__).resolve().parents[1] / "configs" / "benches" / "sim_robot.toml"


def _rows(folder: Path) -> dict[int, dict[str, object]]:
    """Each window's catalogue rows by its number (from 0): verdict, K, reasons, error."""
    db = sqlite3.connect(folder / "catalogue.sqlite")
    rows = db.execute("SELECT s.tags_json, a.verdict, a.K_Nm_per_rad, a.reasons_json, a.error, s.path FROM sessions s "
                      "JOIN analyses a USING (session_key)").fetchall()
    db.close()
    out: dict[int, dict[str, object]] = {}
    for tags, verdict, k, reasons, error, path in rows:
        window = json.loads(tags)["monitor_window"]
        assert window not in out  # one row per window: a re-analysis replaces, never adds
        out[window] = {"verdict": verdict, "K": k, "reasons": json.loads(reasons), "error": error, "path": path}
    return out


def _monitor(capsys: pytest.CaptureFixture[str], out: Path, *args: str) -> dict[int, dict[str, object]]:
    run = run_cli(capsys, "monitor", "--bench", str(ROBOT), "--fast", "--out", str(out), *args)
    assert run.code == 0, run.err
    return _rows(out)


def test_acq_analyze_of_a_window_the_monitor_filed_not_excited_gives_the_same_and_keeps_its_row(
        capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    rows = _monitor(capsys, tmp_path / "m", "--window", "4", "--every", "5", "--for", "10s")
    first = rows[0]
    why = ["0 of the window's 5 moves put torque into 10…400 Hz beyond chance; time that does: 0 % of the window",
           "0 of 14 Welch segments excite — in-band S/N above 1.33, chance's 99 % point, the largest 1.00; the "
           "selection needs 2"]
    # the analysis' notes follow (the judgement dropped them: what the chain did is a fact, not advice on a fit)
    reasons = [*why, "note: clock: the angle stage failed (too little motion); using the frequency stage",
               "note: using 0.062–3.972 s, where both streams have data",
               "note: current: slow offset removed, moving by 962 mA (a drifting sensor offset, or torque held while "
               "the motor stood still: one phase cannot tell them apart)"]
    assert (first["verdict"], first["K"], first["reasons"], first["error"]) == ("not excited", None, reasons, None)
    run = run_cli(capsys, "analyze", str(first["path"]), "--json", "--no-report")
    assert run.code == 0, run.err
    doc = json.loads(run.out)
    assert (doc["quality"]["verdict"], doc["quality"]["reasons"]) == ("not excited", reasons)
    assert "K_Nm_per_rad" not in doc and "ci95" not in doc
    beside = json.loads(Path(str(first["path"])).with_suffix(".result.json").read_text())
    assert "K_Nm_per_rad" not in beside and beside["quality"]["verdict"] == "not excited"
    assert _rows(tmp_path / "m") == rows  # the row re-filed as it was; the other window's untouched
    table = run_cli(capsys, "analyze", str(first["path"]), "--no-report")
    assert table.code == 0 and "verdict not excited" in table.out and "1.039e+04" not in table.out
    view = run_cli(capsys, "view", str(first["path"]), "--screenshot", str(tmp_path / "v.png"))
    assert (view.code, view.err) == (2, f"acq: error: {first['path']}: not excited: {'; '.join(why)}\n")


def test_slow_moves_are_not_excited(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    """The trial's --window 1 --every 1 --for 10s: 2 windows "analysis failed" for the one-phase angle, a property
    of the motion (acq analyze of them: exit 2)."""
    rows = _monitor(capsys, tmp_path / "m", "--window", "1", "--every", "1", "--for", "10s")
    assert [rows[w]["error"] for w in sorted(rows)] == [None] * 10
    slow = ("the motor never turns half an electrical revolution within 20 ms, so the current's phase (θ_0) and DC "
            "cannot be estimated: the motor must run faster than 375 rpm for 20 ms at a time (4 pole pairs) — record "
            "while the machine runs fast moves of this joint")
    assert [w for w in sorted(rows) if rows[w]["reasons"] == [slow]] == [0, 2]
    assert all(rows[w]["verdict"] == "not excited" and rows[w]["K"] is None for w in (0, 2))
    run = run_cli(capsys, "analyze", str(rows[0]["path"]), "--json", "--no-report")  # was exit 2, the same error
    assert run.code == 0, run.err
    assert json.loads(run.out)["quality"] == {"verdict": "not excited", "reasons": [slow]}




def test_a_window_too_short_for_the_bands_welch_averages_says_so_instead_of_try_band(
        capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    """The trial's --window 1: a failed fit (K 822.5, truth 891) advised "another mode or a nonlinearity in the band;
    try --band" where 2 Welch segments of 0.5 s cannot tell a misfit from noise."""
    rows = _monitor(capsys, tmp_path / "m", "--window", "1", "--every", "1", "--for", "5s")
    assert (rows[4]["verdict"], round(rows[4]["K"], 1)) == ("failed", 822.5)
    assert rows[4]["reasons"][0] == (
        "the two-mass model misses |H| by 38 % RMS, but only 2 Welch segments of 0.5 s (the band's 2 Hz resolution) "
        "are averaged: with fewer than 4 the coherence cannot tell the band's limit 0.72 from chance (its 95 % point "
        "with 2: 0.95), so what noise explains is not known — the record is short for the band: it holds 2, and 4 "
        "need 1.25 s where both streams have data (a longer record: acq monitor --window, acq record's duration)")


def test_the_coherence_of_unrelated_signals_and_the_segments_a_limit_needs() -> None:
    from analysis.averages import chance_coherence, segments_to_tell

    assert [round(chance_coherence(n), 3) for n in (1, 2, 3, 4, 10)] == [1.0, 0.95, 0.776, 0.632, 0.283]
    assert (segments_to_tell(0.72), segments_to_tell(0.3), segments_to_tell(0.95)) == (4, 10, 3)


def test_a_passive_record_with_a_wrong_bench_constant_fails_on_it_and_is_not_called_not_excited(
        capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    """The robot of seed 5 excites the joint (``ok``, K within 2 % on a right bench: tests/test_monitor.py), but the
    motor has 8 pole pairs where the bench says 4: the torque read through the wrong electrical angle explains none
    of the speed (0 of 38 Welch segments excite, mean coherence 0.08). The analysis named the constant, and then both
    the segment selection and the judgement of a record without a profile filed it ``not excited`` with "record while
    the machine runs fast moves" — sending the technician to the robot program instead of the bench file."""
    bench = tmp_path / "bench.toml"
    bench.write_text(ROBOT.read_text().replace("seed = 0 ", "seed = 5 ") + "\npole_pairs = 8\n")  # [sim] is last
    run = run_cli(capsys, "record", "--bench", str(bench), "--duration", "10", "--fast", "--out", str(tmp_path / "s"))
    assert run.code == 0, run.err
    (result,) = (tmp_path / "s").glob("*.result.json")
    quality = json.loads(result.read_text())["quality"]
    fault = ("the current turns 2.03× faster than pole_pairs·ω (pole_pairs = 4, counts_per_rev = 131072): check "
             "[encoder] counts_per_rev = 65536")
    assert (quality["verdict"], quality["reasons"][0]) == ("failed", fault)  # was: not excited, "0 of the record's
    assert quality["faults"] == [fault]  # 13 moves put torque into 10…400 Hz beyond chance …", the fault left out
    assert quality["mean_coherence"] < 0.1  # weak: the judgement alone would call it not excited
    assert [r for r in quality["reasons"][1:] if not r.startswith("note: ")] == []  # the fault alone, then the notes
    assert "note: using 0.039–9.972 s, where both streams have data" in quality["reasons"]
    (session,) = (tmp_path / "s").glob("*.h5")
    again = run_cli(capsys, "analyze", str(session), "--json", "--no-report")
    assert again.code == 0 and json.loads(again.out)["quality"]["reasons"] == quality["reasons"]
