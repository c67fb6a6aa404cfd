"""Clock alignment from the data alone: offsets to ±2 s and drifts to ±100 ppm, late host stamps, ambiguity."""

from __future__ import annotations

import tomllib
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from scipy import stats

from analysis.clock_angle import _move_jackknife
from analysis.clock_search import overlap_correlation
from analysis.zero_crossings import percentile_without_copy
from analysis.recording import Recording
from analysis.signals import prepare_signals
from drivers.config import Bench, Profile
from drivers.sim.bench import SimBench

SIM_TOML = Path(__file__).resolve().parent.parent / "configs" / "benches" / "sim.toml"
PROFILE = Profile(kind="triangle", top_speed_rpm=1000.0, accel_time_s=0.2, decel_time_s=0.2, duration_s=30.0)
BLOCK = 2560


def separate_records(offset_s: float, drift_ppm: float, duration_s: float = 6.0, t_motion_s: float | None = None,
                     seed: int = 3) -> Recording:
    """The current over DAQ time 0…``duration_s`` and the encoder over drive time 0…``duration_s``, each
    stamped on one host clock by the simulator (arrival latency and jitter). DAQ sample 0 is at drive time
    ``offset_s``; the motion starts 0.5 s into the later record unless ``t_motion_s`` (drive time) says."""
    with SIM_TOML.open("rb") as f:
        bench = Bench.model_validate(tomllib.load(f))
    assert bench.sim is not None
    bench = bench.model_copy(update={"sim": bench.sim.model_copy(
        update={"daq_offset_s": offset_s, "daq_drift_ppm": drift_ppm, "seed": seed})})
    sim = SimBench(bench, realtime=False, keep_history=True)
    sim.start_motion(PROFILE, max(0.0, offset_s) + 0.5 if t_motion_s is None else t_motion_s)
    n = int(duration_s * sim.daq_rate_hz)
    first = np.arange(0, n, BLOCK, dtype=np.int64)
    count = np.minimum(BLOCK, n - first)
    block_host = sim.host_ns_at(sim.daq_time_s(first + count - 1), sim.host_jitter_s("daq_host", 0, first.size))
    T = sim.drive_period_s
    k = np.arange(int(duration_s / T), dtype=np.int64)
    enc_host = sim.host_ns_at(k * T, sim.host_jitter_s("drive_host", 0, k.size))
    return Recording({"i_a": sim.current_samples(0, n)[0]}, sim.daq_rate_hz, k, sim.encoder_counts(0, k.size), T,
                     sim.counts_per_rev, bench.motor.pole_pairs, bench.motor.torque_constant_Nm_per_A, first, count,
                     block_host, enc_host)


def own_time_columns(rec: Recording) -> Recording:
    """The stamps two separate tools would write: each stream's own time from 0, on no shared clock."""
    assert rec.block_first_index is not None and rec.block_count is not None
    last = rec.block_first_index + rec.block_count - 1
    return replace(rec, block_host_ns=np.rint(last / rec.rate_hz * 1e9).astype(np.int64),
                   encoder_host_ns=np.rint(rec.encoder_index * rec.period_s * 1e9).astype(np.int64),
                   host_clock_shared=False)


