"""Which runs --partial takes when both streams have holes and the streams share no host clock: the record's first
encoder cycle is taken with its first DAQ sample ("started together"), whatever number the drive's cycle counter
starts at — an imported encoder keeps the drive's cycle numbers (found by session 13's reviewer: with the counter
starting at 10 000, encoder 10–15 s was paired with the current's second run, which it shares no time with)."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from acq.offline.analyze import recording_from_session
from acq.recording.reader import load
from analysis import AnalysisRequest, analyze
from analysis.shared_runs import shared_runs
from tests.helpers import record_session_in_subprocess


@pytest.fixture(scope="module")
def holed(tmp_path_factory: pytest.TempPathFactory):
    """A 10 s recording with a 0.1 s hole in the current at 4.8 s and one in the encoder at 5.0 s, no shared host
    clock, the encoder's cycle counter starting at 10 000."""
    rec = recording_from_session(load(record_session_in_subprocess(tmp_path_factory.mktemp("holed"), 10.0)))
    first, count = rec.block_first_index, rec.block_count
    starts = np.concatenate(([0], np.cumsum(count)[:-1]))
    drop = (first / rec.rate_hz >= 4.8) & (first / rec.rate_hz < 4.9)
    keep = np.ones(rec.current_a["i_a"].size, bool)
    for s, c in zip(starts[drop], count[drop]):
        keep[s:s + c] = False
    t_enc = rec.encoder_index * rec.period_s
    kept = ~((t_enc >= 5.0) & (t_enc < 5.1))
    return replace(rec, current_a={k: v[keep] for k, v in rec.current_a.items()}, block_first_index=first[~drop],
                   block_count=count[~drop], block_host_ns=rec.block_host_ns[~drop],
                   encoder_index=rec.encoder_index[kept] + 10_000, position_counts=rec.position_counts[kept],
                   encoder_host_ns=rec.encoder_host_ns[kept],
                   drive_time_s=None if rec.drive_time_s is None else rec.drive_time_s[kept], host_clock_shared=False)


def test_the_runs_taken_share_their_time_whatever_the_cycle_counter_starts_at(holed) -> None:
    span, run = shared_runs(holed, None)
    enc_s = (holed.encoder_index[[span.start, span.stop - 1]] - 10_000) * holed.period_s
    daq_s = np.array([run.first_index, run.first_index + run.count]) / holed.rate_hz
    assert enc_s[0] == pytest.approx(5.1, abs=2e-3) and enc_s[1] == pytest.approx(10.0, abs=2e-3)
    assert daq_s[0] == pytest.approx(4.9, abs=0.05) and daq_s[1] == pytest.approx(10.0, abs=0.05)


def test_such_a_record_is_identified(holed) -> None:
    doc = analyze(holed, AnalysisRequest()).to_json_dict()
    assert doc["clock"]["failure"] is None
    assert doc["quality"]["verdict"] == "ok"
    assert doc["K_Nm_per_rad"] == pytest.approx(891.0, rel=0.02)
