"""Stage 4 of the clock alignment: offset, drift and θ_0 from the phase of i_a against the encoder's electrical angle
(design §4).

In short windows the phase of i_a against the encoder's electrical angle is θ_0 + p·ω·δ(t) where δ(t) is the
remaining clock error; a coherent search then weighted least squares on 2·phase (blind to the sign of i_q) fit
offset, drift and θ_0 to µs.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import stats
from scipy.interpolate import CubicSpline

from analysis.phase_offset import window_phasors
from analysis.zero_crossings import CHUNK_SAMPLES

_SEARCH_STEP_S = 2.5e-5  # grid of the angle stage's coherent offset search, s
# The angle stage demodulates block means of the current (see _block_means): at least this many blocks per
# electrical turn at the fastest speed, so the blocks lose ≤ 0.6 % of the sinusoid's amplitude and none of its
# phase; at most _MAX_BLOCK samples per block (each block's angle taken as linear in time).
_BLOCK_SAMPLES_PER_TURN = 16
_MAX_BLOCK = 8


@dataclass(frozen=True)
class AngleFit:
    """Result of the angle stage: the relation, θ_0 (mod π, rad) and the fit's quality (see
    :class:`analysis.clock_model.ClockFit`)."""

    offset_s: float
    drift_ppm: float
    theta0_rad: float
    residual_s: float
    offset_std_s: float
    drift_std_ppm: float
    n_windows: int
    n_moves: int = 0  # stretches of motion the windows fall in (:func:`_move_jackknife`); 0 when not counted
    drift_from_data: bool = True  # False: the drift's prior decided it more than the data (analysis.clocks)


def angle_alignment(current_a: np.ndarray, rate_hz: float, first_index: int, angle: CubicSpline, pole_pairs: int,
                    offset_s: float, drift_ppm: float, search_s: float = 4e-3, window_s: float = 0.02,
                    iterations: int = 2, fixed_drift: bool = False) -> AngleFit | None:
    """Stage 4: offset, drift and θ_0 from the phase of i_a against the encoder's electrical angle.

    Parameters
    ----------
    current_a : ndarray
        One phase current, A; element 0 is DAQ sample ``first_index``.
    rate_hz : float
        DAQ rate, Hz.
    first_index : int
        DAQ sample index of ``current_a[0]``.
    angle : CubicSpline
        Mechanical angle θ_m(t_drive), rad.
    pole_pairs : int
        Pole pairs p.
    offset_s, drift_ppm : float
        Starting relation, within ``search_s`` of the truth.
    search_s : float
        Half-range of the coherent search for the offset, s.
    window_s : float
        Demodulation window, s.
    iterations : int
        Re-demodulations after the search.
    fixed_drift : bool
        Keep ``drift_ppm`` (known from elsewhere, :func:`analysis.clocks.fit_clock`) and fit offset and θ_0 only; the
        result's ``drift_std_ppm`` is then NaN (the caller knows the drift's uncertainty).

    Returns
    -------
    AngleFit or None
        None when fewer than 10 windows turn half an electrical revolution.

    The drift's standard error is the larger of the least-squares one and a jackknife over the record's moves
    (:func:`_move_jackknife`): within one move the windows share the estimator's errors (the same slowly changing
    torque, the same few electrical turns per window), so a least-squares error that takes them as independent reads
    a drift resting on two or three moves as known to ±26 ppm when it is 195 ppm off.
    """
    t_ref = (first_index + 0.5 * current_a.size) / rate_hz
    t_span = angle.x[[0, -1]]
    speed = angle.derivative()
    blocks = _block_means(current_a, rate_hz, first_index, pole_pairs * float(np.max(np.abs(angle.c[2]))))
    wl = max(8, int(round(window_s * rate_hz / blocks.size)))
    theta0 = 0.0
    for it in range(iterations + 1):
        z, t_c, w_m = _phasors(blocks, angle, speed, pole_pairs, offset_s, drift_ppm, wl, t_span)
        if z.size < 10:
            return None
        k = 2.0 * pole_pairs * w_m
        if it == 0:
            grid = np.arange(-search_s, search_s + 1e-9, _SEARCH_STEP_S)
            power = np.abs(_coherent_sums(z, k, grid[0], _SEARCH_STEP_S, grid.size))
            shift = grid[int(np.argmax(power))]
            offset_s += shift
            z = z * np.exp(-1j * k * shift)
            theta0 = 0.5 * np.angle(np.sum(z))
        A = np.column_stack((2.0 * np.ones_like(k), k, k * (t_c - t_ref)))
        if fixed_drift:
            A[:, 2] = 0.0  # no drift column's worth: lstsq's minimum-norm solution leaves its coefficient 0
        w = np.abs(z)
        r = np.angle(z * np.exp(-2j * theta0))
        keep = np.ones(z.size, bool)
        for _ in range(3):
            sol = _weighted_solution(A, r, w, keep)
            res = r - A @ sol
            mad = 1.4826 * np.median(np.abs(res[keep]))
            keep = np.abs(res) <= max(4.0 * mad, 1e-3)
        theta0 += sol[0]
        d_drift = sol[2]
        offset_s += sol[1] - d_drift * t_ref
        drift_ppm += d_drift * 1e6
    # uncertainty of the last step (the corrections are then tiny), at t_ref then moved to t = 0
    fitted = A[:, :2] if fixed_drift else A
    sw = np.sqrt(w[keep])
    Aw = fitted[keep] * sw[:, None]
    s2 = np.sum((res[keep] * sw) ** 2) / max(1, keep.sum() - fitted.shape[1])
    cov = np.zeros((3, 3))
    cov[:fitted.shape[1], :fitted.shape[1]] = s2 * np.linalg.inv(Aw.T @ Aw)
    n_moves = 0
    if not fixed_drift:
        jack, n_moves = _move_jackknife(A, r, w, keep, t_c)
        if not jack[2, 2] <= cov[2, 2]:  # NaN (too few moves to tell): the drift rests on them, unknown
            cov = jack
    var_off0 = cov[1, 1] - 2 * t_ref * cov[1, 2] + t_ref**2 * cov[2, 2]
    resid = np.sqrt(np.sum(w[keep] * res[keep] ** 2) / np.sum(w[keep] * k[keep] ** 2))
    theta0 = float(np.angle(np.exp(2j * theta0)) / 2.0)
    return AngleFit(offset_s, drift_ppm, theta0, float(resid), float(np.sqrt(var_off0)),
                    float("nan") if fixed_drift else float(np.sqrt(cov[2, 2]) * 1e6), int(keep.sum()), n_moves)


def _weighted_solution(A: np.ndarray, r: np.ndarray, w: np.ndarray, keep: np.ndarray) -> np.ndarray:
    """Weighted least squares of ``r`` on the columns of ``A`` over the rows ``keep`` (weights ``w``)."""
    sw = np.sqrt(w[keep])
    return np.linalg.lstsq(A[keep] * sw[:, None], r[keep] * sw, rcond=None)[0]


def _move_jackknife(A: np.ndarray, r: np.ndarray, w: np.ndarray, keep: np.ndarray, t_c: np.ndarray
                    ) -> tuple[np.ndarray, int]:
    """Delete-a-move jackknife covariance of the angle stage's solution (θ_0, offset, drift), and the moves found.

    A move is a run of consecutive windows (window centres one window apart; a gap is a stretch the motor turned
    less than half an electrical revolution per window). A record of fewer than three moves is split into three
    pieces of equal windows (a block jackknife of one long motion), so that leaving one out leaves two to fit a
    drift on. The covariance is (G − 1)/G · Σ (x_g − x̄)(x_g − x̄)ᵀ over the G moves; NaN where a move left out leaves
    the rest unable to fit the drift (all its windows in one move, or fewer than three of them). It is scaled by
    (t/z)², Student's t of G − 1 degrees of freedom over the normal's z at 97.5 %, so that its square root, read as a
    normal standard error as everything downstream does, spans the 95 % interval its G moves allow (×1.09 at 15 moves):
    the drift's interval of sim_robot 10 s windows (seeds 0–9, 60…540 s into the shift) held the truth in 36 of 42
    without it (RMS error/σ 1.37), 37 with it (1.27): 36 of the 39 whose error the jackknife gives (1.09), 1 of the 3
    where the least squares' is larger (2.66).
    """
    idx = np.flatnonzero(keep)
    if idx.size < 4:
        return np.full((3, 3), np.nan), 1
    spacing = float(np.median(np.diff(t_c[idx])))
    starts = np.flatnonzero(np.diff(t_c[idx]) > 1.5 * spacing) + 1
    moves = np.split(idx, starts)
    n_moves = len(moves)
    if len(moves) < 3:
        moves = np.array_split(idx, 3)
    # each delete-a-move solution from the normal equations less that move's share: one pass over the windows for
    # all of them (a lstsq per move over every other window cost 0.13 s on a 60 s triangle record of ~300 moves);
    # the columns scaled to unit r.m.s. first, so that squaring their condition in the normal equations costs ~1e-10
    # relative of a solution, far below the moves' spread
    scale = np.sqrt(np.mean(A[idx] ** 2, axis=0))
    scale[scale == 0.0] = 1.0
    Aw = A / scale
    group = np.empty(A.shape[0], dtype=np.intp)
    for g, rows in enumerate(moves):
        group[rows] = g
    normal = np.zeros((len(moves), 3, 3))
    right = np.zeros((len(moves), 3))
    np.add.at(normal, group[idx], w[idx, None, None] * Aw[idx, :, None] * Aw[idx, None, :])
    np.add.at(right, group[idx], (w[idx] * r[idx])[:, None] * Aw[idx])
    rest_normal, rest_right = normal.sum(axis=0) - normal, right.sum(axis=0) - right
    # the drift needs the rest to span time: two moves, or one long enough to be split above. The moves are runs of
    # consecutive kept windows in time order, so the rest spans from the first kept window outside the move to the
    # last (the move's neighbours when it is the first or the last) — all moves at once, as one stack of 3 × 3 systems
    size, g = np.array([rows.size for rows in moves]), np.arange(len(moves))
    first = np.where(g == 0, size[0], 0)  # position in idx of the rest's first kept window …
    last = np.where(g == len(moves) - 1, idx.size - 1 - size[-1], idx.size - 1)  # … and of its last
    rest_span = t_c[idx[np.clip(last, 0, idx.size - 1)]] - t_c[idx[np.clip(first, 0, idx.size - 1)]]
    if np.any(idx.size - size < 3) or np.any(rest_span <= 1.5 * spacing):
        return np.full((3, 3), np.nan), n_moves
    if np.any(np.linalg.matrix_rank(rest_normal, hermitian=True) < 3):
        return np.full((3, 3), np.nan), n_moves
    x = np.linalg.solve(rest_normal, rest_right[..., None])[..., 0] / scale
    d = x - x.mean(axis=0)
    t_over_z = stats.t.ppf(0.975, len(moves) - 1) / stats.norm.ppf(0.975)
    return t_over_z**2 * (len(moves) - 1) / len(moves) * (d.T @ d), n_moves


def _coherent_sums(z: np.ndarray, k: np.ndarray, tau0_s: float, step_s: float, n: int) -> np.ndarray:
    """Σ_w z_w·e^{−j·k_w·τ_i} at the offsets τ_i = ``tau0_s`` + i·``step_s``, i = 0 … n − 1 (k in rad/s).

    Each window's phase advances by k_w·step per offset, so the terms are updated by one complex product per
    window and offset instead of a complex exponential of the whole (offsets × windows) matrix (25× faster, and
    memory of one row; after a few hundred steps the sums agree with the direct ones to 1e-14 relative).
    """
    v = z * np.exp(-1j * k * tau0_s)
    advance = np.exp(-1j * k * step_s)
    out = np.empty(n, complex)
    for i in range(n):
        out[i] = v.sum()
        v *= advance
    return out


@dataclass(frozen=True)
class _BlockMeans:
    """The current averaged over blocks of ``size`` consecutive DAQ samples, A, the first block's mid-time on the
    DAQ clock, s, and the blocks' spacing, s."""

    current_a: np.ndarray
    t0_s: float
    dt_s: float
    size: int


