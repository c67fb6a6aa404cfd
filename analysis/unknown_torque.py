"""The Welch segments in which the torque is not known, left out of the FRF (:func:`analysis.frf.estimate_frf`).

A segment's torque is not known where the estimate's own error (its standard error, N·m, per sample) makes an
outlying share of the segment's torque energy compared with the record's other segments
(:func:`unknown_torque_segments`: Tukey's fence on the log of that dimensionless share; no level set on a simulator).
"""

from __future__ import annotations

import numpy as np

from analysis import welch


def unknown_torque_segments(torque_Nm: np.ndarray, torque_std_Nm: np.ndarray, nperseg: int, step: int,
                            keep: np.ndarray | None = None) -> np.ndarray:
    """The segments in which the torque is not known: its estimate's error makes an outlying share of it.

    Per segment (Hann window, linear detrend, as Welch's), the share R = Σ w²·σ² / Σ w²·(x − trend)² of the torque's
    energy that is the estimate's own error (σ = ``torque_std_Nm``). Where the motor holds or steps its torque at an
    electrical angle at which one phase shows little of it, σ there is many times larger, and the estimate's bias
    (the spline bridging what the phase does not show, any error of the angle, offset or interference divided by a
    small sin) grows with it, beyond what σ itself says — so the segment is not used, as a gap would not be. A
    segment is outlying when log R lies beyond Tukey's fence, the upper quartile plus 1.5 interquartile ranges, of
    the segments considered (``keep``: those a segment selection kept; None: all): a rule on the record's own
    spread, no level set on a simulator. Segments outside ``keep`` are never flagged. With fewer than 4 segments
    considered, or if fewer than two would remain (or a quarter of them carry no information), none is flagged. A
    segment whose error is exactly zero (a noise-free phase current, σ = 0) is never flagged and does not count in the
    spread; without 4 segments of finite R, only the segments that carry no information at all (R = ∞, or an error
    not known) are flagged.
    """
    segs = np.lib.stride_tricks.sliding_window_view(torque_Nm, nperseg)[::step]
    errs = np.lib.stride_tricks.sliding_window_view(torque_std_Nm, nperseg)[::step]
    pool = np.ones(segs.shape[0], dtype=bool) if keep is None else np.asarray(keep, dtype=bool).copy()
    out = np.zeros(segs.shape[0], dtype=bool)
    if pool.sum() < 4:
        return out
    w2 = welch.hann(nperseg) ** 2
    t = np.arange(nperseg) - 0.5 * (nperseg - 1)
    detrended = segs - segs.mean(axis=1, keepdims=True)
    detrended -= np.outer(detrended @ t / (t @ t), t)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):  # no information at all: R = ∞, flagged
        weighted = w2 > 0  # the window's zero ends: an infinite error there does not count
        error = errs[:, weighted] ** 2 @ w2[weighted]
        # an error not known (NaN) is no information (∞), as before the σ = 0 case; only an error of exactly 0 is −∞
        log_r = np.where(~(error <= 0.0), np.nan_to_num(np.log(error / (detrended**2 @ w2)), nan=np.inf, posinf=np.inf),
                         -np.inf)
    # an error of exactly zero (σ = 0: a noise-free phase current) gives R = 0: known exactly, never outlying, and no
    # part of the spread (log 0 has none); with fewer than 4 finite ratios there is no spread to judge by, and only a
    # segment that carries no information at all (R = ∞) is unknown — unless a quarter or more do, as with the fence
    # (q3 = ∞). Counting the finite ones, not all judged: five blind segments among noise-free ones had made q1 = q3 = ∞
    # and flagged none, where four were flagged (the second read)
    judged = pool & (log_r > -np.inf)
    if (judged & np.isfinite(log_r)).sum() >= 4:
        with np.errstate(invalid="ignore"):  # q1 = q3 = ∞: no fence (nan), none flagged
            q1, q3 = np.percentile(log_r[judged], [25.0, 75.0])
            out = judged & (log_r > q3 + 1.5 * (q3 - q1))
    else:
        blind = judged & (log_r == np.inf)
        out = blind if 4 * blind.sum() < pool.sum() else np.zeros_like(pool)
    return out if (pool & ~out).sum() >= 2 else np.zeros_like(out)
