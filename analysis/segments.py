"""Segment selection: the Welch segments in which the motion excites the joint, and the moves that do.

A production robot's program excites the joint only in parts: fast moves put torque steps into the
band, while pauses, slow moves and cruising leave the torque flat, and there the speed holds only the
encoder's noise and the speed loop's reaction to it (closed loop: torque caused by the speed noise, not
the other way round). Averaging those segments into the Welch estimate adds noise to G_yy and feedback to
G_xy without adding excitation; selecting the exciting segments keeps the estimate to where the data
carries it (:func:`select_segments`).

The criterion comes from the window's own data, segment by segment: with H the window's H1 over all
segments (weighted by torque power, so it is the exciting segments' response), a segment's in-band speed
splits into what its torque explains, S = Σ|H·X|², and the rest, N = Σ|Y − H·X|² (noise, feedback,
distortion). S > N says the torque explains more of the segment's speed than anything else does (its own
coherence above 1/2). A segment that does not excite has S/N ≤ 1 — exactly 1 when its speed is still
(Y = 0: N = S), below 1 when its speed is unrelated to its torque — so the segment is kept only when S/N
exceeds what chance gives such a segment: the 99 % point of an F distribution with the degrees of freedom
of the in-band bins (2 per bin over the Hann window's equivalent noise bandwidth in bins). No level is
tuned on a simulator: S and N are measured in the segment, the limit follows from the number of bins.

Kept segments of one segmentation are contiguous runs; averaging their cross spectra weighted by the
number of segments is the same as :func:`scipy.signal.csd` on each run (whose segments are the same)
averaged with weights by segment count, and a run shorter than one segment does not exist by
construction. :func:`describe_moves` cuts the motion into moves (rest to rest, from the encoder speed)
and says which of them the kept segments cover.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import stats

from analysis import welch

#: A kept segment "covers" the time of its middle half, where its Hann weight is ≥ 1/2; with 50 % overlap
#: these middle halves tile the record, so the share of kept segments is the share of excited time.
MIDDLE_HALF = (0.25, 0.75)
#: A speed above the rest threshold for fewer than this many drive periods is noise, not a move; gaps shorter
#: than this between two stretches of motion are one move (a trapezoid crosses the threshold once each way).
MIN_RUN_PERIODS = 5
#: Confidence with which a kept segment's S/N is above what a segment without excitation shows.
SIGNIFICANCE = 0.99
#: Segments that must excite for the selection to apply: the H1 estimate and coherence of a single segment are exact
#: by construction (|γ|² = 1 whatever the data), so one segment alone says nothing; below this every segment is used.
MIN_SEGMENTS = 2
#: Rest threshold in robust standard deviations of the speed noise (a Gaussian exceeds 5 σ in 6e-7 of samples).
REST_SIGMAS = 5.0
#: ... and never below this many encoder counts per drive period (quantisation: the speed's resolution).
REST_MIN_COUNTS_PER_PERIOD = 2.0


@dataclass(frozen=True)
class SegmentSelection:
    """Which Welch segments of one segmentation excite the joint.

    Attributes
    ----------
    keep : ndarray of bool
        One per segment of the record's segmentation (start k·step), True where the segment is used.
    snr : ndarray
        S/N of each segment in the band (explained / unexplained speed power, see module docstring).
    snr_limit : float
        The S/N above which a segment excites (the F distribution's :data:`SIGNIFICANCE` point).
    nperseg, step : int
        Segment length and hop, samples.
    applied : bool
        False when fewer than :data:`MIN_SEGMENTS` segments pass (then every segment is used and the verdict judges).
    """

    keep: np.ndarray
    snr: np.ndarray
    snr_limit: float
    nperseg: int
    step: int
    applied: bool

    @property
    def excited(self) -> int:
        """How many segments excite (S/N above :attr:`snr_limit`), whether or not the selection applies."""
        return int(np.sum(self.snr > self.snr_limit))

    @property
    def excited_fraction(self) -> float:
        """Share of the segments that excite (= share of the record's time, see :data:`MIDDLE_HALF`)."""
        return self.excited / self.snr.size if self.snr.size else 0.0

    def runs(self) -> list[tuple[int, int]]:
        """Contiguous runs of kept segments as (first, last + 1) segment indices."""
        starts, ends = _runs(self.keep)
        return list(zip(starts.tolist(), ends.tolist()))

    def covered_s(self, period_s: float) -> list[tuple[float, float]]:
        """Time spans (s from the record's first sample) that the kept segments' middle halves cover."""
        lo, hi = MIDDLE_HALF
        return [((a * self.step + lo * self.nperseg) * period_s, ((b - 1) * self.step + hi * self.nperseg) * period_s)
                for a, b in self.runs()]


def excitation_summary(excited_moves: int, moves: int, band_hz: tuple[float, float], excited_fraction: float,
                       span: str = "record") -> str:
    """How much of a record excites the joint, in words: "2 of the record's 12 moves put torque into 10…400 Hz beyond
    chance; time that does: 8 % of the record" (``span``: what the record is called — a monitor's "window"). The two
    counts are apart: moves (rest to rest) that a kept segment covers, and the share of the record's time in kept
    segments (:attr:`SegmentSelection.excited_fraction`), which can excite outside every move."""
    return (f"{excited_moves} of the {span}'s {moves} moves put torque into {band_hz[0]:g}…{band_hz[1]:g} Hz beyond "
            f"chance; time that does: {100 * excited_fraction:.0f} % of the {span}")


def segments_summary(excited: int, segments: int, needed: int, snr_limit: float, snr_max: float | None) -> str:
    """Why a record's segment selection did not apply, in words (the figures of :class:`SegmentSelection`): "0 of 19
    Welch segments excite — in-band S/N above 2.31, chance's 99 % point, the largest 1.42; the selection needs 2" (the
    largest S/N said only when none excite: how far the best segment fell short)."""
    largest = f", the largest {snr_max:.2f}" if excited == 0 and snr_max is not None else ""
    return (f"{excited} of {segments} Welch segments excite{'s' * (excited == 1)} — in-band S/N above "
            f"{snr_limit:.2f}, chance's {100 * SIGNIFICANCE:g} % point{largest}; the selection needs {needed}")


def select_segments(X: np.ndarray, Y: np.ndarray, in_band: np.ndarray, nperseg: int, step: int) -> SegmentSelection:
    """Keep the segments whose torque explains more of their in-band speed than the rest does.

    Parameters
    ----------
    X, Y : ndarray of complex, shape (segments, bins)
        Windowed, detrended segment FFTs of torque (N·m) and speed (rad/s), one-sided bins first.
    in_band : ndarray of bool, shape (bins,)
        The bins of the band the selection judges (the fit band).
    nperseg, step : int
        Segment length and hop, samples.

    Returns
    -------
    SegmentSelection
    """
    x, y = X[:, : in_band.size][:, in_band], Y[:, : in_band.size][:, in_band]
    with np.errstate(divide="ignore", invalid="ignore"):
        h = np.nan_to_num(np.sum(np.conj(x) * y, axis=0) / np.sum(np.abs(x) ** 2, axis=0))
        explained = np.sum(np.abs(h * x) ** 2, axis=1)
        rest = np.sum(np.abs(y - h * x) ** 2, axis=1)
        snr = np.nan_to_num(explained / rest, nan=0.0, posinf=np.finfo(float).max)
    window = welch.hann(nperseg)
    enbw_bins = nperseg * float(np.sum(window**2)) / float(np.sum(window)) ** 2  # 1.5 for Hann
    dof = 2.0 * int(in_band.sum()) / enbw_bins
    limit = float(stats.f.ppf(SIGNIFICANCE, dof, dof))
    keep = snr > limit
    applied = int(keep.sum()) >= MIN_SEGMENTS
    return SegmentSelection(keep if applied else np.ones_like(keep), snr, limit, nperseg, step, applied)


@dataclass(frozen=True)
class Move:
    """One move of the joint, rest to rest, as the encoder saw it.

    Attributes
    ----------
    index : int
        Number of the move in the record, from 0.
    start_s, duration_s : float
        Start (drive time, s) and duration, s.
    peak_rad_s : float
        Largest |motor speed| during the move, rad/s.
    excited : bool
        True when a kept segment's middle half overlaps the move.
    """

    index: int
    start_s: float
    duration_s: float
    peak_rad_s: float
    excited: bool


def describe_moves(t_s: np.ndarray, speed_rad_s: np.ndarray, period_s: float, counts_per_rev: int,
                   min_travel_rad: float, selection: SegmentSelection) -> list[Move]:
    """Cut the motion into moves and say which ones the selected segments cover.

    Rest is |speed| below :data:`REST_SIGMAS` robust standard deviations of the speed noise (from the median
    absolute first difference, which rest and cruise dominate, where the difference is noise) and never below
    :data:`REST_MIN_COUNTS_PER_PERIOD` counts per period. A stretch of motion that travels less than
    ``min_travel_rad`` (settling or ring-out after a stop) is not a move.

    Parameters
    ----------
    t_s : ndarray
        Drive time of each speed sample, s (the grid the segments were cut from).
    speed_rad_s : ndarray
        Motor speed on the drive's regular grid, rad/s.
    period_s : float
        Grid period, s.
    counts_per_rev : int
        Encoder counts per motor revolution.
    min_travel_rad : float
        Shortest travel of a move, rad (the pipeline gives half an electrical revolution: less cannot be analysed).
    selection : SegmentSelection
        The segments kept, on the same grid.

    Returns
    -------
    list of Move
    """
    v = np.abs(np.asarray(speed_rad_s, dtype=float))
    if v.size < 2:
        return []
    sigma = 1.4826 * float(np.median(np.abs(np.diff(speed_rad_s)))) / np.sqrt(2.0)
    threshold = max(REST_SIGMAS * sigma, REST_MIN_COUNTS_PER_PERIOD * 2 * np.pi / counts_per_rev / period_s)
    starts, ends = _runs(v > threshold)
    if starts.size == 0:  # the joint never left rest
        return []
    # close gaps shorter than MIN_RUN_PERIODS, then drop blips shorter than it
    join = starts[1:] - ends[:-1] >= MIN_RUN_PERIODS
    starts, ends = starts[np.concatenate(([True], join))], ends[np.concatenate((join, [True]))]
    travel = np.array([float(np.sum(v[a:b])) * period_s for a, b in zip(starts, ends)])
    long_enough = (ends - starts >= MIN_RUN_PERIODS) & (travel >= min_travel_rad)
    covered = [(t_s[0] + lo, t_s[0] + hi) for lo, hi in selection.covered_s(period_s)] if selection.applied else []
    moves = []
    for i, (a, b) in enumerate(zip(starts[long_enough], ends[long_enough])):
        t0, t1 = t_s[a], t_s[b - 1] + period_s
        moves.append(Move(i, float(t0), float(t1 - t0), float(v[a:b].max()),
                          any(lo < t1 and hi > t0 for lo, hi in covered)))
    return moves


def _runs(mask: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Starts and ends (exclusive) of the True runs of ``mask``."""
    edges = np.diff(np.concatenate(([0], mask.astype(np.int8), [0])))
    return np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
