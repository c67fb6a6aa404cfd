"""Does the current turn as fast as the encoder says it should? (used by ``acq selftest`` and by the verdict).

The current's electrical frequency f_e (zero crossings of i_a) must equal p·|ω|/2π with p the stated ``pole_pairs``
and ω the speed from the encoder counts scaled by the stated ``counts_per_rev``. A wrong constant makes the ratio
r = f_e / (p·|ω|/2π) = (p_true/p)·(counts_per_rev/counts_per_rev_true) differ from 1 — the clock alignment then
fails without saying why. :func:`electrical_speed_ratio` measures r (the clock lag is searched), :func:`ratio_fault`
words a wrong constant the data establish and :func:`ratio_doubt` a mismatch they do not; the selftest and
``acq analyze`` print the same text.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import signal
from scipy.ndimage import median_filter

from analysis.encoder import longest_gap_free_span, speed_from_counts
from analysis.zero_crossings import crossing_frequency_hz, current_crossings_s

GRID_HZ = 200.0  # grid of the lag search, Hz: the speed's shape (≤ 20 Hz for a triangle) is well inside
MAX_LAG_S = 2.0  # clock offsets searched, s: the design's plausible range of DAQ vs drive start (§4)
#: A ratio off 1 by less is not named: 5 standard errors of the estimate, never below 3 % — below the
#: smallest pole-pair error of a motor with ≤ 32 pole pairs (1/33), above the estimator's bias on
#: simulated records (1.005 ± 0.001 on a 10 s 1000 rpm session, 1.019 ± 0.004 on the selftest's 200 rpm move;
#: over the 48 correctly configured scenarios of bench/scenarios.py, seed 0: 0.9997 … 1.010).
MIN_RATIO_ERROR = 0.03
RATIO_SIGMAS = 5.0
#: Cosine similarity of the two electrical-frequency shapes at the chosen lag below which the lag is not
#: trusted (the true lag lies outside ±MAX_LAG_S, or one stream did not see the motion): no verdict then.
MIN_SHAPE_SIMILARITY = 0.5
#: Relative scatter (1.4826·MAD / median) of the half-periods' ratios above which they do not share one ratio:
#: a wrong bench constant scales every half-period alike (their scatter is the counting's few %), while a lag
#: locked onto the wrong one of a robot's repeated moves scatters them by factors (seen: 0.8 … 10⁵ around a
#: median of 6.6 on a simulated S-curve window) — no verdict then, rather than a wrong constant to "check".
MAX_RELATIVE_SCATTER = 0.25
REFINE_LAG_S, REFINE_STEP_S = 0.015, 0.0005  # lag refinement ±, step, s: three grid steps of the search, 0.5 ms
REFINE_SPAN_S = 20.0  # record span the ratio uses, s: 100 ppm of clock drift moves the lag ≤ 2 ms over it
#: Half-width, in half-periods of the rotation, within which a crossing counts as on the lattice of a ratio: the
#: current crosses zero at fixed electrical angles, so at the true ratio a move's crossings sit on one lattice of
#: spacing ½/(p·r) revolutions. ±1/8 is 3× the spread of a correct bench's crossings about theirs on the selftest's slow
#: move (±0.04: the current's offset against the hysteresis, the lag's 0.5 ms step), and a ratio of small whole
#: numbers p'/p spreads the crossings over p' phases ≥ 1/4 apart at the other's lattice, one of which it counts.
#: On the 49 correctly configured scenarios (seed 0) ratio 1's lattice holds all crossings but 24…27 in 25 moves.
LATTICE_HALF_WIDTH = 0.125


@dataclass(frozen=True)
class SpeedRatio:
    """The current's electrical half-periods against p·(revolutions the encoder travelled meanwhile).

    Attributes
    ----------
    ratio : float
        Median over the current's half-periods of ½ / (p · encoder revolutions in it): 1 on a correct bench.
    spread : float
        Standard error of ``ratio`` (from the MAD of the half-periods).
    lag_s : float
        Time since the first encoder sample minus time since DAQ sample 0 at which the two speed shapes
        match best, s (to the lag grid; searched ±``MAX_LAG_S`` around "both streams started together").
    cycles : float
        Electrical cycles (half-periods / 2) that entered the ratio.
    crossings : int
        Zero crossings of the current counted inside the moves (the encoder turning one way faster than 20 % of
        its peak) of the span the ratio used.
    half_turns : float
        Electrical half-turns the encoder travelled in those moves (the stated constants: 2·p·revolutions).
    moves : int
        Number of those moves.
    moving_s : float
        Their total duration, s.
    on_lattice : tuple of int
        Crossings in the moves on one lattice per move (:data:`LATTICE_HALF_WIDTH`) at ratio 1 and at the best ratio
        within :attr:`tolerance` of ``ratio`` (:func:`_on_lattice`); (0, 0) when not counted.
    """

    ratio: float
    spread: float
    lag_s: float
    cycles: float
    crossings: int = 0
    half_turns: float = 0.0
    moves: int = 0
    moving_s: float = 0.0
    on_lattice: tuple[int, int] = (0, 0)

    @property
    def tolerance(self) -> float:
        """How far off 1 the ratio may be on a correct bench: :data:`RATIO_SIGMAS` standard errors, at least
        :data:`MIN_RATIO_ERROR` (the estimator's bias)."""
        return max(MIN_RATIO_ERROR, RATIO_SIGMAS * self.spread)

    @property
    def mismatched(self) -> bool:
        """True when the ratio is off 1 by more than :attr:`tolerance`."""
        return abs(self.ratio - 1.0) > self.tolerance

    @property
    def count_range(self) -> tuple[float, float]:
        """The ratios the crossings counted in the moves allow, each end widened by :attr:`tolerance`.

        Rotation puts a crossing at every electrical half-turn, so a move through h of them holds h ± 1 (its
        ends cut half-periods); the torque's reversal — once in a move from rest to rest, which accelerates,
        then brakes — adds one, and only adds. Over M moves, H half-turns and n crossings: ratio in
        [(n − 2M)/H, (n + M)/H]. Nothing counted (``half_turns`` 0): ``ratio`` ± tolerance.
        """
        if self.half_turns <= 0:
            return self.ratio - self.tolerance, self.ratio + self.tolerance
        return ((self.crossings - 2 * self.moves) / self.half_turns - self.tolerance,
                (self.crossings + self.moves) / self.half_turns + self.tolerance)

    @property
    def counted(self) -> bool:
        """True when the count allows the ratio the half-periods read (it lies in :attr:`count_range`). The
        half-periods' median is carried by non-rotation intervals when the moves hold few half-turns (a torque
        reversal cuts one in two; all moves alike when the motion repeats: their scatter stays small); the count
        cannot be: it needs no half-period to be whole."""
        low, high = self.count_range
        return low <= self.ratio <= high

    @property
    def whole(self) -> bool:
        """True when the moves hold mostly whole half-periods, so their median is the rotation's: more than twice
        the crossings a move can hold that do not end one (a torque reversal cuts one in two, each end cuts one:
        4), on average. Vacuous (True) when nothing was counted."""
        return self.crossings > 2 * 4 * self.moves

    @property
    def lattice_excludes_one(self) -> bool:
        """True when the crossings' positions hold ``ratio`` and rule out 1: the current crosses zero at fixed
        electrical angles, so the rotation's crossings sit on one lattice per move at the true ratio, and only the
        others (a torque reversal: one a move, a few more where the torque rings) leave it. At least
        ``crossings − moves`` on the lattice at ``ratio``, and more than one a move fewer at 1, is a rotation at
        ``ratio``: on a correct bench ratio 1's lattice holds every rotation crossing, as many as any other ratio's.
        A count that allows both (few half-turns per move, where each move's ends and reversal weigh) cannot tell
        them apart; the positions can."""
        at_one, at_ratio = self.on_lattice
        return self.crossings > 0 and at_ratio >= self.crossings - self.moves and at_one < at_ratio - self.moves

    @property
    def named(self) -> bool:
        """True when the data establish a wrong constant: :attr:`mismatched`, :attr:`counted`, and 1 outside the
        :attr:`count_range` or ruled out by the crossings' positions (:attr:`lattice_excludes_one`)."""
        low, high = self.count_range
        return self.mismatched and self.counted and (not low <= 1.0 <= high or self.lattice_excludes_one)


def electrical_speed_ratio(current_a: np.ndarray, rate_hz: float, encoder_index: np.ndarray,
                           position_counts: np.ndarray, period_s: float, counts_per_rev: int,
                           pole_pairs: int) -> SpeedRatio | None:
    """Measure f_e against p·|ω|/2π over a record; None when it holds too little motion to tell.

    The lag between the clocks comes from the shapes of the two electrical frequencies (same shape up
    to the ratio, :func:`analysis.zero_crossings.current_crossings_s` and
    :func:`~analysis.zero_crossings.crossing_frequency_hz` as in the clock alignment); then each half-period of the
    current, between two zero crossings, is set against the encoder's travel over the same interval (moving
    intervals only: faster than 20 % of the peak). A lag error of a few ms shifts both ends of an interval alike,
    so it barely matters.

    Parameters
    ----------
    current_a : ndarray
        One phase current, A, gap-free, DAQ sample 0 at t_daq = 0.
    rate_hz : float
        DAQ rate, Hz.
    encoder_index, position_counts : ndarray of int
        Drive cycle and unwrapped position, counts, of each encoder sample.
    period_s : float
        Drive cycle, s.
    counts_per_rev, pole_pairs : int
        The bench's stated encoder resolution and pole pairs.
    """
    span = longest_gap_free_span(np.asarray(encoder_index))
    if span.count < 3 or current_a.size < 3:
        return None
    cycles = np.asarray(encoder_index)[span.start:span.stop] - int(encoder_index[0])  # both streams from their start
    counts = np.asarray(position_counts)[span.start:span.stop]
    omega = speed_from_counts(counts, counts_per_rev, period_s)
    t_enc = cycles[1:] * period_s
    grid_enc = np.arange(t_enc[0], t_enc[-1], 1.0 / GRID_HZ)
    f_enc = _smooth(np.interp(grid_enc, t_enc, pole_pairs * np.abs(omega) / (2 * np.pi)))
    grid_daq = np.arange(0.0, current_a.size / rate_hz, 1.0 / GRID_HZ)
    crossings = current_crossings_s(current_a, rate_hz)
    f_cur = crossing_frequency_hz(crossings, grid_daq)
    if not (np.any(f_cur > 0) and np.any(f_enc > 0)):
        return None
    # f_cur[i] at DAQ time i/G matches r·f_enc at drive time i/G + lag: the lag where the shapes correlate
    xc = signal.correlate(f_enc, f_cur, mode="full", method="fft")
    shifts = np.arange(-f_cur.size + 1, f_enc.size)  # f_enc index − f_cur index
    t_lag = grid_enc[0] + shifts / GRID_HZ
    allowed = np.abs(t_lag) <= MAX_LAG_S
    if not np.any(allowed & (xc > 0)):
        return None
    best = int(np.flatnonzero(allowed)[np.argmax(xc[allowed])])
    lag_s = float(t_lag[best])
    if xc[best] < MIN_SHAPE_SIMILARITY * math.sqrt(float(np.dot(f_enc, f_enc)) * float(np.dot(f_cur, f_cur))):
        return None
    # each half-period of the current (between two zero crossings) against the encoder's travel meanwhile;
    # the lag is refined to the one that makes the half-periods agree best (a lag error τ scatters them by
    # ±τ·α/ω, accelerating against decelerating), on the first REFINE_SPAN_S (a clock drift bends it later)
    early = crossings < crossings[0] + REFINE_SPAN_S
    taus = lag_s + np.arange(-REFINE_LAG_S, REFINE_LAG_S + 1e-12, REFINE_STEP_S)
    scatter = _half_period_scatter(crossings[early], taus, cycles, counts, period_s, counts_per_rev, pole_pairs,
                                   float(np.max(f_enc)))
    best_lag = float(taus[np.argmin(scatter)]) if np.isfinite(scatter).any() else lag_s
    per_interval = _half_periods(crossings[early], best_lag, cycles, counts, period_s, counts_per_rev, pole_pairs,
                                 float(np.max(f_enc)))
    if per_interval.size < 8:
        return None
    ratio = float(np.median(per_interval))  # an extra crossing where i_q changes sign is an outlier, not a bias
    scatter = float(1.4826 * np.median(np.abs(per_interval - ratio)))
    if scatter > MAX_RELATIVE_SCATTER * ratio:
        return None
    spread = scatter / math.sqrt(per_interval.size)
    *count, positions = _count_in_moves(crossings[early] + best_lag, cycles, counts, period_s, counts_per_rev,
                                        pole_pairs)
    tolerance = SpeedRatio(ratio, spread, best_lag, 0.0).tolerance
    on_lattice = (_on_lattice(positions, [1.0], pole_pairs),
                  _on_lattice(positions, np.linspace(ratio - tolerance, ratio + tolerance, 41), pole_pairs))
    return SpeedRatio(ratio, spread, best_lag, 0.5 * per_interval.size, *count, on_lattice=on_lattice)


def _on_lattice(positions_rev: list[np.ndarray], ratios: np.ndarray | list[float], pole_pairs: int) -> int:
    """The most crossings, over ``ratios``, that sit on one lattice per move: positions (revolutions at the stated
    constants) within :data:`LATTICE_HALF_WIDTH` of c + k·½/(p·r), c chosen per move (the clocks' lag and drift shift
    a move's crossings alike, and forward and backward moves oppositely)."""
    best = 0
    for r in ratios:
        if r <= 0:
            continue
        held = 0
        for x in positions_rev:
            if x.size:
                phase = np.mod(x * 2.0 * pole_pairs * r, 1.0)
                apart = np.abs(np.mod(phase[:, None] - phase[None, :] + 0.5, 1.0) - 0.5)
                held += int(np.max(np.count_nonzero(apart <= LATTICE_HALF_WIDTH, axis=0)))
        best = max(best, held)
    return best


def _count_in_moves(crossings_drive_s: np.ndarray, cycles: np.ndarray, counts: np.ndarray, period_s: float,
                    counts_per_rev: int, pole_pairs: int) -> tuple[int, float, int, float, list[np.ndarray]]:
    """(crossings, electrical half-turns, moves, seconds, the crossings' positions per move in revolutions) of the
    moves within the crossings' span.

    A move is a run of encoder cycles turning one way faster than 20 % of the peak speed (the threshold of
    :func:`_moving`); ``crossings_drive_s`` are the current's zero crossings on the drive's clock. The lag's
    error (≤ ``REFINE_STEP_S``/2) moves a move's ends by less than a crossing below a few kHz electrical.
    """
    omega = speed_from_counts(counts, counts_per_rev, period_s)  # belongs to the instant of the later sample
    t_s = cycles[1:] * period_s
    inside = (t_s - period_s >= crossings_drive_s[0]) & (t_s <= crossings_drive_s[-1])
    fast = np.abs(omega) >= 0.2 * float(np.max(np.abs(omega)))
    theta_rev = counts / counts_per_rev
    found, half_turns, moves, moving_s, positions = 0, 0.0, 0, 0.0, []
    for sign in (1.0, -1.0):
        run = np.concatenate(([0], (inside & fast & (np.sign(omega) == sign)).astype(np.int8), [0]))
        edges = np.diff(run)
        for first, stop in zip(np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)):
            t0, t1 = t_s[first] - period_s, t_s[stop - 1]
            inside_move = crossings_drive_s[(crossings_drive_s >= t0) & (crossings_drive_s <= t1)]
            found += inside_move.size
            positions.append(np.interp(inside_move, cycles * period_s, theta_rev))
            half_turns += 2.0 * pole_pairs * abs(float(theta_rev[stop] - theta_rev[first]))
            moves += 1
            moving_s += t1 - t0
    return found, half_turns, moves, moving_s, positions


