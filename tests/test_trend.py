"""Condition monitoring: the catalogue, batch re-analysis (process pool and Dask), and the stiffness trend.

A simulated wear series — one joint recorded six times while its simulated K steps 891 → 700 N·m/rad —
is analysed by the batch into a catalogue and trended.
"""

from __future__ import annotations

import json
import math
import os
import re
import shutil
import sqlite3
import subprocess
import sys
from dataclasses import replace
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import pytest

from acq.monitoring.batch import run_batch
from acq.monitoring.catalogue import Catalogue, Entry
from acq.monitoring.catalogue_schema import SCHEMA_VERSION
from acq.monitoring.session_search import find_sessions
from acq.monitoring.trend import EWMA_L, compute_trend
from analysis import AnalysisRequest
from tests.helpers import run_cli, seeded_profile

WEAR_K = (891.0, 853.0, 815.0, 777.0, 738.0, 700.0)
REQUEST = AnalysisRequest()
SIM_TOML = Path(__file__).parents[1] / "configs" / "benches" / "sim.toml"
ACQ = [sys.executable, "-m", "acq"]


def _bench_with_truth(folder: Path, k: float) -> Path:
    """A copy of the simulated bench whose [sim] (true) K is ``k``; the nominal K stays 891."""
    head, section, sim = SIM_TOML.read_text().partition("\n[sim]")
    path = folder / f"bench_K{k:g}.toml"
    path.write_text(head + section + re.sub(r"(?m)^K_Nm_per_rad = .*$", f"K_Nm_per_rad = {k}", sim))
    return path


