"""The recorder end to end on the simulated bench: zero loss, gaps by counters, crash safety."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from acq.config import DEFAULT_BENCH
from acq.recording.reader import load
from tests.helpers import run_cli

RATE_HZ, PERIOD_S, BLOCK = 25600, 0.001, 2560


def _only_session(folder: Path) -> Path:
    files = sorted(folder.glob("*.h5"))
    assert len(files) == 1, files
    return files[0]


def test_fast_10s_session_loses_nothing(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    run = run_cli(capsys, "record", "--profile", "triangle_0.2s", "--fast", "--out", str(tmp_path))
    assert run.code == 0, run.err
    s = load(_only_session(tmp_path))
    assert s.status == "complete"
    idx = s.current.sample_index()
    assert 10 * RATE_HZ <= idx.size <= 10 * RATE_HZ + BLOCK
    np.testing.assert_array_equal(idx, np.arange(idx.size))
    assert 10_000 <= s.encoder.index.size <= 10_000 + 20
    np.testing.assert_array_equal(np.diff(s.encoder.index), 1)
    assert [e for e in s.events if e.kind == "gap"] == []
    assert np.all(np.diff(s.encoder.host_ns) >= 0) and np.all(np.diff(s.current.block_host_ns) > 0)
    assert "complete" in run.out and "current" in run.out and "encoder" in run.out


def test_dropped_encoder_frames_become_gap_events(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    bench = tmp_path / "drops.toml"
    bench.write_text(DEFAULT_BENCH.read_text() + "drop_encoder_frames = [[500, 3], [1500, 10]]\n")
    run = run_cli(capsys, "record", "--profile", "triangle_0.2s", "--bench", str(bench), "--duration", "2",
                  "--fast", "--out", str(tmp_path / "s"))
    assert run.code == 0, run.err
    s = load(_only_session(tmp_path / "s"))
    gaps = [e.detail for e in s.events if e.kind == "gap"]
    assert gaps == ["3 frames missing before cycle 503", "10 frames missing before cycle 1510"]
    assert s.encoder.index.size + 13 == s.encoder.index[-1] - s.encoder.index[0] + 1
    info = run_cli(capsys, "info", str(_only_session(tmp_path / "s")), "--json")
    assert '"missing": 13' in info.out


def _start_recording(out: Path, duration_s: float) -> subprocess.Popen[str]:
    return subprocess.Popen(
        [sys.executable, "-m", "acq", "record", "--profile", "triangle_0.2s", "--duration", str(duration_s),
         "--out", str(out)],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )


def _wait_for_samples(out: Path, proc: subprocess.Popen[str], samples: int, deadline_s: float = 60.0) -> Path:
    """Wait until the recorder has flushed at least ``samples`` current samples (a condition, not a sleep)."""
    end = time.monotonic() + deadline_s
    while time.monotonic() < end:
        assert proc.poll() is None, proc.communicate()
        files = list(out.glob("*.h5"))
        if files:
            try:
                if load(files[0]).current.sample_count >= samples:
                    return files[0]
            except Exception:  # noqa: BLE001 - the file may be mid-creation
                pass
        time.sleep(0.05)
    raise AssertionError("recorder produced no data in time")


def test_sigint_keeps_everything_and_says_so(tmp_path: Path) -> None:
    proc = _start_recording(tmp_path, 60)
    path = _wait_for_samples(tmp_path, proc, RATE_HZ)
    proc.send_signal(signal.SIGINT)
    out, err = proc.communicate(timeout=30)
    assert proc.returncode == 130, err
    assert "interrupted" in err and "kept" in err and str(path) in err.replace("\n", "")
    assert err.replace("\n", "").endswith(f"; not identified: acq analyze {path}")  # Ctrl-C: no waiting, one line
    assert not list(tmp_path.glob("*.result.json"))
    s = load(path)
    assert s.status == "interrupted" and s.attrs["stop_reason"] == "interrupted by user (Ctrl-C)"
    idx = s.current.sample_index()
    np.testing.assert_array_equal(idx, np.arange(idx.size))
    np.testing.assert_array_equal(np.diff(s.encoder.index), 1)
    assert idx.size >= RATE_HZ and s.encoder.index.size >= 900


def test_sigkill_leaves_flushed_samples_and_check_repairs(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    proc = _start_recording(tmp_path, 60)
    path = _wait_for_samples(tmp_path, proc, 2 * RATE_HZ)
    os.kill(proc.pid, signal.SIGKILL)
    proc.communicate(timeout=30)
    before = load(path)
    assert before.status == "recording" and before.current.sample_count >= 2 * RATE_HZ
    run = run_cli(capsys, "check", str(path))
    assert run.code == 0
    assert "interrupted" in run.out and "repaired" in run.out
    after = load(path)
    assert after.status == "interrupted"
    assert after.current.sample_count == before.current.sample_count
    np.testing.assert_array_equal(after.encoder.index, before.encoder.index)
    np.testing.assert_array_equal(after.current.sample_index(), np.arange(after.current.sample_count))
    again = run_cli(capsys, "check", str(path))
    assert "interrupted, checksums and counts verified" in again.out.replace("\n", " ")


def test_listeners_see_blocks_and_the_recorders_gap_events(tmp_path: Path) -> None:
    from acq.config import load_bench, load_profile
    from acq.recording.recorder import Recorder
    from drivers.registry import open_bench

    bench = load_bench()
    bench = bench.model_copy(update={"sim": bench.sim.model_copy(update={"drop_encoder_frames": [(300, 4)]})})
    seen: list[tuple[str, object]] = []
    current, drive = open_bench(bench, fast=True)
    result = Recorder(bench, load_profile("triangle_0.2s"), current, drive, tmp_path, 1.0,
                      listeners=[lambda stream, item: seen.append((stream, item))]).run()
    assert result.status == "complete" and result.encoder_gaps == 1
    events = [item for stream, item in seen if stream == "event"]
    assert [(e.stream, e.kind, e.detail) for e in events] == [("encoder", "gap", "4 frames missing before cycle 304")]
    assert sum(item.count for stream, item in seen if stream == "current") == result.current_samples


def _sim_recorder(tmp_path: Path, duration_s: float, listeners: list | None = None):
    from acq.config import load_bench, load_profile
    from acq.recording.recorder import Recorder
    from drivers.registry import open_bench

    bench = load_bench()
    current, drive = open_bench(bench, fast=True)
    return Recorder(bench, load_profile("triangle_0.2s"), current, drive, tmp_path, duration_s,
                    listeners=listeners or [])


def test_a_stop_requested_from_another_thread_interrupts_and_keeps_the_data(tmp_path: Path) -> None:
    import threading

    recorder: list = []

    def stop_after_a_second(stream: str, item: object) -> None:
        if stream == "current" and item.first_index >= RATE_HZ and not recorder[1].is_set():
            recorder[1].set()
            threading.Thread(target=recorder[0].request_stop, args=("operator pressed stop",)).start()

    rec = _sim_recorder(tmp_path, 30.0, [stop_after_a_second])
    recorder += [rec, threading.Event()]
    result = rec.run()
    assert (result.status, result.stop_reason) == ("interrupted", "operator pressed stop")
    s = load(result.path)
    assert s.status == "interrupted" and RATE_HZ <= s.current.sample_count < 30 * RATE_HZ
    np.testing.assert_array_equal(s.current.sample_index(), np.arange(s.current.sample_count))


def test_a_stop_after_both_streams_are_complete_changes_nothing(tmp_path: Path) -> None:
    rec = _sim_recorder(tmp_path, 1.0)
    seen = {"current": 0, "encoder": 0}

    def stop_once_both_are_complete(stream: str, item: object) -> None:
        if stream in seen:
            seen[stream] += item.count
        if seen["current"] >= RATE_HZ and seen["encoder"] >= 1000:
            rec.request_stop("too late")

    rec.listeners.append(stop_once_both_are_complete)
    result = rec.run()
    assert (result.status, result.stop_reason) == ("complete", "recorded 1 s")


def test_a_session_opened_but_never_run_is_finished_as_interrupted(tmp_path: Path) -> None:
    rec = _sim_recorder(tmp_path, 1.0)
    writer = rec.open_session()
    rec.abort("interrupted by user (Ctrl-C)")
    s = load(writer.path)
    assert (s.status, s.attrs["stop_reason"]) == ("interrupted", "interrupted by user (Ctrl-C)")
    rec.abort("again")  # idempotent
    assert load(writer.path).attrs["stop_reason"] == "interrupted by user (Ctrl-C)"


def test_the_recorded_velocity_demand_is_the_simulated_speed_reference_at_each_cycle(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from acq.config import load_bench, load_profile
    from acq.recording.recorder import Recorder
    from drivers.motion import triangle_speed_rad_s
    from drivers.registry import open_bench
    from drivers.sim.bench import SimBench

    bench, profile = load_bench(), load_profile("triangle_0.2s")
    sim = SimBench(bench, realtime=False)
    current, drive = open_bench(bench, fast=True, sim_bench=sim)
    result = Recorder(bench, profile, current, drive, tmp_path, 2.0).run()
    session = load(result.path)
    enc, profile = session.encoder, session.profile  # as executed: the dither_seed the recorder drew is stored
    assert profile is not None and profile.speed_dither == 0.02 and profile.dither_seed is not None
    (motion,) = sim.truth["motions"]
    # the triangle the drive's speed loop followed, read at its last 4 kHz control instant at or before k·T
    loop_s = 1.0 / bench.sim.speed_loop_hz
    t_loop = np.floor(enc.index * PERIOD_S / loop_s + 1e-9) * loop_s
    moving = (t_loop >= motion["t_start_s"]) & (t_loop < motion["t_stop_s"])
    expected = np.where(moving, triangle_speed_rad_s(t_loop - motion["t_start_s"], profile), 0.0)
    assert enc.velocity_demand_counts_per_s is not None and moving.sum() > 1500
    np.testing.assert_allclose(enc.velocity_demand_counts_per_s[t_loop < motion["t_stop_s"]],
                               (expected * bench.encoder.counts_per_rev / (2 * np.pi))[t_loop < motion["t_stop_s"]],
                               rtol=1e-12, atol=1e-6)
    # 1000 rpm within the 2 % dither (the last cycle may end before its apex)
    assert 980 <= enc.velocity_demand_counts_per_s.max() / bench.encoder.counts_per_rev * 60 <= 1020
    # the speed loop tracks its demand: the encoder's speed stays within a few % of the peak from it
    measured = np.diff(enc.position_counts) / PERIOD_S
    assert np.sqrt(np.mean((measured - enc.velocity_demand_counts_per_s[1:]) ** 2)) < 0.05 * measured.max()
    info = run_cli(capsys, "info", str(result.path), "--json")
    assert '"encoder_extras": [\n    "drive_time_s",\n    "velocity_demand_counts_per_s"\n  ]' in info.out
