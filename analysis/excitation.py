"""Why the coherence is weak: the cause the session's own spectra support, and the remedy only where it applies.

The coherence γ² of the torque → speed FRF misses 1 − γ² of the speed's power. Two noises of the chain are known
from the data, bin by bin: the speed noise of the encoder's quantisation, N_q (:func:`analysis.encoder.quantisation_bound`),
and the torque estimate's own noise, the share G_nn/G_xx of the torque PSD
(:attr:`analysis.frf.FrequencyResponse.noise_ratio`). Where the coherence is weak each is held against what the
coherence misses:

* the quantisation is at least half of the speed's missing power → the encoder's resolution limits the band there;
* the torque estimate's noise is at least half of it → the motion puts too little torque there (the torque sits at
  its estimate's noise floor);
* neither, while both are known → the torque estimate carries power the speed does not follow (interference on the
  phase current — named, with its remedy, only when the torque estimate found some: a line or a moving offset — or a
  drive that does not respond linearly, or the streams' timing);
* otherwise (neither noise known) only what is weak and where.

How the motion is shaped decides the motion's remedy: a step of torque (a ramp's corner) has a spectrum falling as
f⁻², a step smoothed over a time t (an S-curve's jerk time, or a speed loop that makes the torque from its error
alone) as f⁻⁴ above ≈ 1/(πt); the torque PSD's log–log slope below f_a tells which. Advice that names a profile key
is given only when the session's profile (:class:`analysis.recording.CommandedProfile`) is known and has that key set.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np
from scipy.ndimage import median_filter

from analysis.encoder import quantisation_bound
from analysis.frf import FrequencyResponse
from analysis.recording import CommandedProfile

if TYPE_CHECKING:
    from analysis.torque import Interference

#: A named noise is the cause when it is at least half of what the coherence misses: then it is the larger part.
CAUSE_SHARE = 0.5
#: Log–log slope of the torque PSD below f_a that separates steps of torque (−2: a step's spectrum) from smoothed
#: steps (−4 above the smoothing's corner): midway, −3.
SMOOTH_SLOPE = -3.0
#: Bins of the running median that judges where the coherence is weak: a few bins, so that the anti-resonance's
#: notch (a couple of bins wide at 0.5 s segments) is no weak stretch of its own.
SMOOTH_BINS = 5
#: The words by which a weak coherence's reason names the encoder's resolution as its cause.
RESOLUTION_NAMED = "where the encoder's resolution"


def against_limit(value: float, limit: float, decimals: int = 2) -> str:
    """``value`` with at least ``decimals`` decimals and as many more (up to 6) as it takes to read apart from
    ``limit`` (0.718 against 0.72, not 0.72), for a sentence that compares the two."""
    for d in range(decimals, 7):
        text = f"{value:.{d}f}"
        if float(text) != limit:
            return text
    return f"{value:.6f}"


def weak_coherence_cause(frf: FrequencyResponse, check: np.ndarray, limit: float, *, lsb_rad: float = 0.0,
                         profile: CommandedProfile | None = None, f_a_hz: float = float("nan"),
                         band_mask_all: np.ndarray | None = None,
                         interference: tuple[Interference, ...] = ()) -> str:
    """Where the coherence is weak in the bins ``check`` and what the data say causes it, as one clause.

    Parameters
    ----------
    frf : FrequencyResponse
        The measured frequency response.
    check : ndarray of bool
        The bins the failing check averaged (the fit band, or f_a…f_r).
    limit : float
        The coherence below which the check counts as poor.
    lsb_rad : float, optional
        One encoder count, rad (0: the encoder's resolution unknown — the quantisation is not judged).
    profile : CommandedProfile or None, optional
        The profile acq commanded (None: unknown — no advice naming a profile key).
    f_a_hz : float, optional
        The fitted anti-resonance, Hz: the torque's shape is judged below it (NaN: the whole band).
    band_mask_all : ndarray of bool or None, optional
        The fit band's bins (for the torque's shape; None: ``check``).
    interference : tuple of Interference, optional
        What the torque estimate removed from the current (:attr:`analysis.signals.PreparedSignals.interference`).

    Returns
    -------
    str
        E.g. "below 0.72 in 150…400 Hz, where the encoder's resolution (10000 counts/rev, …) …".
    """
    f = frf.f_hz[check]
    g2 = np.clip(frf.coherence[check], 1e-6, 1.0 - 1e-9)
    low, high = _weak_stretch(f, g2, limit)
    where = f"below {limit:g} in {low:.0f}…{high:.0f} Hz"
    weak = (f >= low) & (f <= high)
    missed = (1.0 - g2[weak]) / g2[weak]  # the speed's power the coherence misses, over its coherent power
    torque_noise = (frf.noise_ratio[check][weak] if frf.noise_ratio is not None else np.zeros(int(weak.sum())))
    torque_share = float(np.median(torque_noise / (1.0 - g2[weak])))  # input noise leaves γ² ≤ 1 − G_nn/G_xx
    gain = _power_needed(g2, limit)
    motion = _motion_remedy(frf, band_mask_all if band_mask_all is not None else check, f_a_hz, profile, gain)
    if lsb_rad > 0.0:
        bound2 = quantisation_bound(f[weak], frf.H[check][weak], frf.torque_psd[check][weak], frf.period_s,
                                    lsb_rad) ** 2  # N_q over the coherent speed power
        quant_share = float(np.median(bound2 / missed))
        above_floor_db = float(np.median(10.0 * np.log10((1.0 + missed) / bound2)))
        if quant_share >= CAUSE_SHARE and quant_share >= torque_share:
            counts = 2.0 * math.pi / lsb_rad
            finer = _round_up(counts * math.sqrt(gain))
            return (f"{where}, {RESOLUTION_NAMED} ({counts:.0f} counts/rev, [encoder] counts_per_rev) "
                    f"limits it: the speed there is only {above_floor_db:.0f} dB above its quantisation floor — a "
                    f"finer encoder (≈ {finer:.0f} counts/rev; changing counts_per_rev alone breaks a correct bench), or ≈ {gain:.0f}× the torque power above {low:.0f} Hz: "
                    f"{motion}")
    if torque_share >= CAUSE_SHARE:
        return (f"{where}: the torque there is at the torque estimate's own noise floor (the noise is "
                f"{100 * torque_share:.0f} % of what the coherence misses), the motion puts too little torque above "
                f"{low:.0f} Hz — {motion}")
    if lsb_rad > 0.0:
        torque_db = float(-10.0 * np.log10(max(float(np.median(torque_noise)), 1e-12)))
        found = (f"{where}, though the speed there is {above_floor_db:.0f} dB above the encoder's quantisation floor "
                 f"and the torque {torque_db:.0f} dB above its estimate's noise: the torque estimate carries power "
                 f"the speed does not follow — ")
        removed = _removed(interference)
        if not removed:  # no line, no moving offset on the current: nothing in the data points at interference
            return (found + "no interference was found on the phase current (no line, no moving offset), so a drive "
                    "that does not respond linearly, or a timing error between the two streams (the clock "
                    "alignment), is left: check the clock notes before the drive")
        return (found + f"interference on the phase current that the torque model leaves in it{removed}, or a drive "
                "that does not respond linearly: remove interference at its source (PWM ripple: the DAQ's anti-alias "
                "filter)")
    return f"{where} (the encoder's resolution and the torque estimate's noise unknown: no cause judged)"


def _weak_stretch(f: np.ndarray, g2: np.ndarray, limit: float) -> tuple[float, float]:
    """The longest run of bins whose running-median coherence is below ``limit``: (low Hz, high Hz); the whole
    stretch when no run is (the mean is low, no part alone)."""
    smooth = median_filter(g2, size=min(SMOOTH_BINS, g2.size), mode="nearest")
    below = np.concatenate(([False], smooth < limit, [False]))
    edges = np.flatnonzero(np.diff(below.astype(int)))
    if edges.size == 0:
        return float(f[0]), float(f[-1])
    starts, stops = edges[::2], edges[1::2]
    k = int(np.argmax(stops - starts))
    return float(f[starts[k]]), float(f[stops[k] - 1])


def _power_needed(g2: np.ndarray, limit: float) -> float:
    """The factor on the coherent power (or on 1/noise) that lifts the mean coherence to ``limit``.

    A bin's coherence with its signal power scaled by s is sγ²/(sγ² + 1 − γ²); the factor is found by bisection on
    log s (the mean rises with s)."""
    def mean_at(s: float) -> float:
        return float(np.mean(s * g2 / (s * g2 + 1.0 - g2)))

    lo, hi = 0.0, 8.0  # log10 s
    if mean_at(10.0**hi) < limit:
        return 10.0**hi
    for _ in range(40):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if mean_at(10.0**mid) < limit else (lo, mid)
    return max(10.0**hi, 1.0)


def torque_slope(frf: FrequencyResponse, band: np.ndarray, f_a_hz: float) -> float:
    """Log–log slope of the torque PSD in ``band`` below ``f_a_hz`` (the whole band if NaN): −2 for steps of
    torque, steeper for smoothed steps (NaN with fewer than three bins)."""
    sel = band & (frf.torque_psd > 0)
    if math.isfinite(f_a_hz):
        sel &= frf.f_hz < f_a_hz
    if np.count_nonzero(sel) < 3:
        return float("nan")
    return float(np.polyfit(np.log(frf.f_hz[sel]), np.log(frf.torque_psd[sel]), 1)[0])


def _motion_remedy(frf: FrequencyResponse, band: np.ndarray, f_a_hz: float, profile: CommandedProfile | None,
                   gain: float) -> str:
    """What in the motion would raise its torque power by ``gain``: the profile key that applies, or a neutral
    description when the profile is unknown."""
    slope = torque_slope(frf, band, f_a_hz)
    shape = f"the torque's spectrum falls as f^{slope:.1f} below f_a where a step's falls as f^-2"
    if slope < SMOOTH_SLOPE:
        if profile is None:
            return f"the torque changes smoothly: {shape}"
        if profile.jerk_time_s > 0.0:
            return (f"shorten jerk_time_s ({profile.jerk_time_s:g} s in the profile): the S-curve smooths the torque "
                    f"steps, {shape}")
        return (f"the profile commands steps of acceleration, yet {shape}: the drive's speed loop makes the torque "
                f"from its error alone — enable the drive's acceleration feed-forward")
    if profile is None:
        return "a motion with larger torque steps"
    # at a given top speed a ramp's corners carry the torque's power: its PSD grows as 1/T³ (the step height as
    # 1/T, the corners' rate as 1/T), so ×gain needs the ramps ×gain^(−1/3) and the peak torque ×gain^(1/3)
    factor = gain ** (-1.0 / 3.0)
    if profile.accel_time_s == profile.decel_time_s:
        ramps = f"≈ {factor * profile.accel_time_s:.2g} s from {profile.accel_time_s:g} s"
    else:
        ramps = (f"≈ {factor * profile.accel_time_s:.2g} s and {factor * profile.decel_time_s:.2g} s from "
                 f"{profile.accel_time_s:g} s and {profile.decel_time_s:g} s")
    return (f"shorten accel_time_s and decel_time_s in the profile to {ramps}, at {1.0 / factor:.1f}× the peak "
            f"torque")


def _removed(interference: tuple[Interference, ...]) -> str:
    """What the torque estimate removed from the current, as a parenthesis ("" when nothing)."""
    lines = sorted({round(hz, 1) for found in interference for hz in found.lines_hz})
    drift_a = max((found.offset_drift_a for found in interference), default=0.0)
    parts = ([f"{len(lines)} lines at {lines[0]:.0f}…{lines[-1]:.0f} Hz" if len(lines) > 1
              else f"a line at {lines[0]:.0f} Hz"] if lines else [])
    parts += [f"an offset moving by {1e3 * drift_a:.0f} mA"] if round(1e3 * drift_a) > 0 else []
    return f" (it removed {' and '.join(parts)})" if parts else ""


def _round_up(x: float) -> float:
    """``x`` rounded up to two significant digits."""
    scale = 10.0 ** (math.floor(math.log10(x)) - 1)
    return math.ceil(x / scale) * scale