def _half_periods(crossings: np.ndarray, lag_s: float, cycles: np.ndarray, counts: np.ndarray, period_s: float,
                  counts_per_rev: int, pole_pairs: int, f_enc_max_hz: float) -> np.ndarray:
    """½ / (electrical cycles the encoder travelled) for each moving half-period of the current (1 if consistent)."""
    theta_rev = np.interp(crossings + lag_s, cycles * period_s, counts / counts_per_rev, left=np.nan, right=np.nan)
    half_cycles = pole_pairs * np.abs(np.diff(theta_rev))
    return 0.5 / half_cycles[_moving(half_cycles, np.diff(crossings), f_enc_max_hz)]


def _moving(half_cycles: np.ndarray, dt_s: np.ndarray, f_enc_max_hz: float) -> np.ndarray:
    """The half-periods (durations ``dt_s``, s; encoder travel ``half_cycles``, electrical cycles, per lag along
    the first axis if 2-D) that count: moving by both streams, faster than 20 % of the encoder's peak. A current
    that is noise around zero while the joint stands crosses zero often and quickly, but the encoder does not
    travel meanwhile (it read 5·10¹¹× "faster" on an idle robot window)."""
    return (np.isfinite(half_cycles) & (dt_s < 0.5 / (0.2 * f_enc_max_hz))
            & (half_cycles >= 0.2 * f_enc_max_hz * dt_s))


