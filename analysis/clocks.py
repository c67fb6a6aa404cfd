"""Offline alignment of the DAQ clock to the drive clock from the data itself (design §4): the stages in order, and
which of their results to trust.

The relation sought, t_drive = offset_s + t_daq·(1 + drift_ppm·1e-6), is :class:`analysis.clock_model.ClockFit`.
Four stages, each narrowing the search of the next:

1. host (:mod:`analysis.clock_host`): when both streams carry arrival stamps on one host clock (a recording, not
   two files from separate tools), the stamps give the relation to a few ms — if the transfer latencies are steady.
2. wide (:mod:`analysis.clock_search`): the current's electrical frequency against the encoder's over
   every plausible offset (±2 s around the host relation or, without one, around "started together"),
   one FFT correlation on a 10 ms grid. It always runs: host stamps farther from the data's alignment
   than the frequency stage reaches (a USB DAQ delivering blocks 50–150 ms late) are overruled. Offsets
   the data supports equally (whole periods of the motion apart) are resolved by the host stamps, or
   reported as ambiguous.
3. frequency (:mod:`analysis.clock_frequency`): the lag between the electrical frequency carried by the current and
   the encoder's (:mod:`analysis.zero_crossings`), in windows along the record, gives offset and drift to a fraction
   of a ms.
4. angle (:mod:`analysis.clock_angle`): the phase of i_a against the encoder's electrical angle in short windows
   gives offset, drift and θ_0 to µs.

No pair of crystal clocks drifts by more than :data:`analysis.clock_model.MAX_DRIFT_PPM`: the frequency stage fits
only the offset where its slope would need more, and an angle fit that needs more is rejected (the next candidate
of the wide search, or the host relation, is taken; with none left the alignment fails, :attr:`ClockFit.failure`).

The angle stage's drift rests on how the timing changes from one stretch of motion to the next; its error is a
jackknife over them, and it is combined with what was known before — the host stamps' drift, or the crystals' bound
— by inverse variance (:func:`_with_prior`): on a short record of a few moves the host stamps decide. A record whose
alignment rests on the data alone and whose angle stage fits worse than any verdict accepts (or found too little
motion) cannot be aligned: the alignment fails and says so (:func:`_undetermined_text`).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from scipy.interpolate import CubicSpline

from analysis.clock_angle import AngleFit, angle_alignment
from analysis.clock_frequency import frequency_alignment
from analysis.clock_host import HostRelation
from analysis.clock_model import MAX_DRIFT_PPM, ClockFit, ClockMethod, plausible_drift
from analysis.clock_search import starting_relation, wide_search
from analysis.fit import Z95
from analysis.verdict_limits import Thresholds
from analysis.zero_crossings import angle_crossings_s, crossing_frequency_hz, current_crossings_s

_GRID_HZ = 1000.0  # grid of the frequency stage
_NARROW_S = 0.03  # half-range of the frequency stage's first pass around its starting relation, s
_PIECE_S = 2.0  # current the angle stage uses to tell the wide search's candidates apart, s
#: What is known of the drift before the data when no host stamps tell: two crystal clocks differ by at most
#: MAX_DRIFT_PPM (clock_model), read as the 95 % bound of a normal prior about 0 (σ ≈ 102 ppm).
CRYSTAL_DRIFT_STD_PPM = MAX_DRIFT_PPM / Z95


def fit_clock(current_a: np.ndarray, rate_hz: float, first_index: int, angle: CubicSpline, pole_pairs: int,
              host: HostRelation | None, max_lag_s: float = 2.0) -> ClockFit:
    """Align the DAQ clock to the drive clock through the stages of the module docstring.

    Parameters
    ----------
    current_a : ndarray
        One phase current, A; element 0 is DAQ sample ``first_index`` (a gap-free run).
    rate_hz : float
        DAQ rate, Hz.
    first_index : int
        DAQ sample index of ``current_a[0]``.
    angle : CubicSpline
        Mechanical angle θ_m(t_drive), rad, over a gap-free encoder run (:func:`analysis.encoder.angle_spline`).
    pole_pairs : int
        Pole pairs p.
    host : HostRelation or None
        Stage 1 result (:func:`analysis.clock_host.host_relation`) when the stamps are arrival times on one host
        clock; None otherwise. The wide search runs either way, ±``max_lag_s`` around the host relation or, without
        it, around "both streams started together". Its drift (± its standard error) is what is known of the drift
        before the angle stage (without it: 0 ± :data:`CRYSTAL_DRIFT_STD_PPM`): :func:`_with_prior`.
    max_lag_s : float
        Half-width of the wide search, s.
    """
    t_enc = angle.x[[0, -1]]
    t0 = first_index / rate_hz
    grid = t0 + np.arange(int(current_a.size / rate_hz * _GRID_HZ)) / _GRID_HZ
    f_cur = crossing_frequency_hz(current_crossings_s(current_a, rate_hz, first_index), grid)
    enc_grid = np.arange(t_enc[0], t_enc[1], 1.0 / _GRID_HZ)
    f_enc_grid = crossing_frequency_hz(angle_crossings_s(angle, pole_pairs, t_enc[0], t_enc[1]), enc_grid)

    def f_enc(t: np.ndarray) -> np.ndarray:
        return np.interp(t, enc_grid, f_enc_grid, left=0.0, right=0.0)

    together_s = float(t_enc[0]) - t0
    wide = wide_search(f_cur, f_enc_grid, 1.0 / _GRID_HZ, float(enc_grid[0]) - t0,
                       host[0] if host is not None else together_s, max_lag_s)
    if wide is not None:
        wide = wide.screened(lambda o: _angle_residual_s(o, current_a, rate_hz, first_index, angle, pole_pairs,
                                                         grid, f_cur, f_enc))
    offset_s, drift_ppm, start, ambiguous_by, notes = starting_relation(host, wide, together_s, _NARROW_S)

    rejected: list[AngleFit] = []

    def refine(offset_s: float, drift_ppm: float, method: ClockMethod
               ) -> tuple[float, float, tuple[float, float], ClockMethod, AngleFit | None]:
        """The frequency and angle stages from a starting relation (an angle fit of implausible drift rejected)."""
        freq = (np.nan, np.nan)
        for lag in (_NARROW_S, 0.004):
            o, d, n = frequency_alignment(f_cur, grid, f_enc, offset_s, drift_ppm, lag)
            if n:
                offset_s, drift_ppm, freq, method = o, d, (o, d), "frequency"
        fit = angle_alignment(current_a, rate_hz, first_index, angle, pole_pairs, offset_s, drift_ppm)
        if fit is not None and not plausible_drift(fit.drift_ppm, fit.drift_std_ppm):
            rejected.append(fit)
            fit = None
        if fit is not None:
            fit = _with_prior(fit, host, current_a, rate_hz, first_index, angle, pole_pairs)
        return offset_s, drift_ppm, freq, method, fit

    offset_s, drift_ppm, freq, method, fit = refine(offset_s, drift_ppm, start)
    if host is not None and start == "wide":
        # The data overrule the shared host stamps only where the alignment they lead to fits better: on motion
        # whose electrical frequency correlates well at a wrong lag too (a robot's repeated point-to-point
        # moves with pauses), the wide search's best lag can be wrong while the stamps are right.
        from_host = refine(host[0], host[1], "host")
        if _angle_residual(from_host[4]) <= _angle_residual(fit):
            offset_s, drift_ppm, freq, method, fit = from_host
            start = "host"
        else:
            final_s = fit.offset_s if fit is not None else offset_s
            notes.append(f"clock: the host stamps are {1e3 * (host[0] - final_s):+.0f} ms off the data's alignment "
                         "(blocks delivered late?); the wide search's offset is used")
    failure = ""
    if rejected and fit is None:
        failure = (f"clock: no alignment found — {_rejection_text(rejected)}: the motion repeats too evenly to align "
                   "the streams on (or they do not belong together), so K, J and C would be those of a wrong alignment")
    elif rejected:
        notes.append(f"clock: rejected a fit of the electrical angle: {_rejection_text(rejected)}")
    if not failure and start != "host" and (fit is None and method == "wide" or _angle_residual(fit) >
                                            Thresholds().clock_residual_amplitude_s):
        failure = _undetermined_text(fit, host, offset_s)
    if fit is not None and not fit.drift_from_data:
        notes.append(_prior_text(fit, host, float(current_a.size / rate_hz)))
    common = dict(host_offset_s=host[0] if host else np.nan, host_drift_ppm=host[1] if host else np.nan,
                  frequency_offset_s=freq[0], frequency_drift_ppm=freq[1],
                  wide_offset_s=wide.offset_s if wide else np.nan, ambiguous_by_s=ambiguous_by, notes=tuple(notes))
    if fit is None:
        return ClockFit(offset_s, drift_ppm, method=method, failure=failure, **common)
    return ClockFit(fit.offset_s, fit.drift_ppm, fit.residual_s, fit.offset_std_s, fit.drift_std_ppm,
                    fit.theta0_rad, n_windows=fit.n_windows, method="angle", failure=failure, **common)

def _with_prior(fit: AngleFit, host: HostRelation | None, current_a: np.ndarray, rate_hz: float, first_index: int,
                angle: CubicSpline, pole_pairs: int) -> AngleFit:
    """The angle fit with its drift combined with what was known before (the host stamps' drift ± its standard
    error, else 0 ± :data:`CRYSTAL_DRIFT_STD_PPM`), inverse-variance weighted, and offset and θ_0 fitted again at
    that drift.

    The angle stage's drift rests on how its windows' timing changes from move to move; on a short record of a few
    moves its jackknife error (:func:`analysis.clock_angle.angle_alignment`) is large, and the prior decides: a
    robot's 6 s window of three moves read −155 ± 1030 ppm (truth +40) where its host stamps said +37 ± 5.
    On a record of many moves the data decide (±1…10 ppm against a prior of ±5 or ±102) and nothing changes.
    The result's ``drift_from_data`` is False when the prior decided more than the data (the data's weight less than
    half the combined).
    """
    prior_ppm, prior_std = ((host.drift_ppm, host.drift_std_ppm) if host is not None and np.isfinite(host.drift_std_ppm)
                            else (0.0, CRYSTAL_DRIFT_STD_PPM))
    data_w = 1.0 / fit.drift_std_ppm**2 if np.isfinite(fit.drift_std_ppm) and fit.drift_std_ppm > 0 else 0.0
    if prior_std <= 0.0:  # stamps without delay: the host clock relates the streams exactly
        drift_ppm, drift_std = prior_ppm, 0.0
    else:
        prior_w = 1.0 / prior_std**2
        drift_ppm = (data_w * fit.drift_ppm + prior_w * prior_ppm) / (data_w + prior_w)
        drift_std = float(1.0 / np.sqrt(data_w + prior_w))
    t_mid = (first_index + 0.5 * current_a.size) / rate_hz
    again = angle_alignment(current_a, rate_hz, first_index, angle, pole_pairs,
                            fit.offset_s + (fit.drift_ppm - drift_ppm) * 1e-6 * t_mid, drift_ppm, fixed_drift=True)
    if again is None:
        return fit
    offset_std = float(np.hypot(again.offset_std_s, t_mid * drift_std * 1e-6))
    from_data = data_w * drift_std**2 >= 0.5  # the data's weight is at least half the combined
    return AngleFit(again.offset_s, drift_ppm, again.theta0_rad, again.residual_s, offset_std, drift_std,
                    again.n_windows, fit.n_moves, from_data)


def _prior_text(fit: AngleFit, host: HostRelation | None, duration_s: float) -> str:
    """The note for a drift the record's motion could not decide: what decided it, and the timing it leaves open."""
    moves = fit.n_moves
    told = (f"the record's {moves} stretch{'es' if moves != 1 else ''} of motion fast enough for the electrical angle "
            "tell the drift less well than ")
    if host is not None and np.isfinite(host.drift_std_ppm):
        return (f"clock: {told}the host stamps: their drift is used ({fit.drift_ppm:+.1f} ± "
                f"{Z95 * fit.drift_std_ppm:.1f} ppm, 95 %)")
    ends_us = 1e6 * Z95 * fit.drift_std_ppm * 1e-6 * 0.5 * duration_s
    return (f"clock: {told}two crystal clocks' tolerance (±{MAX_DRIFT_PPM:.0f} ppm): drift {fit.drift_ppm:+.0f} ± "
            f"{Z95 * fit.drift_std_ppm:.0f} ppm (95 %), so the streams' timing is known only to ±{ends_us:.0f} µs at "
            "the record's ends — record longer, with more moves, or both streams on one host clock")


