"""Welch's power spectral density with all segments transformed at once.

:func:`scipy.signal.welch` (scipy 1.17, through ``ShortTimeFFT.stft_detrend``) detrends and transforms the
segments one by one in a Python loop — a least-squares fit per segment for a linear detrend, and 250 FFT calls
for a 4096-sample PSD of a 20 s chunk of the 25.6 kS/s current. Here the segments are one strided view, the
trends are removed from all of them at once and one batched FFT transforms them: the same estimate (Hann
window, 50 % overlap, the trailing partial segment dropped, one-sided density scaling) to rounding.
"""

from __future__ import annotations

from functools import lru_cache
from typing import Literal

import numpy as np
from scipy import signal

Detrend = Literal["constant", "linear"] | None


@lru_cache(maxsize=16)
def hann(nperseg: int) -> np.ndarray:
    """``scipy.signal.get_window("hann", nperseg)`` (the periodic Hann window of spectral analysis), read-only and
    computed once per length: an analysis asks for the same few lengths ~50 times (the fit's window kernel for every
    jackknife replicate), and get_window takes 0.1–0.5 ms a call (its array-API checks, not the cosine)."""
    window = signal.get_window("hann", nperseg)
    window.flags.writeable = False
    return window


class Segments:
    """Welch's segmentation, vectorised: Hann window, detrend per segment, density scaling — the same estimates as
    :func:`scipy.signal.welch` / :func:`scipy.signal.csd` with that detrend, each signal transformed once (the FRF
    keeps the spectra of every segment: its jackknife and segment selection need them).

    Parameters
    ----------
    nperseg, step : int
        Samples per segment and between segment starts.
    fs_hz : float
        Sampling rate, Hz.
    detrend : {"linear", "constant", None}
        Subtract each segment's least-squares line, or its mean, before windowing; None: neither.
    nfft : int or None
        FFT length (zero padding beyond ``nperseg``); None: ``nperseg``.
    """

    def __init__(self, nperseg: int, step: int, fs_hz: float, detrend: Detrend = "linear",
                 nfft: int | None = None) -> None:
        self.nperseg, self.step, self.detrend = nperseg, step, detrend
        self.nfft = nperseg if nfft is None else nfft
        self.window = hann(nperseg)
        self.scale = 1.0 / (fs_hz * float(np.sum(self.window**2)))
        self.t = np.arange(nperseg) - 0.5 * (nperseg - 1)  # centred: orthogonal to the constant

    def fft(self, x: np.ndarray) -> np.ndarray:
        """FFT of each detrended, windowed segment; one-sided for real x, shape (segments, bins)."""
        segs = np.lib.stride_tricks.sliding_window_view(x, self.nperseg)[:: self.step]
        if self.detrend is None:
            segs = segs * self.window
        else:
            slope = (segs @ self.t) / float(self.t @ self.t) if self.detrend == "linear" else None
            segs = segs - segs.mean(axis=1, keepdims=True)  # a copy of the strided view: the rest in place
            if slope is not None:
                segs -= slope[:, None] * self.t
            segs *= self.window
        return np.fft.rfft(segs, n=self.nfft, axis=1) if np.isrealobj(segs) else np.fft.fft(segs, n=self.nfft, axis=1)

    def density(self, A: np.ndarray, B: np.ndarray) -> np.ndarray:
        """One-sided cross spectral density G_ab (conj(A)·B averaged), of the non-negative bins."""
        n = self.nfft // 2 + 1
        return self.density_of_sum(np.sum(np.conj(A[:, :n]) * B[:, :n], axis=0), A.shape[0])

    def density_of_sum(self, total: np.ndarray, count: int) -> np.ndarray:
        """One-sided cross spectral density G_ab from the sum of conj(A)·B over ``count`` segments (non-negative
        bins)."""
        n = self.nfft // 2 + 1
        g = total[:n] / count * self.scale
        g[1:n - 1 if self.nfft % 2 == 0 else n] *= 2.0
        return g


def psd(x: np.ndarray, fs_hz: float, nperseg: int, detrend: Detrend = "constant",
        nfft: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Frequencies, Hz, and the one-sided power spectral density of ``x``, unit²/Hz, as
    ``scipy.signal.welch(x, fs_hz, nperseg=nperseg, nfft=nfft, detrend=detrend or False)`` (Hann window, overlap
    ``nperseg // 2``, the trailing partial segment dropped; :class:`Segments`).
    """
    seg = Segments(nperseg, nperseg - nperseg // 2, fs_hz, detrend, nfft)
    spectra = seg.fft(np.asarray(x, dtype=np.float64))
    return np.fft.rfftfreq(seg.nfft, 1.0 / fs_hz), seg.density(spectra, spectra).real