def _half_period_scatter(crossings: np.ndarray, lags_s: np.ndarray, cycles: np.ndarray, counts: np.ndarray,
                         period_s: float, counts_per_rev: int, pole_pairs: int, f_enc_max_hz: float) -> np.ndarray:
    """For each lag, the median absolute deviation of :func:`_half_periods` (inf where fewer than 8 half-periods).

    All lags at once: the lags whose half-periods that count (:func:`_moving`, inside the encoder record) are the
    same ones make one 2-D median each (the same values as lag by lag).
    """
    theta_rev = np.interp(crossings[None, :] + lags_s[:, None], cycles * period_s, counts / counts_per_rev,
                          left=np.nan, right=np.nan)
    half_cycles = pole_pairs * np.abs(np.diff(theta_rev, axis=1))
    moving = _moving(half_cycles, np.diff(crossings)[None, :], f_enc_max_hz)
    scatter = np.full(lags_s.size, np.inf)
    groups: dict[bytes, list[int]] = {}
    for row, packed in enumerate(np.packbits(moving, axis=1)):
        groups.setdefault(packed.tobytes(), []).append(row)
    for rows in groups.values():
        selected = moving[rows[0]]
        if selected.sum() >= 8:
            per_interval = 0.5 / half_cycles[np.ix_(rows, np.flatnonzero(selected))]
            centre = np.median(per_interval, axis=1, keepdims=True)
            scatter[rows] = np.median(np.abs(per_interval - centre), axis=1)
    return scatter


