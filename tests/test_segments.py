"""Segment selection: Welch on the segments that excite the joint, and which moves of a robot program do."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy import signal

from acq.config import load_bench
from acq.offline.analyze import analyze_session
from acq.recording.recorder import Recorder
from analysis import AnalysisRequest
from analysis.encoder import difference_response
from analysis.frf import estimate_frf
from analysis.segments import excitation_summary
from drivers.motion import RPM_TO_RAD_S
from drivers.registry import open_bench
from drivers.sim.bench import SimBench
from drivers.sim.robot_program import Move

ROBOT = Path(__file__).resolve().parents[1] / "configs" / "benches" / "sim_robot.toml"
WINDOW_S = 20.0


def test_selected_welch_equals_csd_per_contiguous_run_weighted_by_segment_count() -> None:
    rng = np.random.default_rng(3)
    fs, n = 1000.0, 20000
    x = 1e-3 * rng.standard_normal(n)  # quiet: estimation noise only
    for a, b in ((2000, 4500), (9000, 10500), (15000, 18000)):  # three bursts of excitation
        x[a:b] += rng.standard_normal(b - a)
    sos = signal.butter(2, 80.0, fs=fs, output="sos")
    y = signal.sosfilt(sos, x) + 1e-3 * rng.standard_normal(n)
    frf = estimate_frf(x, y, 1 / fs, select_band_hz=(10.0, 400.0))
    sel = frf.selection
    assert sel is not None and sel.applied
    runs = sel.runs()
    assert len(runs) == 3  # one run per burst, nothing from the quiet stretches
    gxx = gxy = 0.0
    for first, end in runs:  # scipy's csd on each run, weighted by its number of segments
        span = slice(first * sel.step, (end - 1) * sel.step + sel.nperseg)
        kw = dict(fs=fs, window="hann", nperseg=sel.nperseg, noverlap=sel.nperseg - sel.step, detrend="linear")
        gxx = gxx + (end - first) * signal.csd(x[span], x[span], **kw)[1].real
        gxy = gxy + (end - first) * signal.csd(x[span], y[span], **kw)[1]
    band = (frf.f_hz >= 10) & (frf.f_hz <= 400)
    expected = (gxy / gxx)[band] / difference_response(frf.f_hz[band], 1 / fs)  # estimate_frf divides it out
    np.testing.assert_allclose(frf.H[band], expected, rtol=1e-9)
    assert frf.n_segments == sum(end - first for first, end in runs)
    # the kept segments are where the bursts are: each run lies inside a burst widened by one segment
    for (first, end), (a, b) in zip(runs, ((2000, 4500), (9000, 10500), (15000, 18000))):
        assert a - sel.nperseg <= first * sel.step and (end - 1) * sel.step + sel.nperseg <= b + sel.nperseg


class _Program:
    """A robot program as a speed reference: the moves given, at rest between them."""

    def __init__(self, moves: list[Move]) -> None:
        self.moves = moves

    def reference(self, t_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        t = np.asarray(t_s, dtype=float)
        speed, accel = np.zeros_like(t), np.zeros_like(t)
        for m in self.moves:
            v, a = m.reference(t - m.t_start_s)
            speed, accel = speed + v, accel + a
        return speed, accel


#: Long pauses and slow moves (≤ 41 rpm, 1 s to top speed) with three fast ones (1200 rpm in 60 ms).
SLOW = [Move(1.0, 3.0, 60 * RPM_TO_RAD_S, 1.0), Move(6.0, -3.0, 60 * RPM_TO_RAD_S, 1.0),
        Move(12.5, 2.0, 60 * RPM_TO_RAD_S, 1.0)]
FAST = [Move(4.5, 8.0, 1200 * RPM_TO_RAD_S, 0.06), Move(11.0, -8.0, 1200 * RPM_TO_RAD_S, 0.06),
        Move(16.5, 6.0, 1200 * RPM_TO_RAD_S, 0.06)]


@pytest.fixture(scope="module")
def mostly_idle_window(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """20 s of the simulated production robot running the program above while acq listens."""
    bench = load_bench(ROBOT)
    sim = SimBench(bench, realtime=False)
    sim.use_reference(_Program(sorted(SLOW + FAST, key=lambda m: m.t_start_s)))
    current, drive = open_bench(bench, fast=True, sim_bench=sim)
    return Recorder(bench, None, current, drive, tmp_path_factory.mktemp("idle"), WINDOW_S).run().path


def test_selection_on_a_mostly_idle_robot_window_keeps_K_and_raises_the_coherence(mostly_idle_window: Path) -> None:
    plain = analyze_session(mostly_idle_window, AnalysisRequest(select_segments=False), write=False,
                            report=False).json_dict
    selected = analyze_session(mostly_idle_window, AnalysisRequest(select_segments=True), write=False, report=False).json_dict
    default = analyze_session(mostly_idle_window, write=False, report=False).json_dict  # no profile: selected too
    assert default["K_Nm_per_rad"] == selected["K_Nm_per_rad"] and default["options"]["select_segments"] is True
    truth = selected["simulated_truth"]["K_Nm_per_rad"]
    assert selected["K_Nm_per_rad"] == pytest.approx(truth, rel=0.03)  # the monitor tests' tolerance
    lo, hi = selected["ci95"]["K_Nm_per_rad"]
    assert lo <= truth <= hi and selected["quality"]["verdict"] == "ok"
    # measured: mean coherence 0.84 → 0.95, between f_a and f_r 0.94 → 0.98
    assert selected["quality"]["mean_coherence"] > plain["quality"]["mean_coherence"] + 0.05
    assert selected["quality"]["excitation_coherence"] > plain["quality"]["excitation_coherence"]
    assert "excitation" not in plain and plain["options"].get("select_segments") is None


def test_the_excited_moves_are_the_fast_ones_and_the_excited_share_matches_them(mostly_idle_window: Path) -> None:
    exc = analyze_session(mostly_idle_window, AnalysisRequest(select_segments=True), write=False, report=False).json_dict["excitation"]
    moves = exc["moves"]
    program = sorted(SLOW + FAST, key=lambda m: m.t_start_s)
    assert len(moves) == len(program)
    for found, move in zip(moves, program):
        assert found["start_s"] == pytest.approx(move.t_start_s, abs=0.03)
        assert found["peak_rad_s"] == pytest.approx(move.peak_rad_s, rel=0.1)
        assert found["excited"] == (move in FAST), found
    # The analysis works in 0.5 s Welch segments, each owning the 0.25 s middle of its window: a fast move
    # excites its own duration widened by about one segment, within one hop (0.25 s) either way.
    segment_s, hop_s = 0.5, 0.25
    expected = sum(m.duration_s + segment_s for m in FAST) / WINDOW_S
    assert exc["excited_fraction"] == pytest.approx(expected, abs=len(FAST) * hop_s / WINDOW_S)
    assert exc["excited_fraction"] == exc["segments_used"] / exc["segments"]


def test_a_joint_that_never_leaves_rest_has_no_moves() -> None:
    from analysis.segments import SegmentSelection, describe_moves

    dither = np.where(np.arange(4000) % 2, 1.0, -1.0) * 2 * np.pi / 4096 / 1e-3  # ±1 count per period
    kept = SegmentSelection(np.ones(3, bool), np.ones(3), 2.0, 256, 128, False)
    assert describe_moves(np.arange(4000) * 1e-3, dither, 1e-3, 4096, 1.0, kept) == []


def test_a_robot_window_whose_half_periods_share_no_ratio_names_no_bench_constant(tmp_path: Path) -> None:
    """Seed 0's first window with S-curve moves: the lag search locks onto the wrong one of the repeated moves,
    and the half-periods' ratios scatter from 0.8 to 10⁵ around 6.6 — that once read "check counts_per_rev =
    19879" on a correctly configured bench."""
    from acq.offline.analyze import recording_from_session
    from acq.recording.reader import load
    from analysis.diagnose import recording_fault
    from analysis.speed_ratio import electrical_speed_ratio

    bench = load_bench(ROBOT)
    bench = bench.model_copy(update={"sim": bench.sim.model_copy(update={"robot_s_curve_fraction": 0.5})})
    current, drive = open_bench(bench, fast=True, sim_bench=SimBench(bench, realtime=False))
    rec = recording_from_session(load(Recorder(bench, None, current, drive, tmp_path, 10.0).run().path))
    assert electrical_speed_ratio(rec.current_a["i_a"], rec.rate_hz, rec.encoder_index, rec.position_counts,
                                  rec.period_s, rec.counts_per_rev, rec.pole_pairs) is None
    assert recording_fault(rec) is None


