"""acq monitor against what a plant does to it: SIGTERM to its process group, a worker killed, a full disk, a
catalogue server restarted — every window filed exactly once, or left for the restart, never lost."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from dataclasses import replace
from pathlib import Path



from tests.test_monitor import EXCITING_SEED, ROBOT, _bench, _rows

ROOT = Path(__file__).resolve().parents[1]


def _env() -> dict[str, str]:
    """The environment of an acq child: this worktree's code first (its workers start without the current folder)."""
    return {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, (str(ROOT), os.environ.get("PYTHONPATH"))))}


def test_sigterm_to_the_process_group_lets_the_analysis_under_way_finish_and_be_filed(tmp_path: Path) -> None:
    """The trial: ``timeout -s TERM 8 acq monitor …`` (timeout signals its whole group) killed the analysis worker
    too: "2 windows filed (1 analysis failed + 1 interrupted)", reason "worker failed: BrokenProcessPool", and the
    window's K lost for good. The workers ignore SIGTERM now: acq's process files the analysis, then stops them."""
    out = tmp_path / "m"
    proc = subprocess.Popen([sys.executable, "-m", "acq", "monitor", "--bench", str(ROBOT), "--window", "10",
                             "--every", "10", "--out", str(out)], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, start_new_session=True, env=_env())
    deadline = time.monotonic() + 120
    while proc.poll() is None and time.monotonic() < deadline and len(list(out.glob("*.h5"))) < 2:
        time.sleep(0.05)  # the second window's capture started: the first one's analysis is under way
    assert proc.poll() is None, proc.communicate()
    first = sorted(out.glob("*.h5"))[0]
    assert not first.with_suffix(".result.json").exists()  # its analysis had not ended (10 s of data take longer)
    os.killpg(proc.pid, signal.SIGTERM)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 130, err
    rows = _rows(out)
    assert [(r["window"], r["verdict"]) for r in rows] == [(0, rows[0]["verdict"]), (1, "interrupted")]
    assert rows[0]["verdict"] in ("ok", "not excited", "poor"), rows[0]  # analysed: K or why not
    assert "BrokenProcessPool" not in err and "not analysed" not in json.dumps(rows)
    assert err.splitlines()[-1].startswith("acq: stopped by SIGTERM: 2 windows filed (")


def test_a_window_whose_worker_died_is_left_for_the_restart_and_analysed_there(tmp_path: Path) -> None:
    """A worker killed (out of memory, kill -9) mid-analysis: the window was filed "not analysed" and neither a restart
    nor acq analyze analysed it again. Now it is not filed; the next windows go to a new pool, and the restart
    analyses it."""
    from acq.monitoring.monitor import Monitor, MonitorSettings

    settings = MonitorSettings(bench=_bench(seed=EXCITING_SEED), out_dir=tmp_path, window_s=10.0, every_s=60.0,
                               for_s=180.0, fast=True, baseline_windows=2)
    killed: list[int] = []

    def kill_the_first_worker(status: object) -> None:
        if not killed and monitor._pending:  # the first window handed to a worker
            time.sleep(0.5)  # the worker has taken it
            pid = next(iter(monitor._pool._processes))
            os.kill(pid, signal.SIGKILL)
            killed.append(pid)

    monitor = Monitor(settings, on_status=kill_the_first_worker)
    assert monitor.run() == 0
    st = monitor.status
    assert killed and st.unfinished == 1
    assert [(r["window"], r["verdict"]) for r in _rows(tmp_path)] == [(1, "ok"), (2, "ok")]
    assert st.filed_total == 2 and st.filed["analysis failed"] == 0
    assert len(list(tmp_path.glob("*.h5"))) == 3  # its raw window kept for the restart
    # the restart analyses it (and captures one more)
    again = Monitor(replace(settings, for_s=60.0))
    assert again.run() == 0
    assert [(r["window"], r["verdict"]) for r in _rows(tmp_path)] == [(0, "ok"), (1, "ok"), (2, "ok"), (3, "ok")]
