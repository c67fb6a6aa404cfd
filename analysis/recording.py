"""One session's raw data as the analysis reads it: plain arrays, nothing resampled or corrected."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class CommandedProfile:
    """The motion profile acq commanded for the record (the session's profile), as far as the analysis reads it.

    Attributes
    ----------
    accel_time_s, decel_time_s : float
        Ramp times from standstill to the top speed and back, s.
    jerk_time_s : float
        S-curve jerk time (the time the acceleration takes to reach its level), s; 0 for plain ramps.
    speed_dither : float
        Each cycle's speed scaled within 1 ± this (0: a motion that repeats exactly).
    """

    accel_time_s: float
    decel_time_s: float
    jerk_time_s: float = 0.0
    speed_dither: float = 0.0


@dataclass(frozen=True)
class Recording:
    """One session's raw data as plain arrays (what ``acq.recording.reader`` reads; nothing resampled).

    Attributes
    ----------
    current_a : dict of str → ndarray
        Phase currents, A (``"i_a"`` required; ``"i_b"``, ``"i_c"`` optional), all blocks concatenated.
    rate_hz : float
        DAQ sample rate as coerced by the card, Hz; DAQ sample n is at t_daq = n / rate_hz.
    encoder_index : ndarray of int64
        Cumulative drive cycle k of each encoder sample (at drive time k·period_s).
    position_counts : ndarray of int64
        Unwrapped position, counts.
    period_s : float
        Drive cycle, s.
    counts_per_rev : int
        Encoder counts per mechanical revolution.
    pole_pairs : int
        Motor pole pairs p.
    k_t_Nm_per_A : float
        Torque constant, N·m/A.
    block_first_index, block_count : ndarray of int64 or None
        DAQ sample index of the first sample of each read, and its sample count. None: one gap-free
        block starting at sample 0.
    block_host_ns, encoder_host_ns : ndarray of int64 or None
        Host monotonic arrival stamps of each DAQ read and each encoder sample, ns (None if not recorded).
    host_clock_shared : bool
        True when both streams' stamps are arrival times on one host clock (a recording by ``acq record``);
        False for files from separate tools, whose time columns relate nothing. Only shared stamps centre
        the clock search; otherwise it runs ±2 s around "both streams started together".
    drive_time_s : ndarray of float64 or None
        The drive's own time stamp of each encoder sample, s (serial frame drive time, CANopen 0x1013):
        the instant it really sampled; its origin and 1 µs quantisation do not matter. None: not recorded.
    profile : CommandedProfile or None
        The profile acq commanded; None when the machine's own controller moved the joint (or not recorded).
    drive_limited_host_ns : ndarray of int64, shape (n, 2), or None
        Host spans (start, end; monotonic ns, the clock of ``encoder_host_ns``) in which the drive reported
        "internal limit active" (CiA 402 0x6041 bit 11, :mod:`analysis.drive_limits`); None or empty: none reported.
    """

    current_a: dict[str, np.ndarray]
    rate_hz: float
    encoder_index: np.ndarray
    position_counts: np.ndarray
    period_s: float
    counts_per_rev: int
    pole_pairs: int
    k_t_Nm_per_A: float
    block_first_index: np.ndarray | None = None
    block_count: np.ndarray | None = None
    block_host_ns: np.ndarray | None = None
    encoder_host_ns: np.ndarray | None = None
    host_clock_shared: bool = True
    drive_time_s: np.ndarray | None = None
    profile: CommandedProfile | None = None
    drive_limited_host_ns: np.ndarray | None = None
