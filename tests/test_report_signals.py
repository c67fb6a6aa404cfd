"""Ctrl-C and SIGTERM while ``acq analyze`` draws the report PNG (or ``acq trend --png`` its plot): exit 130 with one
line, the result file written before stays valid, no report picture (the trend plot, asked for by itself, is written
whole) — never a segfault, never a signal lost in Qt's frames.

The signal is a real one, sent by the process to itself from inside Qt's paint of the report (pyqtgraph's
``GraphicsView.paintEvent``, a Python override Qt calls from C++), so it lands in the drawing every run. A
KeyboardInterrupt raised there unwound through C++ frames: a segfault (exit -11), or Qt printed "Error calling Python
override" and the command went on to exit 0 with the picture drawn."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from tests.helpers import record_session_in_subprocess

#: ``acq ARGV[2:]`` in a child whose first paint of a GraphicsView sends the process ``argv[1]`` (SIGINT / SIGTERM),
#: then paints as pyqtgraph does.
CHILD = """
import os, signal, sys
import pyqtgraph.widgets.GraphicsView as gv

paint = gv.GraphicsView.paintEvent
signum = getattr(signal, sys.argv[1])
sent = []

def paint_signalled(self, event):
    if not sent:
        sent.append(True)
        os.kill(os.getpid(), signum)
    return paint(self, event)

gv.GraphicsView.paintEvent = paint_signalled
sys.argv = ["acq", *sys.argv[2:]]
from acq.entry import main
main()
"""


def _signalled_in_paint(signame: str, cwd: Path, *args: str) -> subprocess.CompletedProcess[str]:
    env = dict(os.environ, QT_QPA_PLATFORM="offscreen", PYTHONFAULTHANDLER="1")
    return subprocess.run([sys.executable, "-c", CHILD, signame, *args], capture_output=True, text=True, env=env,
                          cwd=cwd, timeout=120)


@pytest.fixture(scope="module")
def recorded(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A 3 s simulated session (--fast), not analysed."""
    return record_session_in_subprocess(tmp_path_factory.mktemp("recorded"), 3.0)


@pytest.mark.parametrize("signame", ["SIGINT", "SIGTERM"])
def test_a_signal_while_the_report_is_painted_exits_130_with_one_line_and_the_result_stands(
        recorded: Path, tmp_path: Path, signame: str) -> None:
    session = tmp_path / recorded.name
    session.write_bytes(recorded.read_bytes())
    proc = _signalled_in_paint(signame, tmp_path, "analyze", str(session))
    assert (proc.returncode, proc.stderr) == (130, "acq: interrupted\n"), proc.stdout
    assert f"result: {session.with_suffix('.result.json')}" in proc.stdout.replace("\n", "")
    assert "report:" not in proc.stdout
    result = json.loads(session.with_suffix(".result.json").read_text(encoding="utf-8"))
    assert result["K_Nm_per_rad"] > 0.0
    assert sorted(p.name for p in tmp_path.iterdir() if "png" in p.name) == []  # no picture, no temp picture left


def test_a_ctrl_c_while_the_trend_png_is_painted_exits_130_with_one_line_after_the_whole_picture(tmp_path: Path) -> None:
    from acq.monitoring.catalogue import Catalogue, Outcome

    path = tmp_path / "catalogue.sqlite"
    with Catalogue(path) as c:  # three judged windows of one joint
        for n, k in enumerate([890.0, 891.0, 889.0]):
            doc = {"options": {}, "K_Nm_per_rad": k, "ci95": {"K_Nm_per_rad": [0.9 * k, 1.1 * k]},
                   "quality": {"verdict": "ok", "reasons": []}}
            meta = {"session_id": f"w{n}", "joint": "joint1", "tags": {}, "created_utc": f"2026-11-29T10:0{n}:00+00:00"}
            c.record(Outcome(f"/m/w{n}.h5", f"h{n}", "r", meta, doc, None, 1.0))
    proc = _signalled_in_paint("SIGINT", tmp_path, "trend", "--catalogue", str(path), "--joint", "joint1", "--png",
                               str(tmp_path / "trend.png"))
    assert (proc.returncode, proc.stderr) == (130, "acq: interrupted\n"), proc.stdout
    assert sorted(p.name for p in tmp_path.iterdir() if "png" in p.name) == ["trend.png"]  # no temp file beside it
    png = (tmp_path / "trend.png").read_bytes()
    assert png[:8] == b"\x89PNG\r\n\x1a\n" and png[-8:-4] == b"IEND"  # whole, as it was asked for
