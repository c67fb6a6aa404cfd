"""Stage 1 of the clock alignment: the relation from the host arrival stamps of both streams (design §4).

When both streams carry arrival stamps on one host clock (a recording, not two files from separate tools), the
stamps give the relation of :mod:`analysis.clock_model` to a few ms — if the transfer latencies are steady.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from scipy import stats

_ENVELOPE_PIECES = 8  # pieces of a record whose least-delayed host stamps give the host relation's slope
_CREEP_PIECES = 16  # pieces whose least-delayed host stamps tell a creeping latency (_creep_std)
#: Stamps that all lie on their line to within this, s, were computed from the stream's own clock, not taken at arrival
#: (an imported CSV's current: DAQ time placed on the host timeline, rounded to its 1 ns): a real arrival carries the
#: host's latency scatter, microseconds at the least. 2 ns: the 1 ns rounding of each of two stamps.
_COMPUTED_STAMPS_S = 2e-9


class HostRelation(NamedTuple):
    """The clock relation the host stamps give: offset_s, s, drift_ppm, ppm, and the drift's standard error, ppm,
    from the scatter of the least-delayed stamps about their lines and their bow where a latency crept
    (:func:`lower_line`; NaN with too few pieces to tell)."""

    offset_s: float
    drift_ppm: float
    drift_std_ppm: float


def host_relation(daq_last_index: np.ndarray, daq_host_ns: np.ndarray, rate_hz: float,
                  encoder_index: np.ndarray, encoder_host_ns: np.ndarray, period_s: float) -> HostRelation:
    """Stage 1: offset, s, and drift, ppm (with its standard error), from host arrival stamps.

    Each stream's host time is fitted as a line of its own time (DAQ: the last sample of each block;
    encoder: each sample), shifted to the 2nd percentile of the residual (the least-delayed
    arrivals), and the two lines are composed.

    Parameters
    ----------
    daq_last_index : ndarray of int
        DAQ sample index of the last sample of each block.
    daq_host_ns : ndarray of int
        Host monotonic time each block arrived, ns.
    rate_hz : float
        DAQ sample rate, Hz.
    encoder_index : ndarray of int
        Drive cycle of each encoder sample.
    encoder_host_ns : ndarray of int
        Host monotonic arrival time of each encoder sample, ns.
    period_s : float
        Drive cycle, s.
    """
    ref_ns = int(min(np.min(daq_host_ns), np.min(encoder_host_ns)))
    a_d, b_d, sb_d = lower_line(np.asarray(daq_last_index) / rate_hz, (np.asarray(daq_host_ns) - ref_ns) * 1e-9)
    a_e, b_e, sb_e = lower_line(np.asarray(encoder_index) * period_s, (np.asarray(encoder_host_ns) - ref_ns) * 1e-9)
    return HostRelation((a_d - a_e) / b_e, (b_d / b_e - 1.0) * 1e6, float(np.hypot(sb_d, sb_e)) * 1e6)


def lower_line(x: np.ndarray, y: np.ndarray) -> tuple[float, float, float]:
    """The line under the least-delayed arrivals: (intercept, slope, the slope's standard error) of host time ``y``
    against stream time ``x``.

    Arrival delays are one-sided and bursty (a thread held off for 20 ms stamps a whole run late), so a
    least-squares slope through every stamp tilts by delay/duration — thousands of ppm on a 4 s record.
    As clock filters do (NTP keeps the minimum-delay sample), the slope is fitted through the least-delayed
    stamp of each of up to ``_ENVELOPE_PIECES`` equal pieces of the record; the intercept is then moved
    down to the 2nd percentile of the residual. The slope's standard error is the least-squares one of those
    stamps (their scatter about the line: what is left of the delays at the least-delayed arrivals) and, where they
    bow away from the line, the latency's creep (:func:`_creep_std`); NaN with fewer than four pieces (one degree
    of freedom or none), or when every stamp lies on the line to :data:`_COMPUTED_STAMPS_S` (computed stamps tell
    nothing of the drift between the clocks).
    """
    if x.size < 2:
        return float(np.min(y - x)), 1.0, float("nan")
    least = _least_delayed(x, y, min(_ENVELOPE_PIECES, x.size))
    if least.size < 4:
        b, b_std = float(np.polyfit(x[least], y[least], 1)[0]), float("nan")
    else:
        (b, _), cov = np.polyfit(x[least], y[least], 1, cov=True)
        b_std = float(np.hypot(np.sqrt(cov[0, 0]), _creep_std(x, y)))
    if np.ptp(y - b * x) <= _COMPUTED_STAMPS_S:
        b_std = float("nan")
    return float(np.percentile(y - b * x, 2.0)), float(b), b_std


def _least_delayed(x: np.ndarray, y: np.ndarray, pieces: int) -> np.ndarray:
    """Index of the least-delayed stamp (host time ``y`` − stream time ``x``, both s: the nominal slope is 1) in each of
    ``pieces`` equal pieces of the record."""
    delay = y - x
    return np.array([p[np.argmin(delay[p])] for p in np.array_split(np.arange(x.size), pieces)])


def _creep_std(x: np.ndarray, y: np.ndarray) -> float:
    """What a latency whose rate changed during the record leaves open of the slope of host time ``y`` (s) against
    stream time ``x`` (s): the standard error to add to the least-squares one, from the bow of the least-delayed
    stamps about their line.

    The least-squares error takes the stamps' departures from the line as independent scatter. A latency that creeps
    (a queue backing up: 0.3 ms over a 6 s record) lays the least-delayed stamps on a curve instead: the slope under
    them moves along the record, by 2·c·T from end to end for a quadratic term c (s/s²) over the record's T (s),
    and the line's slope is the one in the middle, c·T from those at the ends — where a latency steady before or
    after the creep gives the clocks' own drift. So a bow adds c·T, once c stands out of its own scatter (Student's
    t at 97.5 %). The bow is read on the least-delayed stamps of :data:`_CREEP_PIECES` pieces, more degrees of freedom
    for the quadratic's error than the slope's :data:`_ENVELOPE_PIECES` leave. Synthetic 6 s records (60 DAQ blocks,
    0.2 ms jitter, tests/test_clock_host.py), 200 seeds: the interval holds the truth through a creep of 0.3 ms in 106
    (88 on 8 pieces, 0 before), through one of 1 ms in all; ordinary jitter is taken for a creep in 17 (the others keep
    their least-squares error). Of a latency shrinking by 0.3 ms (a queue draining) 73 hold: the last four of 60 blocks'
    16 pieces hold three stamps to the others' four, and their higher minima bow jitter alone by c·T ≈ +9 ppm, toward
    the rising creep. With that bias and the minima's scatter both taken from the stamps' own delays (the moments of a
    piece's least delay drawn from all of them), a 0.3 ms creep bows c·T = 50 ± 27 ppm, jitter alone 2 ± 27: no rule on
    these stamps holds the first without widening the second alike. Continuous terms, T·√max(ĉ² − k·s_c², 0), measured
    on the same seeds (0/0.3/0.5/1 ms held; jittered records widened): k = 1 192/156/186/200, 106 widened (66 over 2×);
    k = 4 183/100/157/199, 20 — and widening the host drift of sim_robot 10 s windows hands their drift to the angle
    stage, whose interval held the truth in 36 of 42, 37 with its t (k = 1: combined drift's worst error 8.2 → 19.4
    ppm). A block jackknife of the slope over four parts of the record widens by a fraction of c·T only (its parts'
    slopes spread about the line's): it held the truth in 9 of 40 records of a 0.3 ms creep. A latency growing at one
    rate all along bows nothing: on one stream's stamps it is a drift, and no error can show it. 0 with fewer than six
    pieces.
    """
    n = min(_CREEP_PIECES, x.size)
    if n < 6:
        return 0.0
    least = _least_delayed(x, y, n)
    (c, _, _), cov = np.polyfit(x[least] - np.mean(x[least]), y[least], 2, cov=True)
    if abs(c) <= float(stats.t.ppf(0.975, n - 3)) * np.sqrt(cov[0, 0]):
        return 0.0
    return abs(float(c)) * float(np.ptp(x))