@pytest.mark.parametrize("q", [0.0, 1.0, 37.3, 99.0, 100.0])
def test_the_copy_free_percentile_of_a_long_current_is_numpys(q: float) -> None:
    rng = np.random.default_rng(5)
    n = 1_300_001  # long enough for the chunked path; ties and a skewed tail included
    x = np.concatenate((np.round(3.0 * np.sin(np.arange(n - 1000) * 1e-3), 2), rng.exponential(5.0, 1000)))
    assert percentile_without_copy(x, q) == pytest.approx(np.percentile(x, q), rel=1e-15, abs=1e-15)
    x[n // 2] = np.nan
    assert np.isnan(percentile_without_copy(x, q))


def test_overlap_correlation_is_the_pearson_correlation_over_each_lags_overlap() -> None:
    rng = np.random.default_rng(0)
    x, y = rng.standard_normal(40), rng.standard_normal(55)
    lags, rho, overlap = overlap_correlation(x, y)
    for L in (-39, -12, 0, 7, 30, 54):
        i = int(np.flatnonzero(lags == L)[0])
        a, b = x[max(0, -L):min(x.size, y.size - L)], y[max(0, L):min(y.size, x.size + L)]
        assert overlap[i] == a.size == b.size
        if a.size > 1:
            assert rho[i] == pytest.approx(np.corrcoef(a, b)[0, 1], abs=1e-9)


@pytest.mark.parametrize("offset_s, drift_ppm", [(-2.0, 100.0), (-1.3, -100.0), (-0.2, 100.0), (0.05, -100.0),
                                                 (1.9, 100.0)])
def test_clock_from_the_data_alone_over_2s_and_100ppm(offset_s: float, drift_ppm: float) -> None:
    rec = separate_records(offset_s, drift_ppm)
    for untrusted in (own_time_columns(rec), replace(rec, block_host_ns=None, encoder_host_ns=None)):
        prep = prepare_signals(untrusted)
        clock = prep.clock
        assert clock.method == "angle"
        assert abs(clock.offset_s - offset_s) <= 50e-6
        assert abs(clock.drift_ppm - drift_ppm) <= 5.0
        assert np.isnan(clock.host_offset_s) and clock.ambiguous_by_s == ()
    assert "clock: the streams' time stamps are not on one host clock; aligned from the data alone" in prep.notes or \
        untrusted.block_host_ns is None


def test_host_stamps_of_a_daq_delivering_120ms_late_are_overruled_by_the_data() -> None:
    rec = separate_records(-0.3, 60.0)
    late = replace(rec, block_host_ns=rec.block_host_ns + 120_000_000)
    clock = prepare_signals(late).clock
    assert abs(clock.host_offset_s - (-0.3)) > 0.1  # the stamps alone are 120 ms off
    assert abs(clock.offset_s - (-0.3)) <= 50e-6 and abs(clock.drift_ppm - 60.0) <= 5.0
    (note,) = [n for n in clock.notes if "host stamps" in n]
    assert note == ("clock: the host stamps are +120 ms off the data's alignment (blocks delivered late?); the wide "
                    "search's offset is used")


def test_a_burst_of_late_encoder_stamps_does_not_tilt_the_host_relation() -> None:
    # a reader thread held off by the GIL for the first 0.4 s of a 4 s record stamps those frames 20 ms late:
    # a least-squares slope through every stamp read that as a drift of thousands of ppm (a failed serial session)
    rec = separate_records(0.037, 40.0, duration_s=4.0)
    late = rec.encoder_host_ns.copy()
    late[:400] += np.linspace(20_000_000, 0, 400).astype(np.int64)
    clock = prepare_signals(replace(rec, encoder_host_ns=late)).clock
    assert abs(clock.host_drift_ppm - 40.0) <= 100.0
    assert abs(clock.offset_s - 0.037) <= 50e-6 and abs(clock.drift_ppm - 40.0) <= 5.0


def test_an_offset_the_periodic_motion_leaves_open_is_reported_or_resolved_by_the_host_stamps() -> None:
    # the motion runs before either record starts: over the overlap the streams repeat every 0.4 s
    rec = separate_records(1.9, -20.0, t_motion_s=-1.0)
    alone = prepare_signals(replace(rec, block_host_ns=None, encoder_host_ns=None)).clock
    assert len(alone.ambiguous_by_s) >= 2
    truth_shift = 1.9 - alone.offset_s
    assert min(abs(d - truth_shift) for d in alone.ambiguous_by_s) < 0.005  # the truth is among the alternatives
    # whole cycles of 0.8 s: the half cycles, where |ω| repeats too, the angle stage tells apart (a mirrored angle)
    assert all(abs(d / 0.8 - round(d / 0.8)) < 0.0125 for d in alone.ambiguous_by_s)
    assert any(n.startswith("clock: offset ambiguous by repeats of the motion: shifted by ") for n in alone.notes)
    shared = prepare_signals(rec).clock
    assert abs(shared.offset_s - 1.9) <= 50e-6 and shared.ambiguous_by_s == ()
    assert shared.notes == ()  # resolved: no note of alternatives that the JSON's empty ambiguous_by_s denies


def test_a_mismatch_every_lag_shares_does_not_drop_the_true_lag_from_the_wide_search(tmp_path: Path) -> None:
    # trapezoid with dwell, seed 0: every lag's frequency tracks mismatch over ~0.1 s, measured 9 coarse samples
    # at the half-cycle lags and 10 at the true one; "no longer than the best's" kept only the half cycles (a
    # mirrored angle, residual ~490 µs) and the analysis failed with K +504 %
    from acq.offline.analyze import recording_from_session
    from acq.recording.reader import load
    from bench.scenarios import SCENARIOS, clock_for, record

    index = next(i for i, sc in enumerate(SCENARIOS) if sc.name == "trapezoid: 0.1 s cruise, 0.1 s dwell")
    offset_s, drift_ppm = clock_for(0, index)
    path, _ = record(SCENARIOS[index], 0, offset_s, drift_ppm, tmp_path)
    rec = replace(recording_from_session(load(path)), block_host_ns=None, encoder_host_ns=None)
    clock = prepare_signals(rec).clock
    shifts = np.array((0.0, *clock.ambiguous_by_s)) + clock.offset_s - offset_s
    # the truth is the offset or one of the reported alternatives (coarse: their shifts are given to 1 ms)
    assert abs(clock.offset_s - offset_s) <= 50e-6 or np.min(np.abs(shifts)) < 0.005
    assert np.all(np.abs(shifts / 1.2 - np.round(shifts / 1.2)) < 0.01)  # whole motion cycles of 1.2 s only


def test_the_frequency_stage_fits_only_the_offset_where_its_slope_would_need_an_implausible_drift() -> None:
    from analysis.clock_frequency import frequency_alignment
    from analysis.clock_model import MAX_DRIFT_PPM, plausible_drift

    t = np.arange(0.0, 10.0, 1e-3)
    moves = lambda x: 200.0 * np.clip(np.sin(2 * np.pi * 3.1 * x) + np.sin(2 * np.pi * 1.3 * x), 0, None)  # noqa: E731
    # the current's track lags the encoder's by 1 ms more every second: a line through the windows' lags needs
    # 1000 ppm — what a few scattered windows of motion give, never two crystal clocks
    f_cur = moves(t - (2e-3 + 1e-3 * t))
    offset_s, drift_ppm, n = frequency_alignment(f_cur, t, moves, 0.0, 30.0, 0.03)
    assert n == 5 and drift_ppm == 30.0  # the starting drift kept
    assert offset_s == pytest.approx(-7e-3, abs=0.2e-3)  # the median window's lag (the one at 5 s)
    # and where the lags do fit a plausible line, the slope is taken
    f_cur = moves(t - (2e-3 + 50e-6 * t))
    offset_s, drift_ppm, n = frequency_alignment(f_cur, t, moves, 0.0, 0.0, 0.03)
    assert drift_ppm == pytest.approx(-50.0, abs=5.0) and offset_s == pytest.approx(-2e-3, abs=0.1e-3)
    assert MAX_DRIFT_PPM == 200.0 and plausible_drift(-250.0, 30.0) and not plausible_drift(-31730.0, 1240.0)


def _windows(gap_after: tuple[int, ...], n: int = 40) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Angle-stage windows 20 ms apart with a pause of 1 s after each window index in ``gap_after``: the rows of
    (θ_0, offset, drift), weights, phases with a little noise, and the window times."""
    rng = np.random.default_rng(5)
    t_c = 0.02 * np.arange(n) + np.array([sum(1.0 for g in gap_after if i > g) for i in range(n)])
    k = rng.uniform(300.0, 1500.0, n)
    A = np.column_stack((2.0 * np.ones(n), k, k * (t_c - t_c.mean())))
    w = rng.uniform(0.5, 2.0, n)
    r = A @ np.array([0.1, 2e-5, 3e-6]) + rng.normal(0.0, 1e-3, n)
    return A, r, w, t_c


def test_the_move_jackknife_is_the_spread_of_the_fits_without_each_move() -> None:
    """Four moves (pauses after windows 9, 19, 29; the first window left out by the outlier rule): the covariance is
    (G − 1)/G·Σ (x_g − x̄)(x_g − x̄)ᵀ of the weighted least squares without move g, times (t/z)² (Student's t at G − 1
    degrees of freedom over the normal's z, both at 97.5 %), to 1e-9; a move whose absence leaves fewer than three
    windows gives NaN."""
    A, r, w, t_c = _windows((9, 19, 29))
    keep = np.ones(t_c.size, bool)
    keep[0] = False
    cov, n_moves = _move_jackknife(A, r, w, keep, t_c)
    assert n_moves == 4
    moves = [np.arange(1, 10), np.arange(10, 20), np.arange(20, 30), np.arange(30, 40)]
    fits = []
    for rows in moves:
        rest = keep.copy()
        rest[rows] = False
        sw = np.sqrt(w[rest])
        fits.append(np.linalg.lstsq(A[rest] * sw[:, None], r[rest] * sw, rcond=None)[0])
    x = np.array(fits)
    d = x - x.mean(axis=0)
    t_over_z = stats.t.ppf(0.975, 3) / stats.norm.ppf(0.975)  # 3.182 / 1.960
    np.testing.assert_allclose(cov, t_over_z**2 * 3.0 / 4.0 * d.T @ d, rtol=1e-9, atol=1e-30)
    # three moves, the first two one window each: without the third only two windows are left
    A, r, w, t_c = _windows((0, 1))
    cov, n_moves = _move_jackknife(A, r, w, np.ones(t_c.size, bool), t_c)
    assert n_moves == 3 and np.all(np.isnan(cov))
