"""``acq fleet`` on a catalogue of three joints of two robots (one in alarm, one stale, one ok) plus a robot of
another site, on both catalogue back ends."""

from __future__ import annotations

import io
import re
import json
from dataclasses import replace
from datetime import UTC, datetime, timedelta
from pathlib import Path

import pytest
from rich.console import Console

from acq.monitoring.catalogue import Catalogue, Outcome
from acq.monitoring.fleet import load_fleet
from acq.ui.fleet_display import fleet_table
from tests.helpers import run_cli

#: (robot, joint, site, hours before now, K N·m/rad or None for a failed analysis)
SESSIONS = [("r1", "j1", "A", h, k) for h, k in ((50, 900.0), (40, 901.0), (30, 899.0), (3, 760.0))] + \
           [("r1", "j2", "A", h, k) for h, k in ((260, 500.0), (250, 502.0), (240, 498.0))] + \
           [("r2", "j1", "A", h, k) for h, k in ((30, 1000.0), (20, 1003.0), (10, 998.0), (5, None), (2, 1001.0))] + \
           [("r3", "j1", "B", h, k) for h, k in ((30, 700.0), (1, 500.0))]


def _fill(location: Path | str) -> None:
    now = datetime.now(UTC)
    with Catalogue(location) as c:
        for n, (robot, joint, site, hours, k) in enumerate(SESSIONS):
            doc = None if k is None else {"options": {}, "K_Nm_per_rad": k, "ci95": {"K_Nm_per_rad": [k - 5, k + 5]},
                                          "quality": {"verdict": "ok", "reasons": []}}
            meta = {"session_id": f"s{n:02d}", "joint": joint, "tags": {"robot": robot, "site": site},
                    "created_utc": (now - timedelta(hours=hours)).isoformat(timespec="seconds")}
            c.record(Outcome(f"/x/s{n:02d}.h5", f"h{n}", "r", meta, doc, None if k else "s.h5: too short", 1.0))


def test_fleet_lists_joints_worst_first_and_exits_3_on_an_alarm(catalogue_location: Path | str, tmp_path: Path,
                                                                capsys: pytest.CaptureFixture[str]) -> None:
    _fill(catalogue_location)
    png = tmp_path / "fleet.png"
    run = run_cli(capsys, "fleet", "--catalogue", str(catalogue_location), "--tag", "site=A", "--json",
                  "--png", str(png))
    assert run.code == 3, run.err
    joints = json.loads(run.out)
    assert [(j["robot"], j["joint"], j["state"]) for j in joints] == [
        ("r1", "j1", "alarm"), ("r1", "j2", "stale"), ("r2", "j1", "ok")]
    alarm, stale, ok = joints
    assert alarm["change_pct"] == pytest.approx(100 * (760 / 900 - 1)) and alarm["K_ci95"] == [755.0, 765.0]
    assert alarm["reason"].startswith("threshold") and alarm["baseline_K_Nm_per_rad"] == 900.0
    assert (alarm["analysed_last_day"], alarm["excited_last_day"]) == (1, 1)
    assert stale["change_pct"] == pytest.approx(100 * (498 / 500 - 1)) and stale["analysed_last_day"] == 0
    assert ok["K_Nm_per_rad"] == 1001.0 and ok["change_pct"] == pytest.approx(0.1)
    assert (ok["analysed_last_day"], ok["excited_last_day"]) == (4, 3)  # 20, 10, 5 (failed), 2 h ago
    assert png.read_bytes()[:4] == b"\x89PNG" and png.stat().st_size > 10_000


