"""The host stamps' drift and its error (analysis.clock_host) on synthetic stamp series: a true drift, a latency that
creeps during the window, and the simulator's arrival jitter (|N(0, 0.2 ms)|, drivers/sim/bench.py).

An independent review read 90.7 ± 4.6 ppm against a true 40 ppm on a 6 s window whose DAQ stamps carried a slowly
growing latency: the least-squares error of the least-delayed stamps took their bow about the line for scatter.
"""

from __future__ import annotations

import numpy as np

from analysis.clock_host import HostRelation, host_relation
from analysis.fit import Z95

TRUE_DRIFT_PPM = 40.0
RATE_HZ, BLOCK, PERIOD_S, WINDOW_S, JITTER_S = 25600.0, 2560, 0.001, 6.0, 2e-4


def stamped(seed: int, creep_s: float = 0.0, shape: str = "accelerating") -> HostRelation:
    """The host relation of a ``WINDOW_S`` record: DAQ blocks (stamped at their last sample) and 1 kHz encoder cycles
    on one host clock, the DAQ's clock ``TRUE_DRIFT_PPM`` fast; the DAQ's latency grows by ``creep_s`` (s) over the
    window, quadratically from a standstill (``accelerating``), or steady for its first half and then at one rate
    (``late``)."""
    rng = np.random.default_rng(seed)
    last = np.arange(BLOCK - 1, int(WINDOW_S * RATE_HZ), BLOCK)
    t_daq = last / RATE_HZ
    u = t_daq / WINDOW_S
    creep = creep_s * (u**2 if shape == "accelerating" else np.clip(2.0 * u - 1.0, 0.0, 1.0))
    daq_host_s = 0.037 + t_daq * (1.0 + TRUE_DRIFT_PPM * 1e-6) + 0.002 + creep + np.abs(rng.normal(0, JITTER_S, u.size))
    cycle = np.arange(int(WINDOW_S / PERIOD_S))
    enc_host_s = cycle * PERIOD_S + 0.001 + np.abs(rng.normal(0, JITTER_S, cycle.size))
    return host_relation(last, np.rint(daq_host_s * 1e9).astype(np.int64), RATE_HZ, cycle,
                         np.rint(enc_host_s * 1e9).astype(np.int64), PERIOD_S)


def holds_truth(r: HostRelation) -> bool:
    return abs(r.drift_ppm - TRUE_DRIFT_PPM) <= Z95 * r.drift_std_ppm


def test_a_latency_creeping_by_1ms_widens_the_drift_error_to_hold_the_truth() -> None:
    relations = [stamped(seed, 1e-3) for seed in range(20)]
    drift = np.array([r.drift_ppm for r in relations])
    assert 190.0 < np.median(drift) < 215.0  # the creep reads as a drift (truth 40): no stamp can tell the two apart
    assert sum(holds_truth(r) for r in relations) == 20  # before: 0 of 20 (207.7 ± 18.1 ppm at 95 %)
    assert min(r.drift_std_ppm for r in relations) > 80.0


def test_the_reviewers_creep_of_0_3ms_widens_the_error_where_the_stamps_bow_beyond_their_scatter() -> None:
    """0.3 ms on 60 DAQ stamps of 0.2 ms jitter bows the least-delayed ones by a sagitta of ~40 µs, at the edge of
    what their scatter lets be seen: about half of such windows are caught (106 of 200 seeds; 0 before)."""
    relations = [stamped(seed, 3e-4) for seed in range(40)]
    assert sum(holds_truth(r) for r in relations) == 26  # before: 0 (91.7 ± 7.4 ppm at 95 %, the review's figure)
    late = [stamped(seed, 3e-4, shape="late") for seed in range(40)]
    assert sum(holds_truth(r) for r in late) == 39  # a latency steady, then growing: before 0


def test_ordinary_jittered_stamps_keep_their_least_squares_error() -> None:
    """Without a creep the error is the least-squares one of the least-delayed stamps in 34 of 40 windows (the bow of
    the others' least-delayed stamps stands out of their scatter by chance: 17 of 200 seeds), within 14 times it in
    all; the median, 4.6 ppm, within 1 %."""
    relations = [stamped(seed) for seed in range(40)]
    stds = np.array([r.drift_std_ppm for r in relations])
    least_squares = np.array([_least_squares_std_ppm(seed) for seed in range(40)])
    ratio = stds / least_squares
    assert np.sum(np.isclose(ratio, 1.0, rtol=1e-3)) == 34 and ratio.max() < 14.0
    assert np.median(stds) / np.median(least_squares) < 1.01 and 4.0 < np.median(stds) < 5.0
    assert sum(holds_truth(r) for r in relations) == 35


def _least_squares_std_ppm(seed: int) -> float:
    """The drift's error as the white-noise least squares of each stream's least-delayed stamps (8 pieces) gives it:
    the error before the creep was counted."""
    rng = np.random.default_rng(seed)
    last = np.arange(BLOCK - 1, int(WINDOW_S * RATE_HZ), BLOCK)
    t_daq = last / RATE_HZ
    daq = t_daq * (1.0 + TRUE_DRIFT_PPM * 1e-6) + np.abs(rng.normal(0, JITTER_S, t_daq.size))
    cycle = np.arange(int(WINDOW_S / PERIOD_S)) * PERIOD_S
    enc = cycle + np.abs(rng.normal(0, JITTER_S, cycle.size))
    variances = []
    for x, y in ((t_daq, daq), (cycle, enc)):
        pieces = np.array_split(np.arange(x.size), 8)
        least = np.array([p[np.argmin((y - x)[p])] for p in pieces])
        variances.append(np.polyfit(x[least], y[least], 1, cov=True)[1][0, 0])
    return float(np.sqrt(sum(variances))) * 1e6
