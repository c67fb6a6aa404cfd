"""The signal chain as an explicit strategy: ours, or the paper's (Xu et al.), chosen by the request.

A :class:`SignalChain` says everything in which the two chains differ — the torque estimator, whether
the clocks are aligned from the data, how the torque is moved onto the encoder instants, how the fit
weights the FRF — so :func:`analysis.signals.prepare_signals` and :func:`analysis.pipeline.analyze` read
it instead of carrying the paper's chain through flags of their own.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np

from analysis import resample
from analysis.fit import FitWeighting

TorqueMethod = Literal["hilbert", "encoder", "park"]
Resampling = Literal["antialias", "linear"]
Pipeline = Literal["acq", "paper"]


@dataclass(frozen=True)
class SignalChain:
    """How a raw recording becomes torque and speed on the encoder instants, and how the fit weights them.

    Attributes
    ----------
    torque_method : {"encoder", "hilbert", "park"}
        Torque estimator (:mod:`analysis.torque`, :mod:`analysis.torque_park`, :mod:`analysis.torque_hilbert`); ``park``
        needs ``i_a`` and ``i_b``.
    align : bool
        Fit the clock relation from the data (True) or take both streams as started together, no drift (False).
    resampling : {"antialias", "linear"}
        Zero-phase anti-alias filter then spline read (ours) or plain linear interpolation (the paper's).
    weighting : {"coherence", "uniform"}
        Weights of the FRF fit (:class:`analysis.fit.FitOptions`).
    pipeline : {"acq", "paper"}
        Which chain this is.
    """

    torque_method: TorqueMethod = "encoder"
    align: bool = True
    resampling: Resampling = "antialias"
    weighting: FitWeighting = "coherence"
    pipeline: Pipeline = "acq"

    def edge_s(self, rate_hz: float, f_pass_hz: float, f_stop_hz: float) -> float:
        """Time at each end of a current record where the resampling cannot read the torque, s."""
        if self.resampling == "antialias":
            return resample.edge_s(rate_hz, f_pass_hz, f_stop_hz) + 0.01
        return 1.0 / rate_hz

    def to_instants(self, x: np.ndarray, rate_hz: float, t0_s: float, t_s: np.ndarray, f_pass_hz: float,
                    f_stop_hz: float) -> np.ndarray:
        """``x`` (sampled at ``rate_hz`` from ``t0_s``, DAQ time) read at the DAQ times ``t_s``."""
        if self.resampling == "antialias":
            return resample.to_instants(x, rate_hz, t0_s, t_s, f_pass_hz, f_stop_hz)
        return resample.linear_at(x, rate_hz, t0_s, t_s)


def our_chain(torque_method: TorqueMethod = "encoder", align: bool = True) -> SignalChain:
    """Our chain: clock alignment (unless ``align`` is False), the chosen torque estimator, anti-alias
    resampling, coherence-weighted fit."""
    return SignalChain(torque_method, align, "antialias", "coherence", "acq")


#: The paper's chain, kept for comparison: Hilbert torque, no clock alignment, linear interpolation onto the
#: encoder's grid (the speed keeps its samples, only the torque is interpolated), uniform weights.
PAPER_CHAIN = SignalChain("hilbert", False, "linear", "uniform", "paper")


def chain_caveat(chain: SignalChain, default: SignalChain) -> str | None:
    """The first reason of a verdict that is not ok when ``chain`` is not acq's ``default`` for the recording (None if
    it is): the findings that follow (weak excitation, misfit, encoder noise) may be that chain's own errors — the
    Hilbert envelope's ripple, an unaligned clock — and their advice would send the technician after the joint."""
    if chain == default:
        return None
    if chain.pipeline == "paper":
        return ("these findings are of the paper's chain (Hilbert torque, no clock alignment, linear interpolation, "
                "uniform weights) and may be its own errors: acq analyze without --paper judges the session with "
                "acq's chain")
    what = [f"--torque {chain.torque_method}"] if chain.torque_method != default.torque_method else []
    what += [] if chain.align == default.align else ["no clock alignment"]
    return (f"these findings are of the chain chosen ({', '.join(what)}) and may be its own errors: acq analyze "
            f"without it judges the session with acq's default ({default.torque_method} torque)")
