"""The advice that follows a mismatched electrical speed the data do not establish (``ratio_doubt``): acq selftest
where it can check the constants (a bench acq commands), the data sheets where it cannot (a listening bench)."""

from __future__ import annotations

import numpy as np
import pytest

import analysis.diagnose as diagnose
from analysis import CommandedProfile, Recording
from analysis.speed_ratio import SpeedRatio

#: the short-move record of test_selftest's doubt: 2.99× read, but 480 crossings over 240 moves of 1.3 half-turns
DOUBT = SpeedRatio(ratio=2.99, spread=0.01, lag_s=0.0, cycles=100.0, crossings=480, half_turns=312.0, moves=240,
                   moving_s=4.32)
FIGURES = ("pole_pairs and counts_per_rev cannot be checked on this record: the current's half-periods read 2.99× "
           "pole_pairs·ω, but its 480 zero crossings in the moves allow 0.00–2.36× — each of the 240 moves turns the "
           "motor only 0.16 rev (1.3 electrical half-turns at pole_pairs = 4) in 18 ms, so the current's zero "
           "crossings follow its torque's sign changes as much as the rotation")


def _recording(profile: CommandedProfile | None) -> Recording:
    n = np.arange(100)
    return Recording(current_a={"i_a": np.zeros(1000)}, rate_hz=10_000.0, encoder_index=n, position_counts=n,
                     period_s=1e-3, counts_per_rev=131072, pole_pairs=4, k_t_Nm_per_A=3.0,
                     profile=profile)


@pytest.mark.parametrize(("profile", "advice"), [
    (CommandedProfile(accel_time_s=0.01, decel_time_s=0.01), "check the constants with acq selftest"),
    (None, "acq selftest cannot check them on a listening bench either: take them from the motor's and the "
           "encoder's data sheets"),
])
def test_a_doubt_sends_to_selftest_only_where_selftest_can_check(monkeypatch: pytest.MonkeyPatch,
                                                                 profile: CommandedProfile | None,
                                                                 advice: str) -> None:
    # the ratio's measurement is replaced (its own tests: test_selftest); what is judged here is the advice
    monkeypatch.setattr(diagnose, "electrical_speed_ratio", lambda *args: DOUBT)
    assert diagnose.recording_diagnosis(_recording(profile)) == (None, f"{FIGURES}; {advice}")