@pytest.fixture(scope="module")
def wear(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Six 6 s sessions of joint1 (tagged pose=home), K stepping down, analysed into sessions/catalogue.sqlite.
    Session i runs the shipped profile with dither seed i: the same six motions in every run."""
    root = tmp_path_factory.mktemp("wear")
    out = root / "sessions"
    from acq.ui.cli import main

    for seed, k in enumerate(WEAR_K):
        with pytest.raises(SystemExit) as exc:
            main(["record", "--profile", str(seeded_profile(root, seed)), "--duration", "6", "--fast", "--no-analyze",
                  "--out", str(out), "--bench", str(_bench_with_truth(root, k)), "--tag", "pose=home",
                  "--tag", "payload_kg=2"])
        assert exc.value.code == 0
    with pytest.raises(SystemExit) as exc:
        main(["analyze", str(out), "--jobs", "2", "--no-report"])
    assert exc.value.code == 0
    return out


def _copy_sessions(src: Path, dst: Path, n: int) -> list[Path]:
    dst.mkdir()
    return [Path(shutil.copy2(p, dst)) for p in find_sessions(src)[0][:n]]


def test_wear_series_tracks_the_truth_and_alarms_at_the_first_drop_below_10_percent(
        wear: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    png = tmp_path / "trend.png"
    run = run_cli(capsys, "trend", str(wear), "--joint", "joint1", "--tag", "pose=home", "--json", "--png", str(png))
    assert run.code == 3, run.err
    doc = json.loads(run.out)
    points = doc["points"]
    assert [p["truth_K_Nm_per_rad"] for p in points] == list(WEAR_K)
    assert all(p["verdict"] == "ok" and p["tags"] == {"pose": "home", "payload_kg": 2.0} for p in points)
    for p in points:
        assert p["K_Nm_per_rad"] == pytest.approx(p["truth_K_Nm_per_rad"], rel=0.02)
    # The threshold rule compares the measured change K/K_baseline − 1 with −10 %. Where both sessions' intervals
    # hold their truth the measured change is within the truth's ± the two relative half widths (added: a bound, not
    # a quadrature sum, so that it holds for correlated errors too), and the rule must agree with the truth whenever
    # the truth is past −10 % by more than that; a session nearer the threshold may fall either way (815 N·m/rad is
    # −8.5 %, 1.5 points short: a K 1.6 % low there fired the alarm one session early in one run).
    half_pct = [100 * (p["K_ci95"][1] - p["K_ci95"][0]) / 2 / p["K_Nm_per_rad"] for p in points]
    clear_alarm, clear_none = [], []
    for i, p in enumerate(points[1:], start=1):
        margin_pct = 100 * (p["truth_K_Nm_per_rad"] / WEAR_K[0] - 1) + doc["threshold_pct"]
        if abs(margin_pct) > half_pct[0] + half_pct[i]:
            (clear_alarm if margin_pct < 0 else clear_none).append(i)
            assert ("threshold" in p["reason"]) == (margin_pct < 0), (i, p["K_Nm_per_rad"], p["K_ci95"])
    assert clear_alarm == [3, 4, 5] and clear_none[:1] == [1]  # 777 N·m/rad (−12.8 %) on alarm, 853 (−4.3 %) not
    first_truth_below = next(i for i, k in enumerate(WEAR_K) if k < 0.9 * WEAR_K[0])
    ewma = [i for i, p in enumerate(points) if "EWMA" in p["reason"]]
    assert ewma and ewma[0] <= first_truth_below and points[0]["state"] == "baseline"
    assert png.stat().st_size > 10_000 and png.read_bytes()[:4] == b"\x89PNG"
    assert run_cli(capsys, "trend", str(wear), "--joint", "joint1", "--tag", "pose=away").code == 2


def _entry(i: int, k: float, verdict: str = "ok", error: str | None = None, request: str = "{}") -> Entry:
    return Entry(f"id{i}", f"id{i}", "p.h5", "j", "2026-01-01T00:00:00+00:00", {}, verdict, ["coherence 0.2: weak"],
                 error, k, (k * 0.99, k * 1.01), 55.0, 102.0, request, "2026-01-02T00:00:00+00:00", None)


def test_a_comparison_never_takes_the_sessions_own_results_place_in_the_trend() -> None:
    """The trial: acq analyze S, then acq analyze S --paper — one request each, a tie that the latest (the paper's
    chain, K 1536) won, so the trend had no baseline. Comparisons count only where no session has its own result."""
    from analysis import AnalysisRequest

    own, paper = AnalysisRequest().key(), AnalysisRequest(pipeline="paper").key()
    band = AnalysisRequest(band_hz=(10.0, 150.0)).key()
    later = "2026-01-03T00:00:00+00:00"  # analysed after the session's own result: the tie's old winner
    entries = [_entry(0, 889.6, request=own), replace(_entry(0, 1535.7, verdict="failed", request=paper),
                                                      analyzed_utc=later)]
    trend = compute_trend("j", entries)
    assert [(p.entry.K_Nm_per_rad, p.state) for p in trend.points] == [(889.6, "baseline")]
    three = [e for i in range(3) for e in (_entry(i, 890.0 + i, request=own),
                                           replace(_entry(i, 1600.0 + i, verdict="failed", request=paper),
                                                   analyzed_utc=later),
                                           replace(_entry(i, 870.0, request=band), analyzed_utc=later))]
    assert [p.entry.K_Nm_per_rad for p in compute_trend("j", three).points] == [890.0, 891.0, 892.0]
    only_compared = [_entry(0, 880.0, request=band), _entry(1, 881.0, request=band)]
    assert [p.entry.K_Nm_per_rad for p in compute_trend("j", only_compared).points] == [880.0, 881.0]
    refused = AnalysisRequest(select_segments=False).key()  # a selection refused: a comparison (the second read)
    assert [p.entry.K_Nm_per_rad for p in compute_trend("j", [_entry(0, 890.0, request=own), replace(
        _entry(0, 1500.0, request=refused), analyzed_utc=later)]).points] == [890.0]
    monitor = AnalysisRequest(select_segments=True).key()  # a monitor's windows: their own results
    mixed = [_entry(0, 889.0, request=monitor), replace(_entry(0, 700.0, request=paper), analyzed_utc=later),
             _entry(1, 888.0, request=monitor)]
    assert [p.entry.K_Nm_per_rad for p in compute_trend("j", mixed).points] == [889.0, 888.0]


def test_a_monitor_running_on_across_an_upgrade_judges_its_new_windows_against_the_old_baseline() -> None:
    """The review: old windows filed under the old code's key (select_segments true, another code fingerprint), new
    ones under today's — compared by the full key the new were "other options" and skipped, the 21 % drop unseen."""
    import json as json_

    from analysis import AnalysisRequest

    old = json_.dumps({**json_.loads(AnalysisRequest(select_segments=True).key()), "analysis": "0123456789abcdef"},
                      sort_keys=True)
    new = AnalysisRequest().key()
    entries = [_entry(i, 890.0 + (i % 2), request=old) for i in range(8)]
    entries += [replace(_entry(i, 700.0, request=new), analyzed_utc="2026-01-03T00:00:00+00:00") for i in range(8, 13)]
    trend = compute_trend("j", entries, baseline_sessions=5)
    assert trend.alarm and [p.state for p in trend.points[8:]] == ["alarm"] * 5
    assert trend.baseline_K_Nm_per_rad == pytest.approx(890.4)


def test_trend_skips_sessions_not_ok_and_a_stable_joint_raises_no_alarm() -> None:
    ks = [891.0, 893.0, 889.0, 500.0, 890.0, 892.0, 888.0, 891.0, 890.5, 889.5]
    entries = [_entry(i, k, verdict="poor" if k == 500 else "ok") for i, k in enumerate(ks)]
    entries += [_entry(4, 700.0, request="other"), _entry(99, 0, error="x.h5: too short"),
                _entry(100, 600.0, request="other")]  # other options: not compared with the rest
    trend = compute_trend("j", entries, baseline_sessions=3)
    assert [p.state for p in trend.points][:4] == ["baseline"] * 3 + ["skipped"]
    assert trend.points[3].reason == "verdict poor: coherence 0.2: weak"
    assert trend.points[-2].reason == "analysis failed: x.h5: too short"
    assert trend.points[-1].state == "skipped" and "other options" in trend.points[-1].reason
    assert len(trend.points) == len(ks) + 2 and trend.points[4].entry.K_Nm_per_rad == 890.0
    assert not trend.alarm and all(p.state != "alarm" for p in trend.points)
    assert trend.baseline_K_Nm_per_rad == pytest.approx(891.0)


def test_rerun_skips_sessions_whose_result_is_current(wear: Path, tmp_path: Path) -> None:
    paths, _ = find_sessions(wear)
    with Catalogue(wear / "catalogue.sqlite") as catalogue:
        again = run_batch(paths, catalogue, REQUEST, jobs=1)
    assert not again.outcomes and again.skipped == paths
    copy = _copy_sessions(wear, tmp_path / "copy", 1)  # same file elsewhere: current; other options: not
    with Catalogue(wear / "catalogue.sqlite") as catalogue:
        assert run_batch(copy, catalogue, REQUEST, jobs=1).skipped == copy
        other = run_batch(copy, catalogue, replace(REQUEST, params="K"), jobs=1)
    assert len(other.outcomes) == 1 and other.outcomes[0].doc is not None


def test_results_of_other_analysis_code_are_not_current(wear: Path, tmp_path: Path,
                                                        monkeypatch: pytest.MonkeyPatch) -> None:
    import analysis.request

    copy = _copy_sessions(wear, tmp_path / "copy", 1)
    monkeypatch.setattr(analysis.request, "code_fingerprint", lambda: "changed-code")
    with Catalogue(wear / "catalogue.sqlite") as catalogue:
        rerun = run_batch(copy, catalogue, REQUEST, jobs=1)
    assert len(rerun.outcomes) == 1 and not rerun.skipped


def test_failed_session_is_recorded_and_the_batch_continues(wear: Path, tmp_path: Path,
                                                            capsys: pytest.CaptureFixture[str]) -> None:
    folder = tmp_path / "mixed"
    (good,) = _copy_sessions(wear, folder, 1)
    (folder / "2026-01-01T00-00-00_joint1.h5").write_bytes(b"not an HDF5 file")
    run = run_cli(capsys, "analyze", str(folder / "*.h5"), "--jobs", "2", "--no-report", "--json")
    assert run.code == 1, run.err
    outcomes = {Path(o["path"]).name: o for o in json.loads(run.out)}
    assert outcomes[good.name]["outcome"] == "analysed" and outcomes[good.name]["verdict"] == "ok"
    broken = outcomes["2026-01-01T00-00-00_joint1.h5"]
    assert broken["outcome"] == "failed" and "2026-01-01T00-00-00_joint1.h5" in broken["error"]
    with sqlite3.connect(folder / "catalogue.sqlite") as db:
        errors = db.execute("SELECT error FROM analyses ORDER BY error IS NULL").fetchall()
    assert len(errors) == 2 and errors[0][0] == broken["error"] and errors[1][0] is None


def test_dask_cluster_runs_the_same_batch(wear: Path, tmp_path: Path, catalogue_location: Path | str,
                                         capsys: pytest.CaptureFixture[str]) -> None:
    """acq analyze FOLDER --scheduler tcp://… --catalogue FILE|postgresql://… (the shared catalogue)."""
    distributed = pytest.importorskip("distributed")
    folder = tmp_path / "dask"
    _copy_sessions(wear, folder, 2)
    with distributed.LocalCluster(n_workers=1, threads_per_worker=2, processes=False, protocol="tcp",
                                  dashboard_address=None) as cluster:
        run = run_cli(capsys, "analyze", str(folder), "--scheduler", cluster.scheduler_address, "--catalogue",
                      str(catalogue_location), "--no-report", "--json")
    assert run.code == 0, run.err
    assert [o["outcome"] for o in json.loads(run.out)] == ["analysed"] * 2
    with Catalogue(catalogue_location) as catalogue:
        found = catalogue.entries("joint1")
    assert len(found) == 2
    with Catalogue(wear / "catalogue.sqlite") as pool_catalogue:
        pool = {e.session_id: e.K_Nm_per_rad for e in pool_catalogue.entries("joint1")
                if e.request_key == REQUEST.key()}
    for e in found:
        assert e.K_Nm_per_rad == pytest.approx(pool[e.session_id], rel=1e-9)


_WRITER = """
import sys
from acq.monitoring.catalogue import Catalogue, Outcome
with Catalogue(sys.argv[1]) as c:
    for i in range(200):
        c.record(Outcome(f"/x/{sys.argv[2]}-{i}.h5", "h", "r", {"session_id": f"{sys.argv[2]}-{i}", "joint": "j"},
                         None, "synthetic", 0.0))
"""


def test_two_processes_share_a_catalogue(wear: Path, tmp_path: Path) -> None:
    env = {**os.environ, "COLUMNS": "200"}
    fresh = tmp_path / "fresh.sqlite"  # both create and migrate it at once, then write 200 rows each
    writers = [subprocess.Popen([sys.executable, "-c", _WRITER, str(fresh), tag], env=env) for tag in "ab"]
    folder = tmp_path / "two"
    _copy_sessions(wear, folder, 2)
    analyses = [subprocess.Popen([*ACQ, "analyze", str(folder), "--jobs", "1", "--no-report"], env=env,
                                 stdout=subprocess.PIPE, stderr=subprocess.PIPE) for _ in range(2)]
    assert [w.wait(timeout=60) for w in writers] == [0, 0]
    assert [a.wait(timeout=120) for a in analyses] == [0, 0]
    for path, rows in ((fresh, 400), (folder / "catalogue.sqlite", 2)):
        with sqlite3.connect(path) as db:
            assert db.execute("PRAGMA integrity_check").fetchone()[0] == "ok"
            assert db.execute("SELECT COUNT(*) FROM analyses").fetchone()[0] == rows
            assert db.execute("SELECT COUNT(*) FROM sessions").fetchone()[0] == rows
            assert db.execute("PRAGMA user_version").fetchone()[0] == SCHEMA_VERSION


def test_view_shows_the_trend_window(wear: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")
    from acq.ui.qt_app import ensure_app
    from acq.monitoring.trend_catalogue import load_trend
    from acq.ui.trend_plot import trend_widget

    ensure_app(offscreen=True)
    widget = trend_widget(load_trend(wear, None, "joint1"))
    plots = [item for item in widget.findChildren(object) if type(item).__name__ == "GraphicsLayoutWidget"]
    assert len(plots) == 1
    assert plots[0].ci.getItem(4, 0).text == "alarm rules: acq's defaults"  # where the rules drawn came from
    given = [item for item in trend_widget(load_trend(wear, None, "joint1", threshold_pct=20.0)).findChildren(object)
             if type(item).__name__ == "GraphicsLayoutWidget"]
    assert given[0].ci.getItem(4, 0).text == ("alarm rules: --threshold-pct from the command line, the rest acq's "
                                              "defaults")
    png = tmp_path / "trend_view.png"
    run = run_cli(capsys, "view", "--trend", "joint1", str(wear), "--screenshot", str(png), "--size", "900x600")
    assert run.code == 0, run.err
    assert png.read_bytes()[:4] == b"\x89PNG" and png.stat().st_size > 10_000
    usage = run_cli(capsys, "view")
    assert usage.code == 2 and "give one or more SESSION files, or --trend JOINT [FOLDER]" in usage.err


def test_a_recorded_session_is_in_the_catalogue_at_once(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "sessions"
    rec = run_cli(capsys, "record", "--profile", str(seeded_profile(tmp_path)), "--duration", "4", "--fast", "--out",
                  str(out))
    assert rec.code == 0, rec.err
    trend = run_cli(capsys, "trend", str(out), "--joint", "joint1", "--json")
    assert trend.code == 0, trend.err
    (point,) = json.loads(trend.out)["points"]
    assert point["K_Nm_per_rad"] == pytest.approx(891.0, rel=0.02)
    batch = run_cli(capsys, "analyze", str(out), "--no-report")
    # nothing to do is one line, not a table header without rows
    assert (batch.code, batch.out) == (0, "nothing to analyse: 1 session already analysed (same file, same options) in "
                                          f"{out / 'catalogue.sqlite'}\n")


def test_the_trend_window_redraws_when_a_writer_adds_sessions(tmp_path: Path) -> None:
    os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")
    import functools

    from acq.monitoring.catalogue import Catalogue, Outcome
    from acq.ui.qt_app import ensure_app
    from acq.monitoring.trend_catalogue import load_trend
    from acq.ui.view import LiveTrend

    path = tmp_path / "catalogue.sqlite"

    def write(n: int, k: float) -> None:  # what a monitor's window outcome puts into the catalogue
        doc = {"options": {}, "K_Nm_per_rad": k, "ci95": {"K_Nm_per_rad": [k - 4, k + 4]},
               "quality": {"verdict": "ok", "reasons": []}}
        meta = {"session_id": f"w{n}", "joint": "joint1", "tags": {}, "created_utc": f"2026-11-29T10:0{n}:00+00:00"}
        with Catalogue(path) as c:
            c.record(Outcome(f"/m/w{n}.h5", f"h{n}", "r", meta, doc, None, 1.0))

    for n, k in enumerate((890.0, 891.0)):
        write(n, k)
    ensure_app(offscreen=True)
    load = functools.partial(load_trend, None, path, "joint1")
    live = LiveTrend(load, load(), refresh_s=3600)
    assert len(live.shown.points) == 2 and live.refresh() is False  # nothing new: the figure stays
    write(2, 700.0)
    assert live.refresh() is True and len(live.shown.points) == 3 and live.shown.alarm
    path.write_bytes(b"not a database")  # the catalogue unreadable: the last figure stays, the title says why
    assert live.refresh() is False and len(live.shown.points) == 3
    assert "not refreshed" in live.frame.windowTitle()


def test_the_trend_window_started_before_the_first_window_waits_for_it(tmp_path: Path,
                                                                      capsys: pytest.CaptureFixture[str]) -> None:
    """acq view --trend of a monitor's folder before the monitor had filed a window failed with "no sessions of joint
    joint1 (joints: none)"; README promised a window that redraws when the monitor has added windows."""
    os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")
    import functools

    from acq.monitoring.catalogue import Catalogue, Outcome
    from acq.monitoring.trend_catalogue import NoSessions, load_trend
    from acq.ui.qt_app import ensure_app
    from acq.ui.view import LiveTrend

    folder = tmp_path / "monitor"
    png = tmp_path / "waiting.png"
    run = run_cli(capsys, "view", "--trend", "joint1", str(folder), "--screenshot", str(png))
    # a screenshot (a script) of a trend with no window yet is an error, not a picture of "waiting" (the second read);
    # bad input (exit 2), as acq trend says it
    assert run.code == 2 and not png.exists()
    assert run.err == (f"acq: error: {folder / 'catalogue.sqlite'}: no catalogue — the folder {folder} does not "
                       "exist\n")

    def write(joint: str, n: int, k: float) -> None:
        doc = {"options": {}, "K_Nm_per_rad": k, "ci95": {"K_Nm_per_rad": [k - 4, k + 4]},
               "quality": {"verdict": "ok", "reasons": []}}
        meta = {"session_id": f"{joint}w{n}", "joint": joint, "tags": {"monitor_window": n},
                "created_utc": f"2026-11-29T10:0{n}:00+00:00"}
        with Catalogue(folder / "catalogue.sqlite") as c:
            c.record(Outcome(f"/m/w{n}.h5", f"h{joint}{n}", "r", meta, doc, None, 1.0))

    ensure_app(offscreen=True)
    load = functools.partial(load_trend, folder, None, "joint1")
    with pytest.raises(NoSessions) as missing:
        load()
    live = LiveTrend(load, missing.value, refresh_s=3600, joint="joint1")
    assert live.shown is None and live.frame.windowTitle() == "acq trend — joint1"
    assert live.refresh() is False
    assert live.waiting == f"waiting for the first window of joint1 in {folder / 'catalogue.sqlite'} …"
    write("joint2", 0, 500.0)  # the catalogue made, a window of another joint: still waiting, saying what there is
    assert live.refresh() is False
    assert live.waiting == (f"waiting for the first window of joint1 in {folder / 'catalogue.sqlite'} … "
                            "(joints so far: joint2)")
    write("joint1", 0, 890.0)
    assert live.refresh() is True and live.waiting is None
    assert [p.entry.K_Nm_per_rad for p in live.shown.points] == [890.0]  # type: ignore[union-attr]
    write("joint1", 1, 700.0)
    assert live.refresh() is True and len(live.shown.points) == 2 and live.shown.alarm  # type: ignore[union-attr]


def test_the_trend_window_of_a_joint_the_catalogue_does_not_have_is_one_line_not_a_wait(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A misspelt joint (or tag) in a catalogue that has sessions waited for ever: now one line naming the joint and
    the joints there, exit 2 (bad input, as acq trend). An empty catalogue (or none yet) is a monitor yet to file its first window: waited for."""
    os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")
    from acq.monitoring.catalogue import Outcome

    doc = {"options": {}, "K_Nm_per_rad": 890.0, "ci95": {"K_Nm_per_rad": [886.0, 894.0]},
           "quality": {"verdict": "ok", "reasons": []}}
    for joint in ("joint1", "joint2"):
        meta = {"session_id": joint, "joint": joint, "tags": {"monitor_window": 0},
                "created_utc": "2026-11-29T10:00:00+00:00"}
        with Catalogue(tmp_path / "catalogue.sqlite") as c:
            c.record(Outcome(f"/m/{joint}.h5", f"h{joint}", "r", meta, doc, None, 1.0))
    run = run_cli(capsys, "view", "--trend", "jiont1", str(tmp_path))
    assert (run.code, run.out) == (2, "")
    assert run.err == (f"acq: error: {tmp_path / 'catalogue.sqlite'}: no sessions of joint jiont1 (joints: joint1, "
                       "joint2)\n")
    trend = run_cli(capsys, "trend", str(tmp_path), "--joint", "jiont1")  # the same error, the same exit code
    assert (trend.code, trend.err) == (run.code, run.err)
    run = run_cli(capsys, "view", "--trend", "joint1", str(tmp_path), "--tag", "robot=r2")  # a tag no session has
    assert run.code == 2 and "no sessions of joint joint1 tagged robot=r2 (joints: joint1, joint2)" in run.err


def test_a_skipped_outlier_does_not_squash_the_trend_plot(tmp_path: Path) -> None:
    os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")
    import pyqtgraph as pg

    from acq.monitoring.catalogue import Catalogue, Outcome
    from acq.ui.qt_app import ensure_app
    from acq.monitoring.trend_catalogue import load_trend
    from acq.ui.trend_plot import trend_widget

    path = tmp_path / "catalogue.sqlite"
    with Catalogue(path) as c:  # five good windows, then one whose fit went wild (verdict poor: skipped)
        for n, (k, verdict) in enumerate([(890.0, "ok"), (891.0, "ok"), (889.0, "ok"), (860.0, "ok"),
                                          (13_000.0, "poor"), (850.0, "ok")]):
            doc = {"options": {}, "K_Nm_per_rad": k, "ci95": {"K_Nm_per_rad": [0.9 * k, 1.1 * k]},
                   "quality": {"verdict": verdict, "reasons": []}}
            meta = {"session_id": f"w{n}", "joint": "joint1", "tags": {}, "created_utc": f"2026-11-29T10:0{n}:00+00:00"}
            c.record(Outcome(f"/m/w{n}.h5", f"h{n}", "r", meta, doc, None, 1.0))
    ensure_app(offscreen=True)
    widget = trend_widget(load_trend(None, path, "joint1"))
    (layout,) = [item for item in widget.findChildren(object) if type(item).__name__ == "GraphicsLayoutWidget"]
    k_plot = next(item for item in layout.ci.items if isinstance(item, pg.PlotItem))
    low, high = k_plot.viewRange()[1]
    assert 700.0 < low < 850.0 and 890.0 < high < 1100.0  # the judged points and their limits, not 13 000
    legend = next(item for item in layout.ci.items if isinstance(item, pg.LegendItem))
    assert "1 skipped session(s) outside the range shown" in [label.text for _, label in legend.items]


_WINDOWS: list[Any] = []


def _monitor_trend(tmp_path: Path, windows: list[tuple[float | None, str]], every_s: float) -> tuple[Any, Any, Any]:
    """A monitor's catalogue of ``windows`` (K, verdict) ``every_s`` of machine time apart, drawn as the trend
    widget offscreen: its K plot, frequency plot and legend."""
    os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")
    import pyqtgraph as pg

    from acq.monitoring.catalogue import Catalogue, Outcome
    from acq.monitoring.trend_catalogue import load_trend
    from acq.ui.qt_app import ensure_app
    from acq.ui.trend_plot import trend_widget

    path = tmp_path / "catalogue.sqlite"
    with Catalogue(path) as c:
        for n, (k, verdict) in enumerate(windows):
            doc = {"options": {}, "K_Nm_per_rad": k, "ci95": {"K_Nm_per_rad": [None if k is None else 0.99 * k,
                                                                               None if k is None else 1.01 * k]},
                   "quality": {"verdict": verdict, "reasons": []}}
            meta = {"session_id": f"w{n}", "joint": "joint1", "created_utc": f"2026-11-29T10:00:0{n}+00:00",
                    "tags": {"monitor_window": n, "monitor_elapsed_s": every_s * n}}
            c.record(Outcome(f"/m/w{n}.h5", f"h{n}", "r", meta, doc, None, 1.0))
    ensure_app(offscreen=True)
    widget = trend_widget(load_trend(None, path, "joint1", baseline_sessions=3))
    _WINDOWS.append(widget)  # alive while its items are looked at (Qt deletes a dropped window's items)
    (layout,) = [item for item in widget.findChildren(object) if type(item).__name__ == "GraphicsLayoutWidget"]
    k_plot, f_plot = [item for item in layout.ci.items if isinstance(item, pg.PlotItem)]
    return k_plot, f_plot, next(item for item in layout.ci.items if isinstance(item, pg.LegendItem))


def test_a_monitor_trend_is_drawn_over_machine_time_and_shows_the_windows_without_K(tmp_path: Path) -> None:
    import pyqtgraph as pg

    # windows every 30 min of machine time; 2 not excited, 1 skipped with a wild K, the last one interrupted
    k_plot, f_plot, legend = _monitor_trend(tmp_path, [(890.0, "ok"), (None, "not excited"), (891.0, "ok"),
                                                       (889.0, "ok"), (13_000.0, "poor"), (None, "not excited"),
                                                       (850.0, "ok"), (None, "interrupted")], 1800.0)
    ticks = [label for _, label in f_plot.getAxis("bottom")._tickLevels[0]]
    assert ticks == ["0:00", "0:30", "1:00", "1:30", "2:00", "2:30", "3:00", "3:30"]
    assert f_plot.getAxis("bottom").labelText == "machine time at the window's start (h:min)"
    # each window without K counted under its own verdict (it said "3 not excited / failed" of 2 + 1 interrupted)
    assert "no K: 2 not excited · 1 interrupted" in [label.text for _, label in legend.items]
    (bars,) = [item for item in k_plot.items if isinstance(item, pg.ErrorBarItem)]
    assert sorted(bars.opts["x"]) == [0.0, 2.0, 3.0, 6.0]  # no bar for the skipped window 4



def test_a_short_monitor_run_is_labelled_in_seconds_not_in_hours(tmp_path: Path) -> None:
    """Windows 5 s apart read 0.0, 5.0, 10.0 s (in hours they all read 0.0 h)."""
    _, f_plot, _ = _monitor_trend(tmp_path, [(890.0, "ok")] * 3, 5.0)
    assert [label for _, label in f_plot.getAxis("bottom")._tickLevels[0]] == ["0.0", "5.0", "10.0"]
    assert f_plot.getAxis("bottom").labelText == "machine time at the window's start (s)"


def test_a_ten_minute_grid_reads_as_a_clock_not_as_rounded_decimal_hours(tmp_path: Path) -> None:
    """The third trial: windows every 10 min over 1 h read 0.2 h, 0.3 h, 0.5 h; every 15 s over 2.5 min read
    0.2 min, 0.5 min, 0.8 min."""
    import pyqtgraph as pg

    k_plot, f_plot, _ = _monitor_trend(tmp_path, [(890.0, "ok")] * 7, 600.0)
    assert [label for _, label in f_plot.getAxis("bottom")._tickLevels[0]] == [
        "0:00", "0:10", "0:20", "0:30", "0:40", "0:50", "1:00"]
    # the legend's "shaded: no alarm" is drawn between the baseline and the EWMA limit of the 4 judged windows (it
    # had no path to fill: one of its curves was drawn without a pen)
    (shade,) = [item for item in k_plot.items if isinstance(item, pg.FillBetweenItem)]
    assert shade.path().boundingRect().height() > 0
    (tmp_path / "b").mkdir()
    _, f_plot, _ = _monitor_trend(tmp_path / "b", [(890.0, "ok")] * 9, 15.0)
    assert [label for _, label in f_plot.getAxis("bottom")._tickLevels[0]] == [
        "0:00", "0:15", "0:30", "0:45", "1:00", "1:15", "1:30", "1:45", "2:00"]
    assert f_plot.getAxis("bottom").labelText == "machine time at the window's start (min:s)"


def _known_to(i: int, k: float, half_width_pct: float) -> Entry:
    return replace(_entry(i, k), K_ci95=(k * (1 - half_width_pct / 100), k * (1 + half_width_pct / 100)))


def test_the_ewma_limit_widens_for_a_session_known_less_well_than_the_baseline() -> None:
    """The third trial's fleet: with a one-window baseline (±0.6 %), a second window at −1.0 % known only to ±3.3 %
    raised an EWMA alarm — its limit came from the baseline's interval alone. Each session's own σ now enters the
    EWMA's variance (never below the baseline's); a window as well known as the baseline keeps the textbook limit."""
    base = _known_to(0, 891.0, 0.6)
    vague = compute_trend("j", [base, _known_to(1, 891.0 * 0.99, 3.3)], baseline_sessions=1).points[-1]
    assert (vague.state, vague.reason) == ("ok", "")
    sigma = 891.0 * 0.006 / 1.959964
    textbook = -100.0 * EWMA_L * sigma * math.sqrt(0.2 / 1.8 * (1 - 0.8 ** 2)) / 891.0
    sharp = compute_trend("j", [base, _known_to(1, 891.0 * 0.99, 0.6)], baseline_sessions=1).points[-1]
    assert sharp.ewma_limit_pct == pytest.approx(textbook, rel=1e-6)
    assert (sharp.state, sharp.reason) == ("alarm", "EWMA")  # the same −1.0 %, known to ±0.6 %: a real change
    # t ≥ 3 with every σ alike: the recursion is the textbook formula (at t = 1 any factor on the old variance passes)
    alike = compute_trend("j", [base] + [_known_to(i, 891.0, 0.6) for i in (1, 2, 3)], baseline_sessions=1).points
    assert alike[-1].ewma_limit_pct == pytest.approx(
        -100.0 * EWMA_L * sigma * math.sqrt(0.2 / 1.8 * (1 - 0.8 ** 6)) / 891.0, rel=1e-6)  # z rounded
    own = 891.0 * 0.99 * 0.033 / 1.959964  # its own σ: its interval's half width / z
    assert vague.ewma_limit_pct == pytest.approx(-100.0 * EWMA_L * 0.2 * own / 891.0, rel=1e-6)


#: The trial: a monitor started on a joint losing 20 % of K an hour, windows 10 min apart, each K known to ±0.6 %.
_SOFTENING = [834.5, 772.7, 678.0, 643.7, 624.7]


def test_a_baseline_learned_on_a_changing_joint_is_called_unstable() -> None:
    """Baseline 710.7 with σ 89.6 N·m/rad: the EWMA's limit far too wide, fleet "ok" beside ΔK −12.1 %, no word. The
    sessions' scatter against their own intervals (χ² at 0.1 %) says the joint changed while the baseline was learned;
    the alarm numbers of the trend stay as they were."""
    from acq.monitoring.fleet import fleet_json, fleet_status
    from acq.monitoring.trend import trend_json
    from acq.ui.display import trend_table
    from acq.ui.fleet_display import fleet_table

    entries = [_known_to(i, k, 0.6) for i, k in enumerate(_SOFTENING)]
    trend = compute_trend("j", entries, baseline_sessions=5)
    warning = ("baseline unstable: its 5 sessions scatter 12.6 % while each is known to within ±0.6 % — the joint "
               "changed while the baseline was learned, and its alarm limits are too wide; re-baseline: acq trend --baseline "
               "SESSION_ID judges against a session of the joint in a known state; a monitor learns a new baseline in "
               "a new --out")
    assert trend.baseline_warning == warning and trend_json(trend)["baseline_warning"] == warning
    assert (round(trend.baseline_K_Nm_per_rad, 1), round(trend.sigma_K_Nm_per_rad, 1)) == (710.7, 89.6)
    assert warning in trend_table(trend).caption
    now = datetime(2026, 1, 1, 1, tzinfo=UTC)
    (joint,) = fleet_status(entries, now=now, baseline_sessions=5)
    assert (joint.state, round(joint.change_pct, 1)) == ("baseline", -12.1)  # its latest K is a baseline session's
    assert fleet_json([joint])[0]["baseline_warning"] == warning
    table = fleet_table([joint], 7.0)
    assert f"j: {warning}" in table.caption
    assert table.columns[-1].cells == ["baseline · baseline unstable"]


def test_a_baseline_that_scatters_as_its_intervals_say_is_not_called_unstable() -> None:
    """Five windows of a stable simulated joint (sim_robot.toml, seed 5, windows 0…4 min; measured): K 890.9 ± 0.5 %,
    882.0 ± 3.3 %, 888.5 ± 0.9 %, 891.9 ± 1.1 %, 882.9 ± 3.2 % — χ² 3.3 on 4 degrees of freedom (chance 0.5); and a
    baseline of one session, or without intervals, is never judged."""
    stable = [(890.9, 0.54), (882.0, 3.25), (888.5, 0.87), (891.9, 1.14), (882.9, 3.24)]
    trend = compute_trend("j", [_known_to(i, k, w) for i, (k, w) in enumerate(stable)], baseline_sessions=5)
    assert trend.baseline_warning is None and trend.baseline_K_Nm_per_rad == pytest.approx(887.24)
    assert compute_trend("j", [_known_to(0, 834.5, 0.6), _known_to(1, 600.0, 0.6)]).baseline_warning is None
    no_intervals = [replace(_entry(i, k), K_ci95=(None, None)) for i, k in enumerate(_SOFTENING)]
    assert compute_trend("j", no_intervals, baseline_sessions=5).baseline_warning is None


def test_a_robot_tagged_007_before_and_after_the_upgrade_is_one_fleet_row() -> None:
    """The second read: earlier acq stored --tag robot=007 as 7.0, today's as "007" — fleet showed two rows, the new
    one learning a baseline of its own; one robot, one row, spelt as its latest session, judged on the old baseline."""
    from acq.monitoring.fleet import fleet_status

    old = [replace(_entry(i, 890.0 + (i % 2)), tags={"robot": 7.0}) for i in range(5)]
    new = [replace(_entry(i, 700.0), tags={"robot": "007"}) for i in range(5, 7)]
    (joint,) = fleet_status(old + new, now=datetime(2026, 1, 1, 1, tzinfo=UTC), baseline_sessions=5)
    assert (joint.robot, joint.state, len(joint.trend.points)) == ("007", "alarm", 7)
    assert joint.trend.baseline_K_Nm_per_rad == pytest.approx(890.4)


def test_the_state_before_the_baseline_is_learning_baseline_in_trend_and_fleet() -> None:
    """Monitor "learning baseline", trend "before baseline", fleet "no baseline": one name now (the JSON's values stay)."""
    from acq.monitoring.fleet import fleet_status
    from acq.ui.display import trend_table
    from acq.ui.fleet_display import fleet_table

    entries = [_entry(0, 890.0), _entry(1, 891.0)]
    trend = compute_trend("j", entries, baseline_sessions=5)
    assert [p.state for p in trend.points] == ["before baseline"] * 2
    assert trend_table(trend).columns[-1].cells == ["learning baseline"] * 2
    (joint,) = fleet_status(entries, now=datetime(2026, 1, 1, 1, tzinfo=UTC), baseline_sessions=5)
    assert joint.state == "no baseline" and fleet_table([joint], 7.0).columns[-1].cells == ["learning baseline"]
    pinned = compute_trend("j", [_entry(0, 880.0), _entry(1, 890.0)], baseline_id="id1")
    assert trend_table(pinned).columns[-1].cells[0] == "before baseline"  # before a pinned baseline: not learning
