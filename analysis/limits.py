"""What a recording must offer for the analysis to run at all, so a bench can be refused before it records.

* The encoder must sample fast enough that the fit band (:func:`analysis.fit.default_band_hz`: 10 Hz up to
  0.4 × its rate) is not empty.
* The current must be sampled fast enough for the chain's anti-alias filter, which stops at 0.6 × the encoder
  rate before the torque is moved onto the encoder's instants (:mod:`analysis.signals`): that edge must lie
  below the DAQ's Nyquist frequency.
* A recording must last long enough that two Welch segments remain after what the analysis trims
  (:func:`min_record_s`).
"""

from __future__ import annotations

from analysis.chain import our_chain
from analysis.fit import default_band_hz
from analysis.frf import min_duration_s
from analysis.signals import _PASS_FRACTION, _STOP_FRACTION


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



def min_record_s(rate_hz: float, period_s: float, segment_s: float, start_offset_s: float) -> float:
    """Shortest recording, s of each stream, that leaves two Welch segments of ``segment_s`` after what the analysis
    trims (:func:`analysis.signals.spans_and_clock`): the current outside the encoder's span (the streams' start
    offset ``start_offset_s``, s), the anti-alias filter's transient at both ends of the current (our chain's
    :meth:`~analysis.chain.SignalChain.edge_s` for a DAQ at ``rate_hz`` and an encoder every ``period_s``), and two
    encoder samples (the speed's difference and the rounding of the span onto the encoder's instants)."""
    edge_s = our_chain().edge_s(rate_hz, _PASS_FRACTION / period_s, _STOP_FRACTION / period_s)
    return min_duration_s(segment_s) + abs(start_offset_s) + 2.0 * edge_s + 2.0 * period_s
