"""Frequency response torque → motor speed by Welch's method (design §5 step 4).

H1 = G_xy / G_xx with Hann windows, 0.5 s segments, 50 % overlap and a linear detrend per
segment, and the coherence γ² = |G_xy|² / (G_xx G_yy). The speed is a backward difference of the
encoder angle, whose response relative to the true speed is D(f) = (1 − e^{−j2πfT})/(j2πfT); it is
divided out of H so that H is the plant's own response.

Two effects the fit models instead of ignoring (:func:`estimate_frf` measures what they need):

* fold-over: the encoder samples the position without an anti-alias filter, so the speed samples at
  f also carry the plant's response to the torque near k/T ± f (the triangle's harmonics are phase
  locked, so this is coherent and the coherence cannot reveal it). With the torque shifted by k/T,
  u_k, E[H1(f)] = H(f) + Σ_k [H(k/T + f)·f/(k/T + f)·A_k(f) − H*(k/T − f)·f/(k/T − f)·B_k(f)],
  A_k = G_{x u_k}/G_xx, B_k = G_{x ū_k}/G_xx. On a stiff plant it biased K and J_m by +0.6…0.9 %.
* torque noise: noise n on the torque estimate biases H1 by the factor 1 − G_nn/G_xx, most where
  the torque is weakest — at the resonance, where the speed loop notches it (C +15 % on a stiff
  plant). G_nn comes from the torque estimator's response to white noise.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from functools import lru_cache

import numpy as np

from analysis import welch
from analysis.encoder import difference_response
from analysis.segments import SegmentSelection, select_segments
from analysis.unknown_torque import unknown_torque_segments


KERNEL_PER_BIN = 8
KERNEL_HALF_WIDTH_BINS = 4
# below this many blocks the jackknife variance has too few degrees of freedom to be worth its cost
MIN_JACKKNIFE_BLOCKS = 4


class RecordTooShortError(ValueError):
    """The signals are too short for two Welch segments; the message names the duration needed."""


@dataclass(frozen=True)
class FrequencyResponse:
    """An estimated frequency response torque → motor speed.

    Attributes
    ----------
    f_hz : ndarray
        Frequencies, Hz, from 0 to the Nyquist frequency of the encoder grid.
    H : ndarray of complex
        H1 estimate, (rad/s)/(N·m), with the difference operator divided out.
    coherence : ndarray
        Magnitude-squared coherence γ² between torque and speed, 0…1.
    torque_psd : ndarray
        One-sided power spectral density of the torque, (N·m)²/Hz, at ``f_hz``.
    torque_psd_fine : ndarray
        The same at ``KERNEL_PER_BIN`` times finer spacing (segments that much longer, or the
        whole record zero-padded), for the spectral window of :func:`window_kernel`.
    segment_s : float
        Welch segment length, s.
    n_segments : int
        Number of (overlapping) segments averaged.
    period_s : float
        Sample period of the signals, s (the encoder period).
    noise_ratio : ndarray or None
        G_nn/G_xx per bin, the share of the torque PSD that is estimation noise (clipped to 0…0.5);
        None when unknown (taken as 0).
    alias : ndarray of complex or None
        Shape (k, 2, n_bins): A_k and B_k of the fold-over terms, k = 1, 2, …; None when unknown.
    replicates : tuple of FrequencyResponse or None
        The same estimate with one contiguous block of segments left out, one per block (the
        delete-one-block jackknife of :func:`analysis.fit.fit_two_mass`); None when not asked for.
    selection : SegmentSelection or None
        The segments averaged when segment selection was asked for (:mod:`analysis.segments`); None: all.
    unknown_torque : ndarray of bool or None
        One per segment of the record's segmentation: True where the segment was left out because the torque
        estimate there carries far more of its own error than the record's other segments do
        (:func:`analysis.unknown_torque.unknown_torque_segments`); None when the estimate's standard error was not
        given.
    """

    f_hz: np.ndarray
    H: np.ndarray
    coherence: np.ndarray
    torque_psd: np.ndarray
    torque_psd_fine: np.ndarray
    segment_s: float
    n_segments: int
    period_s: float
    noise_ratio: np.ndarray | None = None
    alias: np.ndarray | None = None
    replicates: tuple[FrequencyResponse, ...] | None = None
    selection: SegmentSelection | None = None
    unknown_torque: np.ndarray | None = None


def min_duration_s(segment_s: float, overlap: float = 0.5) -> float:
    """Shortest record, s, that holds two Welch segments of ``segment_s`` with ``overlap``."""
    return segment_s * (2.0 - overlap)


def segment_layout(segment_s: float, period_s: float, overlap: float = 0.5) -> tuple[int, int]:
    """Samples per Welch segment of ``segment_s`` at ``period_s``, and the hop between segment starts with ``overlap``
    (the share of a segment the next one repeats; Python's round, half to even)."""
    nperseg = int(round(segment_s / period_s))
    return nperseg, nperseg - int(round(overlap * nperseg))


def require_two_segments(n_samples: int, period_s: float, segment_s: float, overlap: float = 0.5) -> None:
    """Raise :class:`RecordTooShortError` unless ``n_samples`` at ``period_s`` hold two Welch segments."""
    nperseg, step = segment_layout(segment_s, period_s, overlap)
    if n_samples < nperseg + step:
        raise RecordTooShortError(
            f"signals last {n_samples * period_s:.3f} s; the FRF needs at least "
            f"{min_duration_s(segment_s, overlap):.3f} s (two {segment_s:g} s Welch segments)"
        )


def window_kernel(frf: FrequencyResponse) -> tuple[np.ndarray, np.ndarray]:
    """The Welch estimate's spectral window: what each FRF bin averages over.

    The expected H1 at bin f is Σ_ν H(f+ν)·S(f+ν)·|W(ν)|² / Σ_ν S(f+ν)·|W(ν)|², with |W|² the
    squared magnitude of the Hann window's transform and S the torque spectrum at a resolution
    finer than the bins (:attr:`FrequencyResponse.torque_psd_fine`; it resolves the harmonics of
    the rectangular torque). Sharp features — the resonance peak and the anti-resonance notch,
    a few hertz wide — are flattened by it at 0.5 s segments; the fit applies the same kernel to
    the model.

    Parameters
    ----------
    frf : FrequencyResponse
        The estimate (segment length, period and fine torque spectrum define the kernel).

    Returns
    -------
    offsets_hz : ndarray, shape (m,)
        Frequency offsets ν, Hz, ± ``KERNEL_HALF_WIDTH_BINS`` bins around each bin.
    weights : ndarray, shape (n_bins, m)
        Kernel of each bin of ``frf.f_hz``, rows summing to 1.
    """
    nperseg, _ = segment_layout(frf.segment_s, frf.period_s)
    spectrum = _window_power(nperseg)
    k = np.arange(-KERNEL_HALF_WIDTH_BINS * KERNEL_PER_BIN, KERNEL_HALF_WIDTH_BINS * KERNEL_PER_BIN + 1)
    fine = np.abs(np.arange(frf.f_hz.size)[:, None] * KERNEL_PER_BIN + k[None, :])
    fine = np.minimum(fine, 2 * (frf.torque_psd_fine.size - 1) - fine)  # mirror at Nyquist
    weights = frf.torque_psd_fine[fine] * spectrum[k % spectrum.size][None, :]
    weights /= np.maximum(weights.sum(axis=1, keepdims=True), np.finfo(float).tiny)
    return k / (KERNEL_PER_BIN * frf.segment_s), weights


@lru_cache(maxsize=8)
def _window_power(nperseg: int) -> np.ndarray:
    """|W|² of the Hann window of ``nperseg`` samples on a grid :data:`KERNEL_PER_BIN` times finer than the bins,
    read-only: the same for the record and each jackknife replicate, so transformed once per length."""
    power = np.abs(np.fft.fft(welch.hann(nperseg), nperseg * KERNEL_PER_BIN)) ** 2
    power.flags.writeable = False
    return power


def estimate_frf(
    torque_Nm: np.ndarray,
    speed_rad_s: np.ndarray,
    period_s: float,
    *,
    segment_s: float = 0.5,
    overlap: float = 0.5,
    torque_noise_Nm: np.ndarray | None = None,
    torque_alias_Nm: np.ndarray | None = None,
    jackknife_blocks: int = 0,
    select_band_hz: tuple[float, float] | None = None,
    reuse_selection: SegmentSelection | None = None,
    torque_std_Nm: np.ndarray | None = None,
    leave_out: np.ndarray | None = None,
) -> FrequencyResponse:
    """Estimate H1 = G_xy/G_xx and the coherence from torque and backward-difference speed.

    Parameters
    ----------
    torque_Nm : ndarray
        Electromagnetic torque, N·m, on the encoder's regular grid.
    speed_rad_s : ndarray
        Motor speed, rad/s, the backward difference of the encoder angle on the same grid.
    period_s : float
        Grid period T, s.
    segment_s : float, optional
        Welch segment length, s (0.5 s by default: 2 Hz resolution).
    overlap : float, optional
        Fraction of a segment shared with the next one, 0 ≤ overlap < 1.
    torque_noise_Nm : ndarray or None, optional
        A realisation of the torque estimate's noise on the same grid, N·m (for ``noise_ratio``).
    torque_alias_Nm : ndarray of complex or None, optional
        Shape (k, n): the torque shifted down by 1/T, 2/T, … and read on the grid, N·m (for ``alias``).
    jackknife_blocks : int, optional
        Also estimate the response with each of this many contiguous blocks of segments left out
        (``replicates``, for the fit's delete-one-block jackknife). Fewer blocks when the record holds
        fewer than two segments per block; none below :data:`MIN_JACKKNIFE_BLOCKS`.
    select_band_hz : tuple of float or None, optional
        Average only the segments that excite the joint in this band (low, high), Hz
        (:func:`analysis.segments.select_segments`; ``selection`` says which); None: every segment.
    reuse_selection : SegmentSelection or None, optional
        Average the segments another estimate selected (the same stretches of other signals) instead of
        selecting; None: every segment, or those ``select_band_hz`` selects.
    torque_std_Nm : ndarray or None, optional
        Standard error of the torque estimate at each sample, N·m: segments where it makes an outlying share of
        the torque are left out (:func:`analysis.unknown_torque.unknown_torque_segments`, ``unknown_torque``); None:
        none left out. Not where a segment selection found fewer than two segments that excite (the record is judged
        as not excited).
    leave_out : ndarray of bool or None, optional
        Leave out these segments as if ``torque_std_Nm`` had flagged them (another estimate's ``unknown_torque``, with
        its ``selection`` as ``reuse_selection``); None: as ``torque_std_Nm`` says.

    Returns
    -------
    FrequencyResponse

    Raises
    ------
    RecordTooShortError
        If the signals do not hold two segments.
    ValueError
        If the two signals differ in length.
    """
    x = np.asarray(torque_Nm, dtype=float)
    y = np.asarray(speed_rad_s, dtype=float)
    if x.shape != y.shape or x.ndim != 1:
        raise ValueError(f"torque and speed must be 1-D arrays of one length, got {x.shape} and {y.shape}")
    require_two_segments(x.size, period_s, segment_s, overlap)
    fs = 1.0 / period_s
    nperseg, step = segment_layout(segment_s, period_s, overlap)
    n_segments = 1 + (x.size - nperseg) // step
    seg = welch.Segments(nperseg, step, fs)
    X, Y = seg.fft(x), seg.fft(y)
    N = None if torque_noise_Nm is None else seg.fft(np.asarray(torque_noise_Nm, dtype=float))
    U = None if torque_alias_Nm is None else [seg.fft(uk) for uk in np.atleast_2d(torque_alias_Nm)]
    n_fine = KERNEL_PER_BIN * nperseg
    selection = reuse_selection
    if selection is None and select_band_hz is not None:
        f = np.fft.rfftfreq(nperseg, period_s)
        selection = select_segments(X, Y, (f >= select_band_hz[0]) & (f <= select_band_hz[1]), nperseg, step)
    unknown = leave_out
    if unknown is None and torque_std_Nm is not None and (selection is None or selection.applied):
        unknown = unknown_torque_segments(x, np.asarray(torque_std_Nm, dtype=float), nperseg, step,
                                          None if selection is None else selection.keep)
    # left out as the selection leaves out segments that do not excite (the selection itself still says which excite)
    used = selection if unknown is None or not unknown.any() else SegmentSelection(
        (np.ones(unknown.size, dtype=bool) if selection is None else selection.keep) & ~unknown,
        np.full(unknown.size, np.inf), 0.0, nperseg, step, True)
    if used is not None:
        keep = used.keep
        X, Y = X[keep], Y[keep]
        N = None if N is None else N[keep]
        U = None if U is None else [u[keep] for u in U]
        n_segments = X.shape[0]
    gxx_fine = _fine_psd(x, fs, nperseg, step, n_fine, None if used is None else used.runs())
    blocks = min(jackknife_blocks, n_segments // 2)
    jackknife = blocks >= MIN_JACKKNIFE_BLOCKS
    # delete-one-block replicates: the segments of one contiguous stretch of the record left out; each is the total's
    # sums less that block's
    block = np.arange(n_segments) * blocks // n_segments if jackknife else np.zeros(n_segments, dtype=int)
    parts = _block_sums(seg, X, Y, N, U, np.flatnonzero(np.diff(block, prepend=-1)))
    total = parts[0]
    for part in parts[1:]:
        total = total + part
    full = replace(_response(seg, total, gxx_fine, period_s), selection=selection, unknown_torque=unknown)
    if not jackknife:
        return full
    return replace(full, replicates=tuple(_response(seg, total - part, gxx_fine, period_s) for part in parts))


def _fine_psd(x: np.ndarray, fs: float, nperseg: int, step: int, n_fine: int,
              runs: list[tuple[int, int]] | None) -> np.ndarray:
    """Torque PSD at ``n_fine`` bins from the samples of the runs of segments (first, last + 1) given, each run's
    Welch estimate (segments up to ``n_fine`` long) weighted by its number of segments; None: the whole record."""
    if runs is None:
        return welch.psd(x, fs, min(n_fine, x.size), detrend="linear", nfft=n_fine)[1]
    total = np.zeros(n_fine // 2 + 1)
    for first, end in runs:
        span = x[first * step: (end - 1) * step + nperseg]
        _, psd = welch.psd(span, fs, min(n_fine, span.size), detrend="linear", nfft=n_fine)
        total += (end - first) * psd
    return total / sum(end - first for first, end in runs)


@dataclass(frozen=True)
class _Sums:
    """Sums over a set of segments of the products the response needs, and the number of segments: conj(X)·X,
    conj(Y)·Y, conj(X)·Y and conj(N)·N at the one-sided bins, and per fold-over signal u_k conj(X)·U_k(f) and
    conj(X)·conj(U_k(−f)), shape (k, 2, bins). Sums, not means: a delete-one-block replicate is the total less one
    block's sums (one pass over the segments for all replicates instead of one per replicate)."""

    count: int
    xx: np.ndarray
    yy: np.ndarray
    xy: np.ndarray
    nn: np.ndarray | None
    xu: np.ndarray | None

    def __add__(self, other: _Sums) -> _Sums:
        return self._combine(other, 1.0)

    def __sub__(self, other: _Sums) -> _Sums:
        return self._combine(other, -1.0)

    def _combine(self, other: _Sums, sign: float) -> _Sums:
        def f(a: np.ndarray | None, b: np.ndarray | None) -> np.ndarray | None:
            return None if a is None or b is None else a + sign * b

        return _Sums(self.count + int(sign) * other.count, f(self.xx, other.xx), f(self.yy, other.yy),
                     f(self.xy, other.xy), f(self.nn, other.nn), f(self.xu, other.xu))


def _block_sums(seg: welch.Segments, X: np.ndarray, Y: np.ndarray, N: np.ndarray | None, U: list[np.ndarray] | None,
                starts: np.ndarray) -> list[_Sums]:
    """:class:`_Sums` of each run of segments from ``starts[i]`` up to the next start (the last: to the end)."""
    n = seg.nperseg // 2 + 1
    conj_x = np.conj(X[:, :n])

    def by_block(p: np.ndarray) -> np.ndarray:
        return np.add.reduceat(p, starts, axis=0)

    xx, yy, xy = by_block(conj_x * X[:, :n]), by_block(np.conj(Y[:, :n]) * Y[:, :n]), by_block(conj_x * Y[:, :n])
    nn = None if N is None else by_block(np.conj(N[:, :n]) * N[:, :n])
    # the FFT of conj(u) at bin f is conj(U(−f)) (U two-sided)
    xu = None if U is None else np.stack([np.stack((by_block(conj_x * u[:, :n]),
                                                    by_block(conj_x * np.conj(u[:, (-np.arange(n)) % seg.nperseg]))))
                                          for u in U])  # (k, 2, blocks, n)
    counts = np.diff(np.append(starts, X.shape[0]))
    return [_Sums(int(c), xx[b], yy[b], xy[b], None if nn is None else nn[b], None if xu is None else xu[:, :, b])
            for b, c in enumerate(counts)]


def _response(seg: welch.Segments, sums: _Sums, gxx_fine: np.ndarray, period_s: float) -> FrequencyResponse:
    """H1, coherence and the noise / fold-over terms averaged over the segments whose ``sums`` are given."""
    f = np.fft.rfftfreq(seg.nperseg, period_s)
    gxx, gyy = seg.density_of_sum(sums.xx, sums.count).real, seg.density_of_sum(sums.yy, sums.count).real
    gxy = seg.density_of_sum(sums.xy, sums.count)
    with np.errstate(divide="ignore", invalid="ignore"):
        h = gxy / gxx / difference_response(f, period_s)
        coh = np.abs(gxy) ** 2 / (gxx * gyy)
    coh = np.clip(np.nan_to_num(coh, nan=0.0), 0.0, 1.0)
    noise_ratio = alias = None
    if sums.nn is not None:
        with np.errstate(divide="ignore", invalid="ignore"):
            noise_ratio = np.clip(np.nan_to_num(seg.density_of_sum(sums.nn, sums.count).real / gxx, nan=0.0), 0.0, 0.5)
    if sums.xu is not None:
        with np.errstate(divide="ignore", invalid="ignore"):  # A_k = G_{x u_k}/G_xx, B_k = G_{x ū_k}/G_xx
            alias = np.nan_to_num(sums.xu / sums.xx.real)
    return FrequencyResponse(
        f_hz=f,
        H=h,
        coherence=coh,
        torque_psd=gxx,
        torque_psd_fine=gxx_fine,
        segment_s=seg.nperseg * period_s,
        n_segments=sums.count,
        period_s=period_s,
        noise_ratio=noise_ratio,
        alias=alias,
    )
