"""What a recording must offer for the analysis to run at all, so a bench can be refused before it records.

* The encoder must sample fast enough that the fit band (:func:`analysis.fit.default_band_hz`: 10 Hz up to
  0.4 × its rate) is not empty.
* The current must be sampled fast enough for the chain's anti-alias filter, which stops at 0.6 × the encoder
  rate before the torque is moved onto the encoder's instants (:mod:`analysis.signals`): that edge must lie
  below the DAQ's Nyquist frequency.
"""

from __future__ import annotations

from analysis.fit import default_band_hz
from analysis.signals import _STOP_FRACTION


def encoder_period_problem(period_s: float) -> str | None:
    """Why an encoder sampled every ``period_s`` (s) leaves no fit band, or None when it does."""
    low, high = default_band_hz(period_s)
    if high > low:
        return None
    return (f"the encoder then samples at {1.0 / period_s:g} Hz, too slow for the fit band (from {low:g} Hz to "
            f"0.4 × its rate = {high:g} Hz): it must be below {0.4 / low:g} s")


def min_current_rate_hz(period_s: float) -> float:
    """The lowest DAQ rate, Hz, whose Nyquist frequency lies above the chain's anti-alias stop edge for an
    encoder sampled every ``period_s`` (s)."""
    return 2.0 * _STOP_FRACTION / period_s

