"""Control characters in tags (the new-user trial: ``--tag $'t=\\x01\\x1b[31mred'`` was stored, and acq trend printed
the raw escape sequence, turning the terminal red): refused at input in one line naming the tag and the character,
exit 2; values an older acq stored are printed escaped. The real CLI in a child process."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from acq.monitoring.catalogue import Catalogue, Outcome

ROBOT = Path(__file__).resolve().parents[1] / "configs" / "benches" / "sim_robot.toml"
RED = "t=\x01\x1b[31mred"


def _acq(*args: str) -> subprocess.CompletedProcess[str]:
    env = {**os.environ, "COLUMNS": "200"}
    return subprocess.run([sys.executable, "-m", "acq", *args], capture_output=True, text=True, env=env, timeout=120)


@pytest.mark.parametrize("command", [("record", "--profile", "triangle_0.2s", "--fast"),
                                     ("monitor", "--bench", str(ROBOT), "--fast", "--for", "1min")])
def test_a_tag_with_a_control_character_is_refused_naming_it(tmp_path: Path, command: tuple[str, ...]) -> None:
    out = tmp_path / "out"
    run = _acq(*command, "--tag", RED, "--out", str(out))
    assert (run.returncode, run.stdout) == (2, "")
    assert run.stderr == ("acq: error: --tag 't=\\x01\\x1b[31mred': holds the control character \\x01 — give it "
                          "without control characters (a terminal that prints it would act on them)\n")
    assert not out.exists()


def test_an_operator_with_a_control_character_is_refused_naming_it(tmp_path: Path) -> None:
    """The review: --operator took what --tag refuses (an OSC title sequence and ESC[31m were stored in the session)."""
    out = tmp_path / "out"
    run = _acq("record", "--profile", "triangle_0.2s", "--fast", "--operator", "eve\x1b]0;pwned\x07", "--out", str(out))
    assert (run.returncode, run.stdout) == (2, "")
    assert run.stderr == ("acq: error: --operator 'eve\\x1b]0;pwned\\x07': holds the control character \\x1b — give "
                          "it without control characters (a terminal that prints it would act on them)\n")
    assert not out.exists()


def test_stored_tags_with_control_characters_are_printed_escaped(tmp_path: Path) -> None:
    """A catalogue an older acq wrote holds them: trend and fleet print ``\\x1b``, never the escape itself."""
    doc = {"options": {}, "K_Nm_per_rad": 890.0, "ci95": {"K_Nm_per_rad": [886.0, 894.0]},
           "quality": {"verdict": "ok", "reasons": []}}
    with Catalogue(tmp_path / "catalogue.sqlite") as catalogue:
        for i in range(3):
            meta = {"session_id": f"s{i}", "joint": "joint1", "tags": {"t": RED[2:], "robot": "r\x1b[32m1"},
                    "created_utc": f"2026-11-29T10:0{i}:00+00:00"}
            catalogue.record(Outcome(f"/m/s{i}.h5", f"h{i}", "r", meta, doc, None, 1.0))
    trend = _acq("trend", str(tmp_path), "--joint", "joint1")
    assert (trend.returncode, trend.stderr) == (0, "")
    assert "\nevery session tagged t=\\x01\\x1b[31mred robot=r\\x1b[32m1" in trend.stdout
    fleet = _acq("fleet", str(tmp_path))
    assert (fleet.returncode, fleet.stderr) == (0, "")
    assert "\n r\\x1b[32m1/joint1 │" in fleet.stdout
    assert "\x1b" not in trend.stdout + fleet.stdout and "\x01" not in trend.stdout