def test_fleet_table_and_the_stale_limit(catalogue_location: Path | str, capsys: pytest.CaptureFixture[str],
                                         monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("COLUMNS", "250")  # one line per row
    _fill(catalogue_location)
    run = run_cli(capsys, "fleet", "--catalogue", str(catalogue_location), "--stale-days", "20")
    assert run.code == 3, run.err
    rows = [line for line in run.out.splitlines() if "│" in line]
    assert [r.split("│")[0].strip() for r in rows] == ["r3/j1", "r1/j1", "r1/j2", "r2/j1"]
    assert "-28.6" in rows[0] and "495.0–505.0" in rows[0] and "ALARM threshold" in rows[0]
    assert "-0.4" in rows[2] and rows[2].rstrip().endswith("ok")  # not stale within 20 days; largest drop first
    quiet = run_cli(capsys, "fleet", "--catalogue", str(catalogue_location), "--tag", "robot=r2")
    assert quiet.code == 0 and re.search(r"fleet — 1 joint *\n", quiet.out)
    none = run_cli(capsys, "fleet", "--catalogue", str(catalogue_location), "--tag", "site=C")
    assert none.code == 2 and none.err.strip().endswith(": no sessions of any joint tagged site=C")


def test_fleet_table_shows_every_value_at_80_columns(catalogue_location: Path | str,
                                                     capsys: pytest.CaptureFixture[str],
                                                     monkeypatch: pytest.MonkeyPatch) -> None:
    _fill(catalogue_location)
    statuses = load_fleet((), [catalogue_location], now=datetime.now(UTC), stale_days=7.0)
    console = Console(width=80, file=io.StringIO(), color_system=None)
    console.print(fleet_table(statuses, stale_days=7.0))
    monkeypatch.setenv("COLUMNS", "80")
    run = run_cli(capsys, "fleet", "--catalogue", str(catalogue_location))
    assert run.code == 3, run.err
    assert run.out == console.file.getvalue()  # type: ignore[attr-defined]
    assert "…" not in run.out and max(len(line) for line in run.out.splitlines()) <= 80
    times = {f"{s.robot}/{s.joint}": s.last_session_utc.strftime("%m-%d %H:%M") for s in statuses
             if s.last_session_utc is not None}
    rows = {line.split("│")[0].strip(): [cell.strip() for cell in line.split("│")[1:]]
            for line in run.out.splitlines() if "│" in line and line.split("│")[0].strip()}
    assert rows == {"r3/j1": ["500.0", "± 1.0", "-28.6", "700.0", times["r3/j1"], "1/1", "ALARM"],
                    "r1/j1": ["760.0", "± 0.7", "-15.6", "900.0", times["r1/j1"], "1/1", "ALARM"],
                    "r1/j2": ["498.0", "± 1.0", "-0.4", "500.0", times["r1/j2"], "0/0", "stale"],
                    "r2/j1": ["1001.0", "± 0.5", "+0.1", "1000.0", times["r2/j1"], "3/4", "ok"]}
    assert run.out.count("threshold") == 2  # "ALARM threshold + EWMA" wrapped at spaces, in both alarm rows


def test_fleet_narrower_than_its_narrowest_table_prints_one_block_of_lines_per_joint(
        catalogue_location: Path | str, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch) -> None:
    """At 40 columns it squeezed its table until names and numbers folded inside themselves ("robo" over "join",
    "1001." over "0"); below the narrowest layout (60 columns here) each joint is now a block of "header: value"
    lines, every value whole, nothing left out."""
    _fill(catalogue_location)
    statuses = load_fleet((), [catalogue_location], now=datetime.now(UTC), stale_days=7.0)
    times = {f"{s.robot}/{s.joint}": s.last_session_utc.strftime("%m-%d %H:%M") for s in statuses
             if s.last_session_utc is not None}
    monkeypatch.setenv("COLUMNS", "40")
    run = run_cli(capsys, "fleet", "--catalogue", str(catalogue_location))
    assert run.code == 3, run.err
    lines = run.out.splitlines()
    assert "│" not in run.out and "not shown at this width" not in run.out and max(map(len, lines)) <= 40
    assert lines[:3] == ["fleet — 4 joints  2 in ALARM", "", "r3/j1"]
    year = {s.last_session_utc.year for s in statuses if s.last_session_utc is not None}.pop()
    assert [line.split(": ", 1)[0] for line in lines[3:10]] == [  # the time in the narrow form: its wide one wraps
        "  K N·m/rad", "  95 % interval N·m/rad", "  ΔK %", "  baseline N·m/rad", f"  last (UTC {year})",
        "  24 h ok/all", "  state"]
    blocks = {lines[i - 1]: [line.split(": ", 1)[1] for line in lines[i:i + 7]]
              for i, line in enumerate(lines) if line.startswith("  K N·m/rad: ")}
    assert blocks == {"r3/j1": ["500.0", "495.0–505.0", "-28.6", "700.0", times["r3/j1"], "1/1", "ALARM threshold + EWMA"],
                      "r1/j1": ["760.0", "755.0–765.0", "-15.6", "900.0", times["r1/j1"], "1/1", "ALARM threshold + EWMA"],
                      "r1/j2": ["498.0", "493.0–503.0", "-0.4", "500.0", times["r1/j2"], "0/0", "stale"],
                      "r2/j1": ["1001.0", "996.0–1006.0", "+0.1", "1000.0", times["r2/j1"], "3/4", "ok"]}
    monkeypatch.setenv("COLUMNS", "60")  # the narrowest table still fits: a table
    assert "┃" in run_cli(capsys, "fleet", "--catalogue", str(catalogue_location)).out


def test_fleet_of_several_sources_at_80_columns_leaves_the_baseline_out_and_breaks_no_header(
        catalogue_location: Path | str) -> None:
    """acq fleet DIR sessions at 80 columns broke its headers inside words: "sour|ce", "sta|te", "bas|eli|ne"."""
    _fill(catalogue_location)
    statuses = [replace(s, source=f"plant/site{i}") for i, s in
                enumerate(load_fleet((), [catalogue_location], now=datetime.now(UTC), stale_days=7.0))]
    console = Console(width=80, file=io.StringIO(), color_system=None)
    console.print(fleet_table(statuses, stale_days=7.0))
    text = console.file.getvalue()  # type: ignore[attr-defined]
    head = [line.split("┃") for line in text.splitlines() if "┃" in line]
    assert [" ".join(" ".join(cells).split()) for cells in zip(*head)][:2] == ["robot/ joint", "source"]
    assert " ".join(head[-1][-1].split()) == "state" and max(len(line) for line in text.splitlines()) <= 80
    assert "plant/site0" in text and "not shown at this width: baseline N·m/rad" in " ".join(text.split())


def test_the_fleet_png_shows_each_session_and_says_what_grey_means(catalogue_location: Path | str,
                                                                   tmp_path: Path) -> None:
    """The fleet PNG was nearly blank at ΔK ≈ 0 (white on white) and its grey cells had no legend."""
    import numpy as np
    import pyqtgraph as pg
    from pyqtgraph.Qt import QtGui

    from acq.ui.fleet_display import NO_DELTA_K_GREY, fleet_widget, render_fleet_png
    from acq.ui.qt_app import ensure_app

    _fill(catalogue_location)
    now = datetime.now(UTC)
    statuses = load_fleet((), [catalogue_location], now=now, stale_days=7.0, tags=["site=A"])
    ensure_app(offscreen=True)
    frame = fleet_widget(statuses, now=now, threshold_pct=10.0, stale_days=7.0)
    (layout,) = [item for item in frame.findChildren(object) if type(item).__name__ == "GraphicsLayoutWidget"]
    legend = next(item for item in layout.ci.items if isinstance(item, pg.LegendItem))
    assert [label.text for _, label in legend.items] == [
        "session judged (its ΔK colours the strip until the next)", "session in alarm",
        "session not judged (not excited, failed, before the baseline)",
        "grey: no ΔK (before the baseline, or no session for 7 days)"]
    plot = next(item for item in layout.ci.items if isinstance(item, pg.PlotItem))
    # every session of site A: judged, in alarm (r1/j1's last), not judged (r2/j1's failed analysis)
    assert [len(item.data) for item in plot.items if isinstance(item, pg.ScatterPlotItem)] == [10, 1, 1]
    png = render_fleet_png(statuses, tmp_path / "fleet.png", now=now, threshold_pct=10.0, stale_days=7.0)
    image = QtGui.QImage(str(png)).convertToFormat(QtGui.QImage.Format.Format_RGB888)
    pixels = np.frombuffer(image.constBits(), np.uint8, count=image.sizeInBytes()).reshape(image.height(), -1)
    pixels = pixels[:, : 3 * image.width()].reshape(image.height(), image.width(), 3).astype(int)
    grey = np.all(np.abs(pixels - NO_DELTA_K_GREY) <= 2, axis=-1).sum()
    at_baseline = np.all(np.abs(pixels - (255, 255, 191)) <= 12, axis=-1).sum()  # the scale's ΔK ≈ 0
    assert grey > 20_000 and at_baseline > 20_000  # r1/j2 stale (grey after 7 days), r2/j1 at its baseline


def test_fleet_at_80_columns_splits_long_names_at_the_slash_never_inside_a_word(
        catalogue_location: Path | str, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(f"{__name__}.SESSIONS", [(r, j.replace("j", "joint"), *rest) for r, j, *rest in SESSIONS])
    _fill(catalogue_location)
    statuses = load_fleet((), [catalogue_location], now=datetime.now(UTC), stale_days=7.0)
    console = Console(width=80, file=io.StringIO(), color_system=None)
    console.print(fleet_table(statuses, stale_days=7.0))
    out = console.file.getvalue()  # type: ignore[attr-defined]
    assert max(len(line) for line in out.splitlines()) <= 80
    first_cells = [line.split("│")[0].strip() for line in out.splitlines() if "│" in line]
    assert [c for c in first_cells if c] == ["r3/", "joint1", "r1/", "joint1", "r1/", "joint2", "r2/", "joint1"]
    states = [line.split("│")[-1].strip() for line in out.splitlines() if "│" in line]
    assert states[:3] == ["ALARM", "threshold", "+ EWMA"]


def test_the_fleet_says_where_its_alarm_rules_came_from(catalogue_location: Path | str,
                                                        capsys: pytest.CaptureFixture[str],
                                                        monkeypatch: pytest.MonkeyPatch) -> None:
    """The table judged each joint by the rules its windows were filed with, or by the command line's, or by acq's
    defaults, and said not which."""
    from acq.monitoring.alarm_rules import AlarmRules

    monkeypatch.setenv("COLUMNS", "250")
    _fill(catalogue_location)

    def rules(*options: str) -> list[str]:
        run = run_cli(capsys, "fleet", "--catalogue", str(catalogue_location), "--tag", "site=A", *options)
        return [line.strip() for line in run.out.splitlines() if "alarm rules:" in line]

    assert rules() == ["alarm rules: acq's defaults"]
    assert rules("--threshold-pct", "20") == [
        "alarm rules: --threshold-pct from the command line, the rest acq's defaults"]
    now = datetime.now(UTC)
    with Catalogue(catalogue_location) as c:  # a monitor's windows: filed with the rules it judged them by
        for n, (hours, k) in enumerate(((4, 900.0), (2, 890.0))):
            doc = {"options": {}, "K_Nm_per_rad": k, "ci95": {"K_Nm_per_rad": [k - 5, k + 5]},
                   "quality": {"verdict": "ok", "reasons": []}}
            meta = {"session_id": f"m{n}", "joint": "j1",
                    "tags": {"robot": "r4", "site": "A", **AlarmRules(1, 15.0, 0.3).as_tags()},
                    "created_utc": (now - timedelta(hours=hours)).isoformat(timespec="seconds")}
            c.record(Outcome(f"/x/m{n}.h5", f"m{n}", "r", meta, doc, None, 1.0))
    assert rules() == ["alarm rules: acq's defaults (r1/j1, r1/j2, r2/j1); as acq monitor judged its windows (r4/j1)"]
    assert rules("--threshold-pct", "20", "--baseline-sessions", "1", "--ewma-lambda", "0.2") == [
        "alarm rules: from the command line"]


def _joint(location: Path | str, prefix: str, ks: tuple[float, ...], **tags: str) -> None:
    """Sessions of joint j1, one an hour up to an hour ago, with these K and tags."""
    now = datetime.now(UTC)
    with Catalogue(location) as c:
        for n, k in enumerate(ks):
            doc = {"options": {}, "K_Nm_per_rad": k, "ci95": {"K_Nm_per_rad": [k - 5, k + 5]},
                   "quality": {"verdict": "ok", "reasons": []}}
            meta = {"session_id": f"{prefix}{n}", "joint": "j1", "tags": dict(tags),
                    "created_utc": (now - timedelta(hours=len(ks) - n)).isoformat(timespec="seconds")}
            c.record(Outcome(f"/x/{prefix}{n}.h5", f"{prefix}{n}", "r", meta, doc, None, 1.0))


def test_fleet_of_several_folders_keeps_a_joint_of_each_apart(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                                              monkeypatch: pytest.MonkeyPatch) -> None:
    """The trial: three robots' sessions, all of joint "joint1", analysed into one catalogue made one joint (baseline
    of one robot, latest K of another: fleet said ok where the robot's own trend said ALARM −31.5 %). Each folder's
    catalogue is now read as it is and judged apart."""
    monkeypatch.setenv("COLUMNS", "250")
    monkeypatch.chdir(tmp_path)
    plant = Path("plant")
    _joint(plant / "r1" / "catalogue.sqlite", "a", (900.0, 902.0, 616.0))  # −31.6 %: alarm
    _joint(plant / "r2" / "catalogue.sqlite", "b", (600.0, 601.0, 599.0))
    run = run_cli(capsys, "fleet", str(plant / "r1"), str(plant / "r2"), "--json")
    assert run.code == 3, run.err
    rows = [(j["source"], j["robot"], j["joint"], j["state"], j["baseline_K_Nm_per_rad"], round(j["change_pct"], 1))
            for j in json.loads(run.out)]
    assert rows == [(str(plant / "r1"), "—", "j1", "alarm", 900.0, -31.6),
                    (str(plant / "r2"), "—", "j1", "ok", 600.0, -0.2)]
    table = run_cli(capsys, "fleet", str(plant / "r1"), str(plant / "r2"))
    lines = [[cell.strip() for cell in line.split("│")] for line in table.out.splitlines() if "│" in line]
    assert [line[:2] for line in lines] == [["—/j1", str(plant / "r1")], ["—/j1", str(plant / "r2")]]
    trends = run_cli(capsys, "trend", str(plant / "r1"), str(plant / "r2"), "--joint", "j1", "--json")
    assert trends.code == 3, trends.err
    assert [(t["joint"], t["baseline_K_Nm_per_rad"], [p["K_Nm_per_rad"] for p in t["points"]], t["alarm"])
            for t in json.loads(trends.out)] == [(f"j1 ({plant / 'r1'})", 900.0, [900.0, 902.0, 616.0], True),
                                                 (f"j1 ({plant / 'r2'})", 600.0, [600.0, 601.0, 599.0], False)]
    tables = run_cli(capsys, "trend", str(plant / "r1"), str(plant / "r2"), "--joint", "j1")
    assert [line.strip() for line in tables.out.splitlines() if "stiffness trend" in line] == [
        f"stiffness trend — j1 ({plant / 'r1'})  ALARM", f"stiffness trend — j1 ({plant / 'r2'})"]
    one_png = run_cli(capsys, "trend", str(plant / "r1"), str(plant / "r2"), "--joint", "j1", "--png",
                      str(tmp_path / "t.png"))
    assert (one_png.code, one_png.err) == (2, "acq: error: --png is for one trend: give one FOLDER or --catalogue\n")
    twice = run_cli(capsys, "fleet", str(plant / "r1"), "--catalogue", str(plant / "r1" / "catalogue.sqlite"))
    assert (twice.code, twice.err) == (2, f"acq: error: {plant / 'r1'} {plant / 'r1' / 'catalogue.sqlite'}: a "
                                          "catalogue is given twice\n")


def test_fleet_judges_the_windows_of_two_monitors_of_one_joint_name_apart(tmp_path: Path,
                                                                         capsys: pytest.CaptureFixture[str]) -> None:
    """Two monitors without a robot tag filing into one catalogue: one row each, named by the monitor."""
    shared = tmp_path / "plant.sqlite"
    _joint(shared, "a", (900.0, 902.0, 616.0), monitor_window="0", monitor_id="host:/m/r1:0a")
    _joint(shared, "b", (600.0, 601.0, 599.0), monitor_window="0", monitor_id="host:/m/r2:0b")
    run = run_cli(capsys, "fleet", "--catalogue", str(shared), "--json")
    assert run.code == 3, run.err
    assert [(j["source"], j["monitor_id"], j["state"], j["baseline_K_Nm_per_rad"]) for j in json.loads(run.out)] == [
        ("monitor host:/m/r1:0a", "host:/m/r1:0a", "alarm", 900.0), ("monitor host:/m/r2:0b", "host:/m/r2:0b", "ok",
                                                                     600.0)]


def test_a_monitors_windows_are_not_judged_with_a_benchs_sessions_of_the_same_joint_name(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The second read: with one monitor among them, a bench's sessions of the same joint name (no monitor_id) were
    one history with its windows — the bench's first sessions became the monitor's baseline, a confident alarm (or ok)
    that the monitor itself never gave. They are apart now in acq fleet, and acq trend refuses to mix them."""
    catalogue = tmp_path / "catalogue.sqlite"
    _joint(catalogue, "bench", (600.0, 601.0, 599.0))  # a lab bench's joint1: another joint altogether
    _joint(catalogue, "w", (900.0, 902.0, 899.0), monitor_id="host:/m:1", monitor_window="0")
    run = run_cli(capsys, "fleet", "--catalogue", str(catalogue), "--json")
    assert run.code == 0, run.err
    rows = {j["monitor_id"]: (j["state"], j["baseline_K_Nm_per_rad"], j["K_Nm_per_rad"]) for j in json.loads(run.out)}
    assert rows == {"host:/m:1": ("ok", 900.0, 899.0), None: ("ok", 600.0, 599.0)}  # mixed: baseline 600, K −50 %
    trend = run_cli(capsys, "trend", "--catalogue", str(catalogue), "--joint", "j1")
    assert trend.code == 2
    assert "has the windows of 1 monitor (host:/m:1) and 3 session(s) of no monitor — trend one: --tag " \
           "monitor_id=ID" in trend.err
    own = run_cli(capsys, "trend", "--catalogue", str(catalogue), "--joint", "j1", "--tag", "monitor_id=host:/m:1",
                  "--json")
    assert own.code == 0 and [p["K_Nm_per_rad"] for p in json.loads(own.out)["points"]] == [900.0, 902.0, 899.0]
    # the trial: the bench's sessions had no selector (--tag monitor_id= is refused as empty): --no-monitor
    assert trend.err == (f"acq: error: {catalogue}: joint j1 has the windows of 1 monitor (host:/m:1) and 3 session(s) "
                         "of no monitor — trend one: --tag monitor_id=ID or --no-monitor (those of no monitor)\n")
    bench = run_cli(capsys, "trend", "--catalogue", str(catalogue), "--joint", "j1", "--no-monitor", "--json")
    assert bench.code == 0 and [p["K_Nm_per_rad"] for p in json.loads(bench.out)["points"]] == [600.0, 601.0, 599.0]
    both = run_cli(capsys, "trend", "--catalogue", str(catalogue), "--joint", "j1", "--no-monitor", "--tag",
                   "monitor_id=host:/m:1")
    assert (both.code, both.err) == (2, "acq: error: --no-monitor and --tag monitor_id=host:/m:1: give one of them\n")