def _block_means(current_a: np.ndarray, rate_hz: float, first_index: int, omega_e_max_rad_s: float) -> _BlockMeans:
    """Average ``current_a`` over blocks of D samples, D as large as keeps ``_BLOCK_SAMPLES_PER_TURN`` blocks per
    electrical turn at the fastest electrical speed ``omega_e_max_rad_s`` (at most ``_MAX_BLOCK``).

    The mean of a·sin θ + b·cos θ + c over a block in which θ advances at a constant rate is the same sinusoid read
    at the block's mid-time, its amplitude times sin(Dδ/2)/(D·sin(δ/2)) (δ: angle per sample; ≥ 0.994 at 16
    blocks per turn) and its phase unchanged; white noise keeps its information (variance / D on D times fewer
    values). So the angle stage, which reads only the phase, demodulates the blocks against the angle at their
    mid-times: D times fewer angle evaluations, sines and products, three passes for the cost of one average.
    """
    per_turn = 2.0 * np.pi * rate_hz / max(omega_e_max_rad_s, 1e-9)
    size = int(np.clip(per_turn // _BLOCK_SAMPLES_PER_TURN, 1, _MAX_BLOCK))
    n = current_a.size // size
    # a matrix-vector product with weights 1/D: BLAS reads the rows once, 4–20× faster than NumPy's mean over many
    # short rows (the same means to rounding)
    means = (current_a[:n * size].reshape(n, size) @ np.full(size, 1.0 / size) if size > 1
             else np.asarray(current_a, np.float64))
    return _BlockMeans(means, (first_index + 0.5 * (size - 1)) / rate_hz, size / rate_hz, size)


def _phasors(blocks: _BlockMeans, angle: CubicSpline, speed: CubicSpline, pole_pairs: int, offset_s: float,
             drift_ppm: float, wl: int, t_span: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Squared window phasors (i_q²·e^{2j(θ_0 + pωδ)}) over windows of ``wl`` blocks, window-centre DAQ times, s, and
    speeds, rad/s."""
    zs, ts, ws = [], [], []
    step = (CHUNK_SAMPLES // wl) * wl
    scale = 1.0 + drift_ppm * 1e-6
    current_a, dt = blocks.current_a, blocks.dt_s
    for a in range(0, current_a.size - wl + 1, step):
        seg = current_a[a:a + step]
        t_daq = blocks.t0_s + (a + np.arange(seg.size)) * dt
        t_drv = offset_s + t_daq * scale
        wp = window_phasors(seg, pole_pairs * angle(t_drv), wl)
        t_c = blocks.t0_s + (a + wp.centre_index) * dt
        t_c_drv = offset_s + t_c * scale
        inside = (t_c_drv - 0.5 * wl * dt > t_span[0]) & (t_c_drv + 0.5 * wl * dt < t_span[1])
        ok = wp.valid & inside
        zs.append(wp.phasor_a[ok] ** 2)
        ts.append(t_c[ok])
        ws.append(speed(t_c_drv[ok]))
    return np.concatenate(zs), np.concatenate(ts), np.concatenate(ws)