def _undetermined_text(fit: AngleFit | None, host: HostRelation | None, offset_s: float) -> str:
    """Why the record cannot place the streams when neither host stamps nor the electrical angle do (the alignment
    rests on the data alone, and the angle stage found too little motion or fits no better than the loosest residual
    a verdict accepts, :attr:`analysis.verdict_limits.Thresholds.clock_residual_amplitude_s`): the failure's text."""
    limit_us = 1e6 * Thresholds().clock_residual_amplitude_s
    if fit is None:
        why = (f"its motion is too slow or too short for the electrical angle (only the electrical frequencies matched, "
               f"at {offset_s:+.3f} s)")
    else:
        stretches = fit.n_moves
        why = (f"at the best offset its {stretches} stretch{'es' if stretches != 1 else ''} of motion fast enough for the "
               f"electrical angle allow ({fit.offset_s:+.3f} s) the current's phase "
               f"follows the encoder's angle only to {1e6 * fit.residual_s:.0f} µs RMS, above the {limit_us:.0f} µs "
               "any fit accepts")
    unplaced = ("no shared host clock places the streams" if host is None else
                "the host stamps, which the data overruled, do not either")
    return (f"clock: this record cannot align the two streams — {why}, and {unplaced}: K, J and C would be those of a "
            "guessed alignment, and whether the moves excite the joint cannot be judged — record longer (more moves), "
            "or both streams on one host clock")


