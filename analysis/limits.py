"""What a recording must offer for the analysis to run at all, so a bench can be refused before it records.

* The encoder must sample fast enough that the fit band (:func:`analysis.fit.default_band_hz`: 10 Hz up to
  0.4 × its rate) is not empty.
* The current must be sampled fast enough for the chain's anti-alias filter, which stops at 0.6 × the encoder
  rate before the torque is moved onto the encoder's instants (:mod:`analysis.antialias`): that edge must lie
  below the DAQ's Nyquist frequency.
* A recording must last long enough that two Welch segments remain after what the analysis trims
  (:func:`min_record_s`).
* A fit band asked for must lie where the chain and the fit can judge the joint (:func:`band_problem`).
"""

from __future__ import annotations

from analysis.antialias import PASS_FRACTION, STOP_FRACTION
from analysis.chain import our_chain
from analysis.fit import default_band_hz
from analysis.frf import KERNEL_HALF_WIDTH_BINS, min_duration_s

# relative allowance on the band's top: a limit typed back as printed (6 significant digits, :g) is at most 5e-6
# above the exact one (0.4/0.0015 s = 266.6666… Hz printed 266.667); not a tolerance of the analysis
_TYPED_LIMIT_REL = 1e-5


def encoder_period_problem(period_s: float) -> str | None:
    """Why an encoder sampled every ``period_s`` (s) leaves no fit band, or None when it does."""
    low, high = default_band_hz(period_s)
    if high > low:
        return None
    return (f"the encoder then samples at {1.0 / period_s:g} Hz, too slow for the fit band (from {low:g} Hz to "
            f"0.4 × its rate = {high:g} Hz): it must be below {0.4 / low:g} s")


def band_problem(band_hz: tuple[float, float], period_s: float, segment_s: float) -> str | None:
    """Why a fit band asked for cannot be judged on a recording whose encoder samples every ``period_s`` (s) with
    Welch segments of ``segment_s`` (s), or None when it can. One line, naming the band and the limit it crosses.

    * Its top must not lie above the anti-alias filter's pass edge, 0.4 × the encoder rate (:mod:`analysis.antialias`),
      where the default band ends: above it the filter's transition attenuates the torque (to half at the encoder's
      Nyquist frequency) and the encoder's sampling folds what is left, so the measured FRF there is the chain's, not
      the joint's; a two-mass fit reads it as a misfit (a 500 Hz encoder with a band to 250 Hz: "misses by −101 % at
      226…240 Hz … a third mode").
    * Its bottom must lie above ``KERNEL_HALF_WIDTH_BINS`` bins: the fit models each FRF bin as the joint's response
      averaged over that many bins either side (:func:`analysis.frf.window_kernel`), and a bin whose average
      reaches 0 Hz, where the rigid body's response is infinite, leaves the fit no finite cost.
    """
    low, high = band_hz
    if not low < high:  # also NaN
        return f"fit band {low:g}…{high:g} Hz is empty"
    floor_hz = KERNEL_HALF_WIDTH_BINS / segment_s
    if not low > floor_hz:
        return (f"fit band {low:g}…{high:g} Hz starts at or below {floor_hz:g} Hz: with {segment_s:g} s Welch "
                f"segments the fit takes each FRF bin as the joint averaged over ±{floor_hz:g} Hz, which must stay "
                f"above 0 Hz; start the band above {floor_hz:g} Hz")
    top_hz = PASS_FRACTION / period_s
    if high > top_hz * (1.0 + _TYPED_LIMIT_REL):
        return (f"fit band {low:g}…{high:g} Hz ends above {top_hz:g} Hz, the highest frequency the analysis can "
                f"judge with this recording's {1.0 / period_s:g} Hz encoder ({PASS_FRACTION:g} × its rate, the "
                f"anti-alias filter's pass edge: above it the filter and the encoder's sampling, not the joint, shape "
                f"the FRF); end the band at {top_hz:g} Hz or below")
    return None


def min_current_rate_hz(period_s: float) -> float:
    """The lowest DAQ rate, Hz, whose Nyquist frequency lies above the chain's anti-alias stop edge for an
    encoder sampled every ``period_s`` (s)."""
    return 2.0 * STOP_FRACTION / period_s



def min_record_s(rate_hz: float, period_s: float, segment_s: float, start_offset_s: float) -> float:
    """Shortest recording, s of each stream, that leaves two Welch segments of ``segment_s`` after what the analysis
    trims (:func:`analysis.stream_spans.spans_and_clock`): the current outside the encoder's span (the streams' start
    offset ``start_offset_s``, s), the anti-alias filter's transient at both ends of the current (our chain's
    :meth:`~analysis.chain.SignalChain.edge_s` for a DAQ at ``rate_hz`` and an encoder every ``period_s``), and two
    encoder samples (the speed's difference and the rounding of the span onto the encoder's instants)."""
    edge_s = our_chain().edge_s(rate_hz, PASS_FRACTION / period_s, STOP_FRACTION / period_s)
    return min_duration_s(segment_s) + abs(start_offset_s) + 2.0 * edge_s + 2.0 * period_s
