"""The banded least squares behind :func:`analysis.torque.torque_encoder`: y ≈ g·s(t) + Σ β_k·x_k.

s is a uniform cubic B-spline in time (a knot every m samples), fitted by penalised least squares with
every sample weighted by g² (the phase's sin²); the β_k are global coefficients of extra columns x_k
(the slow sensor offset, θ_0 and clock corrections, interference lines), eliminated by their Schur
complement, so the cost stays linear in the record's length. :class:`SlowOffset` is the offset's own
coarse B-spline basis, evaluated where it is needed instead of held as a (functions × samples) array
that would be mostly zeros.

scipy offers banded Cholesky (:func:`scipy.linalg.cholesky_banded`) but no solver for a banded system
bordered by dense columns, nor a sparse representation that keeps these products cache-sized, hence
this module.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np
from scipy.linalg import cholesky_banded
from scipy.linalg.lapack import dtbtrs

# Knot spans per block of the projections in :func:`spline_fit`: the block's rows (right-hand sides and the extra
# columns active there, ~10, 2048·m samples each) stay in a core's L2 cache (1 MB here) through the products, instead
# of streaming every full-length row through memory several times; fewer, larger blocks cost less Python per sample.
_BLOCK_SPANS = 2048


def bspline_weights(m: int) -> np.ndarray:
    """Uniform cubic B-spline weights of the 4 active coefficients at the m samples of one knot span."""
    r = np.arange(m) / m
    return np.stack([(1 - r) ** 3, 3 * r**3 - 6 * r**2 + 4, -3 * r**3 + 3 * r**2 + 3 * r + 1, r**3], axis=1) / 6.0


@dataclass(frozen=True)
class SlowOffset:
    """A cubic B-spline basis in time over ``n`` samples, a knot every ``span`` samples (its functions sum to 1 at
    every sample): the sensor offset's columns of :func:`spline_fit`, evaluated block by block.

    Function j lives on the knot intervals j − 3 … j; interval q holds the samples whose index i has
    min(⌊i/span⌋, intervals − 1) = q (the last interval takes the remainder).
    """

    n: int
    span: float

    @property
    def intervals(self) -> int:
        """Number of knot intervals."""
        return int(np.floor((self.n - 1) / self.span)) + 1

    @property
    def count(self) -> int:
        """Number of basis functions (columns)."""
        return self.intervals + 3

    def bounds(self) -> np.ndarray:
        """First sample of each knot interval, then ``n``: shape (intervals + 1,) (read-only)."""
        return self._bounds

    @cached_property
    def _bounds(self) -> np.ndarray:
        """:meth:`bounds`, computed once (:func:`spline_fit` asks for it in every block)."""
        q = np.arange(self.intervals + 1)
        first = np.ceil(q * self.span).astype(np.int64)
        # ⌊i/span⌋ ≥ q decides, as it does sample by sample: correct ceil(q·span)'s rounding by one either way
        first -= (first > 0) & (np.floor((first - 1) / self.span) >= q)
        first += np.floor(first / self.span) < q
        first[0], first[-1] = 0, self.n
        out = np.minimum(first, self.n)
        out.flags.writeable = False
        return out

    def support(self) -> np.ndarray:
        """Samples [start, stop) outside which each function is zero, shape (count, 2)."""
        bounds, j = self.bounds(), np.arange(self.count)
        return np.stack((bounds[np.clip(j - 3, 0, self.intervals)], bounds[np.clip(j + 1, 0, self.intervals)]),
                        axis=1)

    def block(self, s0: int, s1: int, below: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """The functions non-zero on samples ``s0`` … ``s1`` − 1: their indices and values there, shape (k, s1 − s0);
        with ``below`` (rows on the same samples) the values and then those rows in one array, shape
        (k + len(below), s1 − s0), written in place instead of joined by a copy."""
        bounds = self.bounds()
        q0 = int(np.searchsorted(bounds, s0, side="right")) - 1
        q1 = int(np.searchsorted(bounds, s1 - 1, side="right")) - 1
        k = q1 - q0 + 4
        values = np.empty((k + (0 if below is None else below.shape[0]), s1 - s0))
        if q1 > q0:  # inside one knot interval its 4 pieces below fill the k = 4 rows whole: no zeros to write first
            values[:k] = 0.0
        for q in range(q0, q1 + 1):  # knot interval q carries functions q … q + 3
            a, b = max(s0, int(bounds[q])), min(s1, int(bounds[q + 1]))
            values[q - q0:q - q0 + 4, a - s0:b - s0] = self._pieces(q, a, b)
        if below is not None:
            values[k:] = below
        return np.arange(q0, q1 + 4), values

    def curve(self, beta: np.ndarray) -> np.ndarray:
        """Σ_j β_j·B_j at every sample, shape (n,)."""
        bounds = self.bounds()
        out = np.empty(self.n)
        for q in range(self.intervals):
            a, b = int(bounds[q]), int(bounds[q + 1])
            out[a:b] = beta[q:q + 4] @ self._pieces(q, a, b)
        return out

    def _pieces(self, q: int, a: int, b: int) -> np.ndarray:
        """The 4 cubic pieces of knot interval q at its samples a … b − 1, shape (4, b − a)."""
        if self.span.is_integer():  # every interval starts at q·span: one table serves them all
            first = q * int(self.span)
            return self._table[:, a - first:b - first]
        return _cubic_pieces(np.arange(a, b) / self.span - q)

    @cached_property
    def _table(self) -> np.ndarray:
        """The 4 cubic pieces at the samples of one knot interval of an integer ``span`` (the last interval holds
        the rest, at most as many), shape (4, span)."""
        return _cubic_pieces(np.arange(int(self.span)) / self.span)


def _cubic_pieces(r: np.ndarray) -> np.ndarray:
    """The 4 cubic B-spline pieces at the positions r within a knot interval (in units of it), shape (4, len(r))."""
    r2, r3 = r**2, r**3
    return np.stack(((1 - r) ** 3 / 6.0, (3 * r3 - 6 * r2 + 4) / 6.0, (-3 * r3 + 3 * r2 + 3 * r + 1) / 6.0, r3 / 6.0))


def spline_factor(g: np.ndarray, m: int, smoothing: float) -> np.ndarray:
    """Banded Cholesky factor R = diag(d)·U (A = RᵀR, U unit upper triangular) of the penalised normal matrix
    A = Bᵀ·diag(g²)·B + λ·D₂ᵀD₂ of a uniform cubic B-spline B with a knot every m samples, λ = ``smoothing`` × the
    mean diagonal of Bᵀ·diag(g²)·B: U's superdiagonals in the upper banded storage of
    :func:`scipy.linalg.cholesky_banded`, d in its diagonal row.

    Stored so, the triangular solves of :func:`spline_fit` run on U's unit diagonal (LAPACK reads no diagonal then)
    and divide by d once, vectorised: without the division in every step of its sequential sweep, the
    solve with Uᵀ took 8.3 ms where the one with Rᵀ took 12.9 ms (18 columns of 85 336 rows, one 20 s chunk)."""
    n = g.size
    nk = -(-n // m)
    W = bspline_weights(m)
    G2 = np.empty(nk * m)
    np.square(g, out=G2[:n])
    G2[n:] = 0.0  # the last knot span's samples past n
    pairs = [(k, l) for k in range(4) for l in range(k, 4)]
    # (10, m) @ (m, nk): one row per pair of active coefficients, read contiguously below
    diag = np.stack([W[:, k] * W[:, l] for k, l in pairs]) @ G2.reshape(nk, m).T
    ab = np.zeros((4, nk + 3))  # upper banded storage: ab[3 - d, j] = A[j - d, j]
    for q, (k, l) in enumerate(pairs):
        ab[3 - (l - k), l:l + nk] += diag[q]
    lam = smoothing * ab[3].mean()
    d2 = np.array([1.0, -2.0, 1.0])
    for a in range(3):
        for b in range(a, 3):
            ab[3 - (b - a), b:b + nk + 1] += lam * d2[a] * d2[b]
    r_band = cholesky_banded(ab, overwrite_ab=True)
    d = r_band[3].copy()
    for u in range(3):  # superdiagonal 3 − u: R[j − 3 + u, j] in column j, row j − 3 + u scaled by its d
        r_band[u, 3 - u:] /= d[:d.size - 3 + u]
    return r_band


def spline_fit(y: np.ndarray, g: np.ndarray, m: int, r_band: np.ndarray, extra: np.ndarray,
               offset: SlowOffset | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Penalised LS of y ≈ g·s(t) + Σ β_k·x_k, s a uniform cubic B-spline (knot every m samples), R the
    Cholesky factor of the spline's penalised normal matrix (:func:`spline_factor` of the same g and m, diag(d)·U).

    The global coefficients β border the banded spline system and are eliminated by their Schur
    complement. ``y`` may hold several right-hand sides as columns, shape (n, r): one factorisation
    serves them all. The columns x_k are the functions of ``offset`` (if given), then the rows of ``extra``,
    shape (len(extra), n). Returns s at the samples (shape of ``y``) and β (shape (k,) or (k, r)).

    The projections Bᵀ(g·x) and the products xᵀ·x, xᵀ·y are summed block by block of :data:`_BLOCK_SPANS`
    knot spans (cache-sized), each with the offset functions non-zero there only; the triangular solve of
    a column starts where the column does.
    """
    n = y.shape[0]
    nk = -(-n // m)
    W = bspline_weights(m)
    Yt = y.reshape(n, -1).T
    nd = 0 if offset is None else offset.count
    ny, ne = Yt.shape[0], nd + extra.shape[0]
    dense = nd + np.arange(extra.shape[0])
    Pt = np.zeros((ny + ne, nk + 3))  # rows: Bᵀ(g·y_i), then Bᵀ(g·x_k)
    VV, VY = np.zeros((ne, ne)), np.zeros((ne, ny))
    for k0 in range(0, nk, _BLOCK_SPANS):
        k1 = min(nk, k0 + _BLOCK_SPANS)
        s0, s1 = k0 * m, min(n, k1 * m)
        if offset is None:
            act, v = dense, extra[:, s0:s1]
        else:
            local, v = offset.block(s0, s1, below=extra[:, s0:s1])
            act = np.concatenate((local, dense))
        yb = Yt[:, s0:s1]
        VV[act[:, None], act] += v @ v.T
        VY[act] += v @ yb.T
        rows = np.empty((ny + act.size, (k1 - k0) * m))
        rows[:, s1 - s0:] = 0.0  # the last block's samples past n, if any (the rest written below)
        np.multiply(yb, g[s0:s1], out=rows[:ny, :s1 - s0])
        np.multiply(v, g[s0:s1], out=rows[ny:, :s1 - s0])
        # (4, m) @ (m, rows·spans): a wide product (the tall (rows·spans, m) @ (m, 4) is ~10× slower in OpenBLAS)
        full = (W.T @ rows.reshape(-1, m).T).reshape(4, rows.shape[0], k1 - k0)
        # the block's projections, then one scattered add into Pt (started from a copy of the first term, not zeros plus
        # it: a zero's sign aside the same sums, and Pt, from zeros, holds no −0.0 for that sign to show in)
        local_p = np.empty((rows.shape[0], k1 - k0 + 3))
        local_p[:, :k1 - k0] = full[0]
        local_p[:, k1 - k0:] = 0.0
        for k in range(1, 4):
            local_p[:, k:k1 - k0 + k] += full[k]
        Pt[np.concatenate((np.arange(ny), ny + act)), k0:k1 + 3] += local_p
    # A = RᵀR (:func:`spline_factor`). The Schur complement needs Pᵤᵀ·A⁻¹·[P_y, Pᵤ] = Zᵤᵀ·[Z_y, Zᵤ] with Z = R⁻ᵀ·P (one
    # triangular solve per column), and the spline only R⁻¹·(Z_y − Zᵤ·β): half the banded solves of A⁻¹·P, which
    # are sequential level-2 sweeps, one per column (LAPACK's tbsv). Rᵀ is lower triangular, so a column of P that
    # is zero up to row j has Z zero there too: its sweep starts at j (the same arithmetic on the rest)
    start = np.zeros(ny + ne, dtype=np.int64)
    if offset is not None:
        start[ny:ny + nd] = offset.support()[:, 0] // m
    # (R = diag(d)·U: Rᵀz = p is Uᵀw = p, z = w/d, and R·c = b is U·c = b/d). Z is Pt's memory seen transposed
    # (Fortran order), each column solved and divided by d in place of its row of Pt (Pt is not needed after): Z's
    # 12 MB (18 columns of a 20 s chunk) are neither zeroed nor gathered, copied and scattered back. A column's rows
    # before its start are zero in Pt already, and stay so (0/d). Pt's rows a … b − 1 from column j on are a Fortran-
    # ordered block of Z for j = 0 (each run of consecutive columns starting there) or a single row
    for j in np.unique(start):
        cols = np.flatnonzero(start == j)
        runs = np.split(cols, np.flatnonzero(np.diff(cols) > 1) + 1) if j == 0 else np.split(cols, cols.size)
        for run in runs:
            z = Pt[run[0]:run[-1] + 1, j:].T
            # LAPACK solves z itself (Fortran-contiguous), and NumPy skips assigning an array to itself
            z[...] = _banded_triangular_solve(r_band[:, j:], z, transpose=True, overwrite_b=True)
            z /= r_band[3][j:, None]
    Z = Pt.T
    Zy, Zu = Z[:, :ny], Z[:, ny:]
    beta = np.linalg.lstsq(VV - Zu.T @ Zu, VY - Zu.T @ Zy, rcond=None)[0]
    b = Zy - Zu @ beta
    b /= r_band[3][:, None]
    coef = _banded_triangular_solve(r_band, b, transpose=False, overwrite_b=True)
    c4 = np.empty((ny, nk, 4))  # the 4 coefficients active in each knot span, per right-hand side
    for k in range(4):
        c4[:, :, k] = coef[k:k + nk].T
    # one (ny·nk, 4) @ (4, m) product: each span's m samples, in sample order (10× faster than the wide product
    # (m, 4) @ (4, nk·ny) and its transposing copy back to sample order)
    s_rows = (c4.reshape(-1, 4) @ W.T).reshape(ny, nk * m)[:, :n]
    return (s_rows[0], beta[:, 0]) if y.ndim == 1 else (s_rows.T, beta)


def _banded_triangular_solve(r_band: np.ndarray, b: np.ndarray, transpose: bool,
                             overwrite_b: bool = False) -> np.ndarray:
    """U⁻ᵀ·b (``transpose``) or U⁻¹·b for U unit upper triangular in the banded storage of
    :func:`scipy.linalg.cholesky_banded` (its diagonal row not read; LAPACK dtbtrs, scipy.linalg offers no public
    banded triangular solve). ``overwrite_b``: b (Fortran order) may be solved in place instead of copied first."""
    x, info = dtbtrs(r_band, b, uplo="U", trans="T" if transpose else "N", diag="U", overwrite_b=overwrite_b)
    if info != 0:
        raise np.linalg.LinAlgError(f"banded triangular solve failed (LAPACK info {info})")
    return x