def _rejection_text(rejected: list[AngleFit]) -> str:
    """What the rejected angle fits needed (the smallest drift of them), for a note or the failure."""
    least = min(rejected, key=lambda f: abs(f.drift_ppm))
    drift, margin = (f"{x:,.0f}".replace(",", " ") for x in (least.drift_ppm, Z95 * least.drift_std_ppm))
    more = f" (and from {len(rejected) - 1} other start(s) more)" if len(rejected) > 1 else ""
    return (f"the phase of the current against the encoder's angle fits at offset {least.offset_s:+.3f} s only with a "
            f"drift of {'+' if least.drift_ppm >= 0 else ''}{drift} ± {margin} ppm{more}, beyond the "
            f"±{MAX_DRIFT_PPM:.0f} ppm two crystal clocks can differ")


def _angle_residual(fit: AngleFit | None) -> float:
    """Timing residual, s, of an angle-stage fit (inf without one)."""
    return fit.residual_s if fit is not None else np.inf


def _angle_residual_s(offset_s: float, current_a: np.ndarray, rate_hz: float, first_index: int, angle: CubicSpline,
                      pole_pairs: int, grid: np.ndarray, f_cur: np.ndarray,
                      f_enc: Callable[[np.ndarray], np.ndarray]) -> float:
    """Timing residual, s, of the frequency and angle stages started at ``offset_s`` on ``_PIECE_S`` of current in
    the middle of the overlap there (inf when the angle stage finds too little motion or needs an implausible
    drift, :func:`analysis.clock_model.plausible_drift`)."""
    t_enc = angle.x[[0, -1]]
    lo, hi = max(grid[0], t_enc[0] - offset_s), min(grid[-1], t_enc[1] - offset_s)
    a_s, b_s = max(lo, 0.5 * (lo + hi - _PIECE_S)), min(hi, 0.5 * (lo + hi + _PIECE_S))
    sel = (grid >= a_s) & (grid < b_s)
    drift_ppm = 0.0
    for lag in (_NARROW_S, 0.004):
        o, d, n = frequency_alignment(f_cur[sel], grid[sel], f_enc, offset_s, drift_ppm, lag, window_s=b_s - a_s)
        if n:
            offset_s, drift_ppm = o, d
    a, b = (int(np.clip(round(x * rate_hz) - first_index, 0, current_a.size)) for x in (a_s, b_s))
    fit = angle_alignment(current_a[a:b], rate_hz, first_index + a, angle, pole_pairs, offset_s, drift_ppm,
                          iterations=0)
    return fit.residual_s if fit is not None and plausible_drift(fit.drift_ppm, fit.drift_std_ppm) else np.inf
