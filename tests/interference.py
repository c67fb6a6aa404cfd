"""Interference added to a recorded phase current, as a bench without it would not have it (tests and bench/).

What the simulated bench does not (yet) make: mains hum with harmonics, a sensor offset that drifts as a
random walk, and fixed tones such as a drive's PWM ripple folded by a DAQ without anti-alias filter.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from analysis.recording import Recording


def with_interference(rec: Recording, seed: int, *, hum_A: float = 0.0, mains_hz: float = 50.0,
                      drift_A: float = 0.0, tones_A: float = 0.0, tone_hz: tuple[float, ...] = (),
                      tone_band_hz: tuple[float, float] = (2000.0, 4000.0), n_tones: int = 0) -> Recording:
    """``rec`` with interference added to ``i_a``.

    Parameters
    ----------
    rec : Recording
        The recording.
    seed : int
        Draws the phases, the mains frequency's deviation (±0.1 %), the drift's walk and tone frequencies.
    hum_A : float
        Amplitude of the mains fundamental, A; the 3rd and 5th harmonics get 30 % and 15 % of it.
    mains_hz : float
        Nominal mains frequency, Hz.
    drift_A : float
        Peak-to-peak excursion of the offset's random walk, A.
    tones_A : float
        Amplitude of each fixed tone, A.
    tone_hz : tuple of float
        Tone frequencies, Hz; if empty, ``n_tones`` drawn uniformly in ``tone_band_hz``.
    """
    rng = np.random.default_rng([seed, 13])
    i = rec.current_a["i_a"].copy()
    t = np.arange(i.size) / rec.rate_hz
    f0 = mains_hz * (1.0 + rng.uniform(-1e-3, 1e-3))
    for k, share in ((1, 1.0), (3, 0.3), (5, 0.15)):
        i += share * hum_A * np.sin(2 * np.pi * k * f0 * t + rng.uniform(0, 2 * np.pi))
    walk = np.cumsum(rng.standard_normal(i.size))
    if drift_A > 0:
        i += drift_A * (walk - walk.mean()) / np.ptp(walk)
    freqs = tone_hz or tuple(rng.uniform(*tone_band_hz, size=n_tones))
    for f in freqs:
        i += tones_A * np.sin(2 * np.pi * f * t + rng.uniform(0, 2 * np.pi))
    return replace(rec, current_a={**rec.current_a, "i_a": i})