def _smooth(x: np.ndarray) -> np.ndarray:
    """The same 15-sample median the current's crossing frequency gets, so both shapes match."""
    return median_filter(x, size=15, mode="nearest")


def likely_counts_per_rev(estimate: float, tolerance: float) -> int:
    """``estimate`` rounded, or the power of two within ``tolerance`` (relative) of it: most encoders have one."""
    power = 2 ** round(math.log2(max(estimate, 1.0)))
    return power if abs(estimate / power - 1.0) < tolerance else round(estimate)


def ratio_fault(r: SpeedRatio, pole_pairs: int, counts_per_rev: int) -> str | None:
    """The words for a wrong constant the ratio establishes (:attr:`SpeedRatio.named`; None otherwise): what turns
    faster, and the values to check — ``pole_pairs`` when p·r is near a whole number, and ``counts_per_rev`` =
    counts_per_rev/r (snapped to a power of two within 2 %, as most encoders are). The ratio alone cannot tell which
    of the two is wrong, so both are offered (``acq selftest``'s encoder-speed check tells the encoder's apart).
    A mismatch the count does not establish: :func:`ratio_doubt`.
    """
    if not r.named:
        return None
    word = f"{r.ratio:.2f}× faster" if r.ratio > 1 else f"{1 / r.ratio:.2f}× slower"
    candidates = []
    p = pole_pairs * r.ratio
    if round(p) >= 1 and abs(p - round(p)) < 0.1:
        candidates.append(f"[motor] pole_pairs = {round(p)}")
    candidates.append(f"[encoder] counts_per_rev = {likely_counts_per_rev(counts_per_rev / r.ratio, 0.02)}")
    return (f"the current turns {word} than pole_pairs·ω (pole_pairs = {pole_pairs}, counts_per_rev = "
            f"{counts_per_rev}): check {' or '.join(candidates)}")


def ratio_doubt(r: SpeedRatio, pole_pairs: int) -> str | None:
    """The words for a mismatched ratio the count does not establish (None otherwise): the motion the encoder saw
    and why it cannot check the constants, instead of a constant to change."""
    if not r.mismatched or r.named:
        return None
    low, high = r.count_range
    half_turns = r.half_turns / r.moves
    return (f"pole_pairs and counts_per_rev cannot be checked on this record: the current's half-periods read "
            f"{r.ratio:.2f}× pole_pairs·ω, but its {r.crossings} zero crossings in the moves allow "
            f"{max(low, 0.0):.2f}–{high:.2f}× — each of the {r.moves} moves turns the motor only "
            f"{half_turns / (2 * pole_pairs):.2g} rev ({half_turns:.1f} electrical half-turns at pole_pairs = "
            f"{pole_pairs}) in {1e3 * r.moving_s / r.moves:.0f} ms, so the current's zero crossings follow its "
            "torque's sign changes as much as the rotation")
