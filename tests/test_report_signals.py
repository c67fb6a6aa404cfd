"""Ctrl-C and SIGTERM while ``acq analyze`` draws the report PNG: exit 130 with one line, the result file written
before stays valid, no picture — never a segfault, never a signal lost in Qt's frames.

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

#: ``acq analyze`` in a child whose first paint of a GraphicsView sends the process ``argv[1]`` (SIGINT / SIGTERM),
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
sys.argv = ["acq", "analyze", sys.argv[2]]
from acq.entry import main
main()
"""


@pytest.fixture(scope="module")
def recorded(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A 3 s simulated session (--fast), not analysed."""
    return record_session_in_subprocess(tmp_path_factory.mktemp("recorded"), 3.0)


@pytest.mark.parametrize("signame", ["SIGINT", "SIGTERM"])
def test_a_signal_while_the_report_is_painted_exits_130_with_one_line_and_the_result_stands(
        recorded: Path, tmp_path: Path, signame: str) -> None:
    session = tmp_path / recorded.name
    session.write_bytes(recorded.read_bytes())
    env = dict(os.environ, QT_QPA_PLATFORM="offscreen", PYTHONFAULTHANDLER="1")
    proc = subprocess.run([sys.executable, "-c", CHILD, signame, str(session)], capture_output=True, text=True,
                          env=env, cwd=tmp_path, timeout=120)
    assert (proc.returncode, proc.stderr) == (130, "acq: interrupted\n"), proc.stdout
    assert f"result: {session.with_suffix('.result.json')}" in proc.stdout.replace("\n", "")
    assert "report:" not in proc.stdout
    result = json.loads(session.with_suffix(".result.json").read_text(encoding="utf-8"))
    assert result["K_Nm_per_rad"] > 0.0
    assert sorted(p.name for p in tmp_path.iterdir() if "png" in p.name) == []  # no picture, no temp picture left
