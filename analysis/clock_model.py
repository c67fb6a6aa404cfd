"""The clock relation the alignment recovers, and the drift two crystal clocks can have (design §4).

Convention (shared with the simulator and the report): t_drive = offset_s + t_daq·(1 + drift_ppm·1e-6),
with t_daq = n / rate_hz for DAQ sample n and t_drive = k·T for drive cycle k. :func:`analysis.clocks.fit_clock`
finds it; :class:`ClockFit` holds it with what each stage found.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np

from analysis.fit import Z95

#: The largest drift, ppm, two free-running clocks can have against each other: the DAQ's timebase and the drive's
#: are crystal oscillators specified to ±50…100 ppm of nominal (over temperature and ageing), so two of them differ
#: by at most 200 ppm (design §4's plausible range, ±100 ppm, is the common pair of ±50 ppm parts). A fit needing
#: more has locked onto a wrong lag — on a robot's point-to-point moves the phase of i_a matches the encoder's
#: angle mod 2π at many relations, some of them stretched by percents. Drifts beyond this bound are rejected.
MAX_DRIFT_PPM = 200.0

ClockMethod = Literal["angle", "frequency", "wide", "host", "none"]


@dataclass(frozen=True)
class ClockFit:
    """The recovered relation t_drive = offset_s + t_daq·(1 + drift_ppm·1e-6).

    Attributes
    ----------
    offset_s : float
        Drive time of DAQ sample 0, s.
    drift_ppm : float
        Rate of the drive clock against the DAQ clock, ppm.
    residual_s : float
        Information-weighted RMS timing residual of the angle windows, s (NaN below the angle stage).
    offset_std_s, drift_std_ppm : float
        Standard errors of offset (at DAQ time 0), s, and drift, ppm (NaN below the angle stage).
    theta0_rad : float
        Electrical offset θ_0 modulo π from the angle stage, rad (NaN below it).
    host_offset_s, host_drift_ppm : float
        Stage 1 result from the host stamps (NaN without stamps).
    frequency_offset_s, frequency_drift_ppm : float
        Frequency stage result (NaN when the motion gave no usable window).
    n_windows : int
        Angle windows used in the final fit.
    method : {"angle", "frequency", "wide", "host", "none"}
        The last stage that succeeded ("none": streams taken as started together, no alignment).
    wide_offset_s : float
        The wide search's best offset, s (NaN when it found no motion on both sides).
    ambiguous_by_s : tuple of float
        Shifts, s, of the offset that fit the data as well (whole periods of the motion) and that no
        shared host clock resolved; empty when the offset is unique.
    notes : tuple of str
        What a person should know about the alignment (host stamps overruled, ambiguity).
    failure : str
        Why no alignment was found (every fit of the electrical angle needed a drift beyond
        :data:`MAX_DRIFT_PPM`); empty when the alignment did not fail. The relation is then the best
        guess left (frequency stage, host stamps, or "started together") and not to be trusted.
    """

    offset_s: float
    drift_ppm: float
    residual_s: float = np.nan
    offset_std_s: float = np.nan
    drift_std_ppm: float = np.nan
    theta0_rad: float = np.nan
    host_offset_s: float = np.nan
    host_drift_ppm: float = np.nan
    frequency_offset_s: float = np.nan
    frequency_drift_ppm: float = np.nan
    n_windows: int = 0
    method: ClockMethod = "none"
    wide_offset_s: float = np.nan
    ambiguous_by_s: tuple[float, ...] = ()
    notes: tuple[str, ...] = ()
    failure: str = ""

    def drive_time_s(self, t_daq_s: np.ndarray | float) -> np.ndarray:
        """Drive time, s, of DAQ time ``t_daq_s``, s."""
        return self.offset_s + np.asarray(t_daq_s) * (1.0 + self.drift_ppm * 1e-6)

    def daq_time_s(self, t_drive_s: np.ndarray | float) -> np.ndarray:
        """DAQ time, s, of drive time ``t_drive_s``, s."""
        return (np.asarray(t_drive_s) - self.offset_s) / (1.0 + self.drift_ppm * 1e-6)


def plausible_drift(drift_ppm: float, drift_std_ppm: float) -> bool:
    """False when a fitted drift, ppm, lies beyond :data:`MAX_DRIFT_PPM` by more than its own 95 % uncertainty
    (``drift_std_ppm``, its standard error, ppm; NaN counts as zero): the data then say the clocks would
    have to differ by more than any pair of crystal oscillators does."""
    return not abs(drift_ppm) - Z95 * float(np.nan_to_num(drift_std_ppm)) > MAX_DRIFT_PPM