def test_an_idle_robot_window_names_no_bench_constant(tmp_path: Path) -> None:
    """Seed 0's first 4 s window (docs/monitoring.md's monitor example) stands still most of the time: the current is
    noise around zero and crosses zero quickly while the encoder does not move. Those half-periods once read
    "the current turns 500000000000.00× faster … check [motor] pole_pairs = 2000000000000 or [encoder]
    counts_per_rev = 0"; only half-periods in which the encoder travels count now."""
    from acq.offline.analyze import recording_from_session
    from acq.recording.reader import load
    from analysis.diagnose import recording_fault

    bench = load_bench(ROBOT)
    current, drive = open_bench(bench, fast=True, sim_bench=SimBench(bench, realtime=False))
    rec = recording_from_session(load(Recorder(bench, None, current, drive, tmp_path, 4.0).run().path))
    assert recording_fault(rec) is None


def test_the_excitation_summary_says_what_each_count_counts() -> None:
    """It read "0 of 12 moves put torque into 10…400 Hz beyond chance (3 % of the window)": 3 % of what, if no move
    excites? The moves and the excited time are counted apart (a kept segment can lie outside every move)."""
    assert excitation_summary(0, 12, (10.0, 400.0), 0.03, "window") == (
        "0 of the window's 12 moves put torque into 10…400 Hz beyond chance; time that does: 3 % of the window")
    assert excitation_summary(2, 5, (10.0, 150.0), 0.084) == (
        "2 of the record's 5 moves put torque into 10…150 Hz beyond chance; time that does: 8 % of the record")
