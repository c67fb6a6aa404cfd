"""`acq analyze` and the analysis at the end of `acq record`, on session files from the simulated bench."""

from __future__ import annotations

import json
import re
import shutil
from pathlib import Path

import pytest

from acq.recording.reader import load
from acq.ui.values import format_value
from tests.helpers import read_only_view, run_cli, seeded_profile, tiny_read_only_folder

KEYS = {"K_Nm_per_rad", "Jm_kgm2", "Jl_kgm2", "C_Nms_per_rad", "ci95", "antiresonance_hz", "resonance_hz",
        "clock", "quality", "options"}


@pytest.fixture(scope="module")
def session_10s(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A 10 s recording of the default simulated bench (recorded, not analysed)."""
    out = tmp_path_factory.mktemp("sessions")
    from acq.ui.cli import main

    with pytest.raises(SystemExit) as exc:
        main(["record", "--profile", str(seeded_profile(out.parent)), "--fast", "--no-analyze", "--out", str(out)])
    assert exc.value.code == 0
    (path,) = out.glob("*.h5")
    return path


def test_analyze_json_has_documented_keys_and_finds_K(session_10s: Path, capsys: pytest.CaptureFixture[str]) -> None:
    earlier_png = session_10s.with_name(session_10s.stem + ".report.png")
    earlier_png.write_bytes(b"a picture of an earlier result")
    run = run_cli(capsys, "analyze", str(session_10s), "--json", "--no-report")
    assert run.code == 0, run.err
    assert not earlier_png.exists(), "a picture of another result must not stand beside this one"
    doc = json.loads(run.out)
    assert KEYS <= set(doc)
    # b_v's interval beside the four (README's key table: the second fit with the vibration's motor-side damping free)
    assert set(doc["ci95"]) == {"K_Nm_per_rad", "Jm_kgm2", "Jl_kgm2", "C_Nms_per_rad", "bv_Nms_per_rad"}
    bv_low, bv_high = doc["ci95"]["bv_Nms_per_rad"]
    assert 0.0 == bv_low <= doc["bv_Nms_per_rad"] <= bv_high  # passive (clipped at 0), and a healthy joint: 0 held
    assert set(doc["clock"]) == {"offset_s", "drift_ppm", "residual_s", "ambiguous_by_s", "failure"}
    assert {"verdict", "mean_coherence", "reasons"} <= set(doc["quality"])
    assert doc["quality"]["verdict"] == "ok"
    truth = doc["simulated_truth"]
    assert doc["K_Nm_per_rad"] == pytest.approx(truth["K_Nm_per_rad"], rel=0.01)
    assert doc["Jm_kgm2"] == pytest.approx(truth["Jm_kgm2"], rel=0.02)
    assert doc["Jl_kgm2"] == pytest.approx(truth["Jl_kgm2"], rel=0.02)
    assert doc["clock"]["offset_s"] == pytest.approx(truth["offset_s"], abs=50e-6)
    assert doc["clock"]["drift_ppm"] == pytest.approx(truth["drift_ppm"], abs=5.0)
    assert doc["options"]["torque_method"] == "encoder" and doc["options"]["params"] == "K,Jm,Jl"
    written = json.loads(session_10s.with_name(session_10s.stem + ".result.json").read_text())
    assert written["K_Nm_per_rad"] == doc["K_Nm_per_rad"]
    assert written["session"]["session_id"] == load(session_10s).attrs["session_id"]


def test_readme_documents_every_key_of_the_result_json(session_10s: Path, capsys: pytest.CaptureFixture[str]) -> None:
    doc = json.loads(run_cli(capsys, "analyze", str(session_10s), "--json", "--no-report").out)
    readme = (Path(__file__).resolve().parent.parent / "README.md").read_text()
    table = readme.split("### The result: `--json` and `<session>.result.json`")[1].split("\n\n")[1]
    documented = set(re.findall(r"`([A-Za-z_0-9.]+)`", table))
    keys = {k for k in doc if k not in ("clock", "quality")} | {f"{g}.{k}" for g in ("clock", "quality") for k in doc[g]}
    assert keys <= documented, keys - documented
    assert "motor-side" in table.split("`C_Nms_per_rad` |")[1].splitlines()[0]


def test_params_K_fixes_inertias_to_nominal(session_10s: Path, capsys: pytest.CaptureFixture[str]) -> None:
    run = run_cli(capsys, "analyze", str(session_10s), "--json", "--no-report", "--params", "K")
    doc = json.loads(run.out)
    assert doc["Jm_kgm2"] == 0.003027 and doc["Jl_kgm2"] == 0.00748
    assert doc["K_Nm_per_rad"] == pytest.approx(891.0, rel=0.01)


def test_papers_pipeline_is_worse_than_ours(session_10s: Path, capsys: pytest.CaptureFixture[str]) -> None:
    ours = json.loads(run_cli(capsys, "analyze", str(session_10s), "--json", "--no-report").out)
    paper = json.loads(run_cli(capsys, "analyze", str(session_10s), "--json", "--no-report", "--paper").out)
    assert paper["options"]["pipeline"] == "paper" and paper["options"]["torque_method"] == "hilbert"
    err = {name: abs(doc["Jm_kgm2"] / 0.003027 - 1) for name, doc in (("ours", ours), ("paper", paper))}
    assert err["paper"] > 5 * err["ours"]
    # the comparison sits beside the session's result, it does not replace it
    stem = session_10s.with_suffix("")
    assert json.loads(Path(f"{stem}.result.json").read_text())["K_Nm_per_rad"] == ours["K_Nm_per_rad"]
    assert json.loads(Path(f"{stem}.paper.result.json").read_text())["K_Nm_per_rad"] == paper["K_Nm_per_rad"]



def test_a_request_other_than_the_default_writes_beside_the_sessions_result(
        session_10s: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    """`--band` or `--params K` rewrote `<session>.result.json` (what `acq view` and the trend show): a technician
    experimenting lost the session's result. `--no-report` also removed the session's report PNG."""
    monkeypatch.chdir(tmp_path)
    shutil.copy(session_10s, "s.h5")
    assert run_cli(capsys, "analyze", "s.h5", "--json", "--wait-report").code == 0  # the session's result + report
    default_json, default_png = Path("s.result.json").read_bytes(), Path("s.report.png").read_bytes()
    run = run_cli(capsys, "analyze", "s.h5", "--band", "10,150", "--params", "K")
    assert run.code == 0, run.err
    assert "result: s.params-K.band-10-150.result.json (beside the session's result s.result.json, left as it was) " \
           "report: s.params-K.band-10-150.report.png" in " ".join(run.out.split())
    variant = json.loads(Path("s.params-K.band-10-150.result.json").read_text())
    assert variant["options"]["band_hz"] == [10.0, 150.0] and variant["options"]["params"] == "K"
    assert Path("s.params-K.band-10-150.report.png").stat().st_size > 0
    assert run_cli(capsys, "analyze", "s.h5", "--json", "--no-report", "--fit", "complex").code == 0
    assert Path("s.result.json").read_bytes() == default_json and Path("s.report.png").read_bytes() == default_png
    assert json.loads(default_json)["options"]["band_hz"] == [10.0, 400.0]
    assert sorted(p.name for p in tmp_path.glob("s.*")) == [
        "s.fit-complex.result.json", "s.h5", "s.params-K.band-10-150.report.png",
        "s.params-K.band-10-150.result.json", "s.report.png", "s.result.json"]


def test_an_option_that_names_the_default_writes_the_sessions_own_result(
        session_10s: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    """`--torque encoder` on a one-phase session and `--band 10,400` at a 1 kHz encoder are what the default does, but
    they wrote `s.torque-encoder.result.json` / `s.band-10-400.result.json` beside the session's result, filed in the
    catalogue as comparisons: a user who spells out the default gets the default's result."""
    from acq.monitoring.catalogue import Catalogue
    from analysis import AnalysisRequest

    monkeypatch.chdir(tmp_path)
    shutil.copy(session_10s, "s.h5")
    for options in (["--torque", "encoder"], ["--band", "10,400"], ["--torque", "encoder", "--band", "10,400.0"]):
        run = run_cli(capsys, "analyze", "s.h5", "--no-report", *options)
        assert run.code == 0, run.err
        assert "result: s.result.json" in run.out and "beside" not in run.out, options
        assert sorted(p.name for p in tmp_path.glob("s.*")) == ["s.h5", "s.result.json"], options
        assert json.loads(Path("s.result.json").read_text())["options"]["band_hz"] == [10.0, 400.0]
    with Catalogue(tmp_path / "catalogue.sqlite") as catalogue:
        assert {e.request_key for e in catalogue.entries("joint1")} == {AnalysisRequest().key()}
    assert run_cli(capsys, "analyze", "s.h5", "--no-report", "--band", "10,300").code == 0  # not the default band
    assert sorted(p.name for p in tmp_path.glob("s.*")) == ["s.band-10-300.result.json", "s.h5", "s.result.json"]


def test_variant_labels_name_what_differs_from_the_default_request() -> None:
    from acq.offline.analyze import output_paths
    from analysis import AnalysisRequest

    assert AnalysisRequest().variant_label() == ""
    assert AnalysisRequest(partial=True).variant_label() == ""  # a live session's result so far is its result
    assert AnalysisRequest(select_segments=False).variant_label() == "segments-off"  # the review: it overwrote
    assert AnalysisRequest(torque_method="park", params="K", fit="complex", band_hz=(12.5, 300.0),
                           align=False, segment_s=0.25).variant_label() == \
        "torque-park.params-K.fit-complex.band-12.5-300.no-align.segment-0.25s"
    assert AnalysisRequest(pipeline="paper", torque_method="park", align=False).variant_label() == "paper"
    assert output_paths(Path("/d/s.h5"), AnalysisRequest(pipeline="paper", band_hz=(10, 150)), Path("/r")) == (
        Path("/r/s.paper.band-10-150.result.json"), Path("/r/s.paper.band-10-150.report.png"))


def test_findings_of_a_chosen_chain_say_first_that_they_are_that_chains(
        session_10s: Path, capsys: pytest.CaptureFixture[str]) -> None:
    ours = json.loads(run_cli(capsys, "analyze", str(session_10s), "--json", "--no-report").out)["quality"]
    assert ours["verdict"] == "ok" and not any("findings" in r for r in ours["reasons"])
    first = {}
    for option in ("--paper", "--torque=hilbert"):
        quality = json.loads(run_cli(capsys, "analyze", str(session_10s), "--json", "--no-report", option).out)["quality"]
        assert quality["verdict"] != "ok"  # the Hilbert envelope's errors: weak coherence, misfit, wide intervals
        first[option] = quality["reasons"][0]
    assert first == {
        "--paper": "these findings are of the paper's chain (Hilbert torque, no clock alignment, linear interpolation, "
                   "uniform weights) and may be its own errors: acq analyze without --paper judges the session with "
                   "acq's chain",
        "--torque=hilbert": "these findings are of the chain chosen (--torque hilbert) and may be its own errors: acq "
                            "analyze without it judges the session with acq's default (encoder torque)"}


@pytest.mark.parametrize(("band", "message"), [
    ("500,10", "--band 500,10: must be LO,HI in Hz with 0 < LO < HI"),
    ("ten,400", "--band ten,400: must be LO,HI in Hz, e.g. 10,400"),
    ("300,600", "{path}: fit band 300…600 Hz ends above 400 Hz, the highest frequency the analysis can judge with "
                "this recording's 1000 Hz encoder (0.4 × its rate, the anti-alias filter's pass edge: above it the "
                "filter and the encoder's sampling, not the joint, shape the FRF); end the band at 400 Hz or below"),
    ("2,400", "{path}: fit band 2…400 Hz starts at or below 8 Hz: with 0.5 s Welch segments the fit takes each FRF bin "
              "as the joint averaged over ±8 Hz, which must stay above 0 Hz; start the band above 8 Hz"),
    ("100,101", "{path}: fit band 100…101 Hz holds 1 FRF bin (the 0.5 s segments give 2 Hz bins); need at least 12"),
])
def test_bad_band_is_one_line_exit_2(session_10s: Path, capsys: pytest.CaptureFixture[str], band: str,
                                     message: str) -> None:
    run = run_cli(capsys, "analyze", str(session_10s), "--band", band)
    assert run.code == 2
    assert run.err.strip() == f"acq: error: {message.format(name=session_10s.name, path=session_10s)}"


BAND_ABOVE_500_HZ_ENCODER = (
    "fit band 10…250 Hz ends above 200 Hz, the highest frequency the analysis can judge with this recording's 500 Hz "
    "encoder (0.4 × its rate, the anti-alias filter's pass edge: above it the filter and the encoder's sampling, not "
    "the joint, shape the FRF); end the band at 200 Hz or below")


@pytest.fixture(scope="module")
def session_500hz(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A 3 s recording of the simulated bench with its encoder read every 2 ms (500 Hz; not analysed)."""
    out = tmp_path_factory.mktemp("sessions_500hz")
    bench = out / "sim_500hz.toml"
    sim_toml = (Path(__file__).resolve().parent.parent / "configs" / "benches" / "sim.toml").read_text()
    bench.write_text(sim_toml.replace("period_s = 0.001", "period_s = 0.002"))
    from acq.ui.cli import main

    with pytest.raises(SystemExit) as exc:
        main(["record", "--profile", str(seeded_profile(bench.parent)), "--bench", str(bench), "--duration", "3",
              "--fast", "--no-analyze", "--out", str(out)])
    assert exc.value.code == 0
    (path,) = out.glob("*.h5")
    return path


def test_a_band_beyond_what_a_500_hz_encoder_supports_is_refused_and_one_up_to_its_limit_analysed(
        session_500hz: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """--band 10,250 on a 500 Hz encoder was analysed: the bins above 200 Hz, where the anti-alias filter has cut the
    torque, read as a −101 % misfit at 226…240 Hz, "a third mode" (1 of 4 ten-second sessions, seeds 0–3)."""
    run = run_cli(capsys, "analyze", str(session_500hz), "--band", "10,250", "--no-report")
    assert (run.code, run.out) == (2, "")
    assert run.err == f"acq: error: {session_500hz}: {BAND_ABOVE_500_HZ_ENCODER}\n"
    assert not session_500hz.with_name(session_500hz.stem + ".result.json").exists()
    at_limit = run_cli(capsys, "analyze", str(session_500hz), "--band", "10,200", "--no-report", "--json")
    assert at_limit.code == 0, at_limit.err
    assert json.loads(at_limit.out)["options"]["band_hz"] == [10.0, 200.0]


def test_a_batch_fails_only_the_session_whose_encoder_cannot_support_the_band(
        session_500hz: Path, session_10s: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """One band for a folder of benches with encoders of 1 kHz and 500 Hz: the 1 kHz session is analysed, the 500 Hz
    one fails with the reason, the batch ends with exit 1 instead of a traceback."""
    folder = tmp_path / "mixed"
    folder.mkdir()
    (folder / "a_1khz.h5").write_bytes(session_10s.read_bytes())
    (folder / "b_500hz.h5").write_bytes(session_500hz.read_bytes())
    batch = run_cli(capsys, "analyze", str(folder), "--band", "10,250", "--no-report", "--jobs", "1", "--json")
    assert batch.code == 1, batch.err
    outcomes = {Path(d["path"]).name: (d["outcome"], d["error"]) for d in json.loads(batch.out)}
    assert outcomes["a_1khz.h5"] == ("analysed", None)
    assert outcomes["b_500hz.h5"] == ("failed", f"{folder.resolve() / 'b_500hz.h5'}: {BAND_ABOVE_500_HZ_ENCODER}")


def test_record_refuses_a_duration_the_identification_cannot_use_and_the_one_it_names_works(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The pre-check counts what the analysis trims: --duration 0.8 passed the old check (0.75 s), recorded, then
    failed with `signals last 0.709 s; the FRF needs at least 0.750 s` (exit 1)."""
    need = ("the identification needs --duration 0.85 s or more (two 0.5 s Welch segments = 0.75 s, the streams' start "
            "offset 0.037 s ([sim] daq_offset_s) and 0.055 s the analysis trims at the ends); record longer, or add "
            "--no-analyze")
    for duration in ("0.5", "0.8"):  # refused before anything is recorded
        run = run_cli(capsys, "record", "--profile", "triangle_0.2s", "--duration", duration, "--fast", "--out",
                      str(tmp_path))
        assert (run.code, run.err) == (2, f"acq: error: --duration {duration}: {need}\n")
    assert not list(tmp_path.glob("*.h5"))
    run = run_cli(capsys, "record", "--profile", str(seeded_profile(tmp_path)), "--duration", "0.85", "--fast",
                  "--out", str(tmp_path / "named"))
    assert run.code == 0 and "acq:" not in run.err, run.err  # the duration named is enough: identified
    (result,) = (tmp_path / "named").glob("*.result.json")
    doc = json.loads(result.read_text())  # 0.85 s of a dithered motion (seed 0 here; K 10.5 % off in one run of a
    lo, hi = doc["ci95"]["K_Nm_per_rad"]  # random seed), so never as a confident wrong number
    assert abs(doc["K_Nm_per_rad"] / 891.0 - 1) < 0.2 and (lo <= 891.0 <= hi or doc["quality"]["verdict"] != "ok")
    # recorded without the identification, a session too short for it is refused by acq analyze in one line
    run = run_cli(capsys, "record", "--profile", "triangle_0.2s", "--duration", "0.76", "--fast", "--no-analyze",
                  "--out", str(tmp_path))
    assert run.code == 0
    (path,) = tmp_path.glob("*.h5")
    again = run_cli(capsys, "analyze", str(path))
    assert again.code == 2
    assert again.err.startswith(f"acq: error: {path}: signals last ")
    assert again.err.strip().endswith("the FRF needs at least 0.750 s (two 0.5 s Welch segments)")
    assert "Traceback" not in again.err


def _profile(folder: Path, name: str, top_speed_rpm: float, ramp_s: float) -> Path:
    path = folder / f"{name}.toml"
    path.write_text(f'kind = "triangle"\ntop_speed_rpm = {top_speed_rpm}\naccel_time_s = {ramp_s}\n'
                    f'decel_time_s = {ramp_s}\nduration_s = 2\n')
    return path


def test_a_profile_too_slow_or_too_short_to_find_the_currents_phase_is_refused_and_its_session_says_what_to_change(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    slow, tiny = _profile(tmp_path, "slow", 300, 0.2), _profile(tmp_path, "tiny", 1000, 0.002)
    run = run_cli(capsys, "record", "--profile", str(slow), "--fast", "--out", str(tmp_path / "s"))
    assert (run.code, run.err) == (2, f"acq: error: profile {slow}: top_speed_rpm = 300: the identification needs the "
                                      "motor faster than 375 rpm for 20 ms at a time (half an electrical revolution, 4 "
                                      "pole pairs) — raise top_speed_rpm, or add --no-analyze\n")
    run = run_cli(capsys, "record", "--profile", str(tiny), "--fast", "--out", str(tmp_path / "s"))
    assert (run.code, run.err) == (2, f"acq: error: profile {tiny}: the motor swings 12° per half-cycle (top_speed_rpm, "
                                      "accel_time_s, cruise_s, decel_time_s), the identification needs half an "
                                      "electrical revolution (45°, 4 pole pairs) — lengthen the ramps or raise "
                                      "top_speed_rpm, or add --no-analyze\n")
    assert not (tmp_path / "s").exists()
    run = run_cli(capsys, "record", "--profile", str(slow), "--fast", "--no-analyze", "--out", str(tmp_path / "s"))
    assert run.code == 0, run.err
    (path,) = (tmp_path / "s").glob("*.h5")
    run = run_cli(capsys, "analyze", str(path), "--no-report")
    assert (run.code, run.err) == (2, f"acq: error: {path}: the motor never turns half an electrical revolution within "
                                      "20 ms, so the current's phase (θ_0) and DC cannot be estimated: the motor must "
                                      "run faster than 375 rpm for 20 ms at a time (4 pole pairs) — raise the profile's "
                                      "top_speed_rpm, and lengthen accel_time_s and decel_time_s if the drive cannot "
                                      "follow them\n")


def test_several_sessions_as_the_shell_expands_a_glob_are_one_batch(session_10s: Path, tmp_path: Path,
                                                                     capsys: pytest.CaptureFixture[str]) -> None:
    """Before: `acq analyze par/*.h5` unquoted was 'Got unexpected extra argument (par/b.h5)', exit 2."""
    par, other = tmp_path / "par", tmp_path / "other"
    for folder, name in ((par, "a.h5"), (par, "b.h5"), (other, "c.h5")):
        folder.mkdir(exist_ok=True)
        (folder / name).write_bytes(session_10s.read_bytes())
    batch = run_cli(capsys, "analyze", str(par / "a.h5"), str(par / "b.h5"), "--no-report", "--jobs", "1", "--json")
    assert batch.code == 0, batch.err
    assert [(Path(d["path"]).name, d["outcome"]) for d in json.loads(batch.out)] == [("a.h5", "analysed"),
                                                                                   ("b.h5", "analysed")]
    assert (par / "catalogue.sqlite").is_file()  # in the sessions' folder, as for `acq analyze par`
    # sessions in different folders: no folder is theirs (the common one could be /: the review) — one line asking
    # for the catalogue; with it, a folder, a glob and a session named twice: each session once
    spread = run_cli(capsys, "analyze", str(par), str(other / "*.h5"), "--no-report")
    assert (spread.code, spread.err) == (2, f"acq: error: the sessions lie in 2 folders ({other}, {par}): give "
                                            "--catalogue FILE for the catalogue they go in\n")
    batch = run_cli(capsys, "analyze", str(par), str(other / "*.h5"), str(par / "a.h5"), "--no-report", "--jobs",
                    "1", "--json", "--catalogue", str(tmp_path / "both.sqlite"))
    assert batch.code == 0, batch.err
    assert sorted((Path(d["path"]).name, d["outcome"]) for d in json.loads(batch.out)) == [
        ("a.h5", "analysed"), ("b.h5", "analysed"), ("c.h5", "analysed")]
    assert (tmp_path / "both.sqlite").is_file() and not (tmp_path / "catalogue.sqlite").exists()
    missing = run_cli(capsys, "analyze", str(par / "a.h5"), str(par / "nope.h5"), "--no-report")
    assert (missing.code, missing.err) == (2, f"acq: error: {par / 'nope.h5'}: no such session file\n")
    none = run_cli(capsys, "analyze", "--no-report")
    assert (none.code, none.err) == (2, "acq: error: Missing argument 'SESSION...'.\n")


def test_missing_session_is_one_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    run = run_cli(capsys, "analyze", str(tmp_path / "nope.h5"))
    assert run.code == 2
    assert run.err.strip() == f"acq: error: {tmp_path / 'nope.h5'}: no such session file"


def test_a_session_with_an_empty_stream_is_one_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from acq.config import load_bench, load_profile
    from acq.recording.writer import SessionWriter
    from drivers.base import CurrentSourceInfo, DriveInfo

    path = tmp_path / "empty.h5"
    SessionWriter(path, bench=load_bench(), profile=load_profile("triangle_0.2s"),
                  current_info=CurrentSourceInfo(25600.0, ("i_a",), "daq"),
                  drive_info=DriveInfo(0.001, 131072, "sim", "drive_cycle", "drive"),
                  host_ns_at_start=0).finish("failed", "no device answered")
    for args in (("analyze", str(path)), ("export", str(path), "--csv", str(tmp_path / "csv"))):
        run = run_cli(capsys, *args)
        assert run.code == 2
        assert run.err.strip() == f"acq: error: {path}: /current holds no samples (status failed)"


def test_a_broken_result_file_is_one_line_for_view(session_10s: Path, tmp_path: Path,
                                                    capsys: pytest.CaptureFixture[str]) -> None:
    import shutil

    copy = Path(shutil.copy2(session_10s, tmp_path / "s.h5"))
    broken = tmp_path / "s.result.json"
    broken.write_text('{"K_Nm_per_rad": 8')
    run = run_cli(capsys, "view", str(copy), "--screenshot", str(tmp_path / "v.png"))
    assert run.code == 2
    assert run.err.strip() == f"acq: error: {broken}: not a result of acq analyze (run acq analyze {copy} to redo it)"


def test_piped_result_tables_fit_80_columns(session_10s: Path, capsys: pytest.CaptureFixture[str],
                                            monkeypatch: pytest.MonkeyPatch) -> None:
    import acq.ui.analyze_cli

    monkeypatch.setattr(acq.ui.analyze_cli.out, "width", 80)  # what a pipe or an 80-column terminal gives
    shown = {}
    for option in ("", "--params=K", "--paper"):
        run = run_cli(capsys, "analyze", str(session_10s), "--no-report", *([option] if option else []))
        assert run.code == 0, run.err
        assert not re.search(r"…\s*(│|┃|$)", run.out, re.M), "a cell cut to …"
        assert max(len(line) for line in run.out.splitlines()) <= 80
        shown[option] = run.out
    assert "fixed (nominal)" not in shown[""] and shown["--params=K"].count("fixed (nominal)") == 2
    assert "0.003027 – 0.003027" not in shown["--params=K"]
    assert re.search(r"clock offset \[ms\] +│ +0\.000 │ +│ +37 │ -3[67]\.\d{3} ms", shown["--paper"])


def test_a_report_that_cannot_be_drawn_is_a_note_not_a_failed_identification(
        session_10s: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch) -> None:
    import shutil
    import sys

    from acq.monitoring.session_outcome import analyze_one
    from acq.monitoring.catalogue import Catalogue
    from analysis import AnalysisRequest
    from acq.ui.report_png import draw_report

    copy = Path(shutil.copy2(session_10s, tmp_path / "s.h5"))
    expected = json.loads(run_cli(capsys, "analyze", str(session_10s), "--json", "--no-report").out)
    monkeypatch.delitem(sys.modules, "acq.ui.report_view", raising=False)
    monkeypatch.setitem(sys.modules, "pyqtgraph", None)  # a headless worker without the Qt libraries
    run = run_cli(capsys, "analyze", str(copy))
    assert run.code == 0, run.err
    why = "ModuleNotFoundError: import of pyqtgraph halted; None in sys.modules"
    png, result = tmp_path / "s.report.png", tmp_path / "s.result.json"
    line = f"acq: {png}: report not drawn ({why}); the result stands in {result}"
    assert run.err.splitlines().count(line) == 1
    doc = json.loads(result.read_text())
    assert doc["quality"]["verdict"] == expected["quality"]["verdict"] == "ok"
    assert doc["K_Nm_per_rad"] == expected["K_Nm_per_rad"]
    assert doc["quality"]["reasons"][-1] == f"note: report not drawn: {why}"
    assert not png.exists() and "report:" not in run.out
    with Catalogue(tmp_path / "catalogue.sqlite") as catalogue:
        (entry,) = catalogue.entries()
    assert entry.verdict == "ok" and entry.error is None and entry.K_Nm_per_rad == expected["K_Nm_per_rad"]
    outcome = analyze_one(str(copy), "sha", AnalysisRequest(), draw_report)  # what a batch worker does
    assert outcome.error is None and outcome.doc is not None and outcome.doc["quality"]["verdict"] == "ok"
    assert outcome.doc["quality"]["reasons"][-1].startswith("note: report not drawn: ModuleNotFoundError")


def test_help_and_a_mistyped_path_load_no_numerical_library() -> None:
    """`acq --help` lists every command with its own short help, and `acq analyze missing.h5` says so in one line,
    in a process that never imported numpy, scipy, h5py, pydantic or Qt (what made them take 1.1 s)."""
    import importlib
    import subprocess
    import sys

    from acq.ui.cli import LAZY_COMMANDS

    for name, (module, attribute, short_help) in LAZY_COMMANDS.items():
        command = getattr(importlib.import_module(module), attribute)
        assert command.name == name and command.get_short_help_str(limit=10_000) == short_help
    # what was loaded, said as acq exits: at once (os._exit) after a command, else by SystemExit
    probe = ("import os, sys; from acq.ui.cli import main\nleave = os._exit\n"
             "def said(code):\n"
             "    heavy = sorted({'numpy', 'scipy', 'h5py', 'pydantic', 'PySide6'} & set(sys.modules))\n"
             "    print('loaded:', heavy, 'exit:', code, file=sys.stderr, flush=True)\n    leave(0)\n"
             "os._exit = said\n"
             "try:\n    main(sys.argv[1:])\nexcept SystemExit as e:\n    said(e.code)")
    helped = subprocess.run([sys.executable, "-c", probe, "--help"], capture_output=True, text=True, timeout=60)
    assert helped.stderr.strip() == "loaded: [] exit: 0"
    listed = dict(re.findall(r"^  (\w+) +(\S.*)$", helped.stdout.split("Commands:")[1], re.M))
    assert sorted(listed) == sorted(LAZY_COMMANDS) == ["analyze", "check", "devices", "export", "fleet", "import", "info",
                                                       "monitor", "record", "selftest", "trend", "view"]
    assert listed["devices"] == "List NI devices and AI channels, CAN interfaces, serial ports..."
    missing = subprocess.run([sys.executable, "-c", probe, "analyze", "missing.h5"], capture_output=True, text=True,
                             timeout=60)
    assert missing.stderr.splitlines() == ["acq: error: missing.h5: no such session file", "loaded: [] exit: 2"]


def test_a_read_only_session_folder_shows_the_result_fails_the_write_and_result_dir_writes_elsewhere(
        session_10s: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """It said only `read-only file system: ro/s.result.json`, exit 1, no numbers."""
    archive = tmp_path / "archive"
    archive.mkdir()
    for name in ("a.h5", "b.h5"):
        (archive / name).write_bytes(session_10s.read_bytes())
    with read_only_view(archive) as ro:
        not_saved = f"acq: error: read-only file system: {ro}/a.result.json — the result above is not saved " \
                    "(--result-dir DIR writes it elsewhere)\n"
        table = run_cli(capsys, "analyze", str(ro / "a.h5"), "--no-report")
        assert (table.code, table.err) == (1, not_saved)
        as_json = run_cli(capsys, "analyze", str(ro / "a.h5"), "--no-report", "--json")
        assert (as_json.code, as_json.err) == (1, not_saved)
        doc = json.loads(as_json.out)
        assert abs(doc["K_Nm_per_rad"] / 891.0 - 1) < 0.02
        # the same numbers, as the table writes them (4 significant digits: 889.96 is "890", not "890.0")
        assert f" {format_value(doc['K_Nm_per_rad'])} " in table.out.split("K [N·m/rad]")[1].split("\n")[0]
        elsewhere = tmp_path / "results"
        saved = run_cli(capsys, "analyze", str(ro / "a.h5"), "--no-report", "--json", "--result-dir", str(elsewhere))
        assert saved.code == 0, saved.err
        assert json.loads((elsewhere / "a.result.json").read_text())["K_Nm_per_rad"] == doc["K_Nm_per_rad"]
        assert (elsewhere / "catalogue.sqlite").exists()  # the default catalogue goes with the results
        # a batch of the read-only archive, its catalogue elsewhere: every result fails to be written …
        catalogue = tmp_path / "cat.sqlite"
        batch = run_cli(capsys, "analyze", str(ro), "--catalogue", str(catalogue), "--no-report", "--jobs", "1",
                        "--json")
        assert batch.code == 1
        assert [(d["outcome"], d["error"]) for d in json.loads(batch.out)] == [
            ("failed", f"read-only file system: {ro}/{n}.result.json") for n in ("a", "b")]
        # … and with --result-dir it works
        batch = run_cli(capsys, "analyze", str(ro), "--catalogue", str(catalogue), "--no-report", "--jobs", "1",
                        "--json", "--result-dir", str(tmp_path / "batch_results"))
        assert batch.code == 0, batch.err
        assert [d["outcome"] for d in json.loads(batch.out)] == ["analysed", "analysed"]
        assert sorted(p.name for p in (tmp_path / "batch_results").iterdir()) == ["a.result.json", "b.result.json"]
        assert sorted(p.name for p in ro.iterdir()) == ["a.h5", "b.h5"]


def test_a_result_dir_on_a_tiny_read_only_mount_is_read_only_not_full(
        session_10s: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """It said "disk full: <dir>/<session>.report.png": the room for the report (4 MiB) was checked before whether the
    folder may be written at all, and a 1 MiB read-only mount has no room either. Now the cause, naming the file."""
    with tiny_read_only_folder(tmp_path / "ro") as (ro, cause):
        for json_flag in ((), ("--json",)):
            run = run_cli(capsys, "analyze", str(session_10s), "--result-dir", str(ro), *json_flag)
            assert (run.code, run.err) == (1, f"acq: error: {cause}: {ro / session_10s.stem}.result.json — the result "
                                              "above is not saved (give --result-dir a folder acq may write)\n")
        # a batch: the catalogue that goes with the results cannot be made there either (the trial: it suggested
        # the --result-dir already given)
        run = run_cli(capsys, "analyze", str(session_10s.parent), "--result-dir", str(ro), "--no-report")
        assert (run.code, run.err) == (1, f"acq: error: {cause}: {ro / 'catalogue.sqlite'} (no catalogue can be made "
                                          "there) — give --result-dir a folder acq may write\n")
        assert list(ro.iterdir()) == []


def test_a_result_dir_that_cannot_be_made_is_bad_input(session_10s: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The trial: `--result-dir /proc/x` said "folder vanished" (exit 1) of a folder that never was."""
    run = run_cli(capsys, "analyze", str(session_10s), "--no-report", "--result-dir", "/proc/acq-none/x")
    assert run.code == 2
    assert run.err == ("acq: error: --result-dir /proc/acq-none/x: cannot make a folder there (no such file or "
                       "directory)\n")
