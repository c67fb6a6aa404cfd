"""The signal chain: a raw recording → torque and speed on the encoder's own instants (design §4, §5.1–5.3).

:func:`prepare_signals` runs it in two stages. :func:`analysis.stream_spans.spans_and_clock`: gap-free spans, clock
fit, speed on k·T. :func:`torque_on_instants`: torque by the chosen method at the DAQ samples
(:mod:`analysis.torque`, :mod:`analysis.torque_park`, :mod:`analysis.torque_hilbert`), moved to the encoder instants
after a zero-phase anti-alias filter (:mod:`analysis.resample`, :mod:`analysis.antialias`); long records are
processed in chunks of ~20 s with overlapping margins, so memory stays a few times one chunk whatever the length.

The :class:`analysis.chain.SignalChain` given decides the differences between our chain and the
paper's (:data:`analysis.chain.PAPER_CHAIN`: Hilbert torque, no alignment — both streams taken as
started together, no drift — and linear interpolation onto the common 1/T grid).
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, field, replace

import numpy as np

from analysis import resample, torque
from analysis.antialias import ALIAS_ORDERS, alias_terms, band_edges_hz
from analysis.chain import SignalChain, TorqueMethod
from analysis.clock_model import ClockFit
from analysis.recording import Recording
from analysis.fit import Z95
from analysis.phase_offset import PhaseOffset, phase_offset
from analysis.sample_instants import EncoderJitter
from analysis.stream_spans import Spans, spans_and_clock
from analysis.torque_hilbert import apex_sign, torque_hilbert
from analysis.torque_park import PhaseGains, phase_gains, torque_park

_CHUNK_S = 20.0
_MARGIN_S = 0.1
# lines removed from the current are listed in the notes from this amplitude on (smaller ones, often
# the motion's own residual content at a line's frequency, are removed too but not worth a word)
_NOTE_MIN_LINE_A = 1e-3


@dataclass(frozen=True)
class PreparedSignals:
    """Torque and speed at the same instants, ready for the FRF.

    Attributes
    ----------
    t_s : ndarray
        Drive time of each sample, s: k·period_s over the longest gap-free encoder span covered by the current.
    torque_Nm : ndarray
        Electromagnetic torque at ``t_s``, N·m.
    speed_rad_s : ndarray
        Motor speed at ``t_s``, rad/s (backward difference: divide
        :func:`analysis.encoder.difference_response` out of the FRF).
    period_s : float
        Drive cycle, s.
    clock : ClockFit
        The DAQ → drive clock relation used.
    torque_method : {"hilbert", "encoder", "park"}
        How the torque was computed.
    aligned : bool
        False for the paper's chain (no clock alignment).
    theta0_rad : float
        Electrical offset θ_0 used to demodulate, rad, sign chosen (NaN for hilbert).
    notes : list of str
        What a person should know (gaps, spans used, sign choices).
    torque_noise_Nm : ndarray or None
        What the torque estimator makes of white current noise of the fit's residual RMS, at ``t_s``,
        N·m (encoder method only): its spectrum is the torque estimate's noise spectrum.
    torque_alias_Nm : ndarray of complex or None
        Shape (``ALIAS_ORDERS``, n): the torque shifted down by k·f_enc (k = 1, 2), anti-aliased and
        read at ``t_s``, N·m. The encoder samples the position without an anti-alias filter, so the
        plant's response to the torque near k·f_enc ± f folds onto f; these carry that torque
        (:func:`analysis.frf.estimate_frf` turns them into the fold-over terms the fit models).
    encoder_jitter : EncoderJitter or None
        The encoder's sample-instant jitter left in ``speed_rad_s`` (after the drive's time stamps, if
        any), estimated from the data (:mod:`analysis.sample_instants`).
    interference : tuple of Interference
        What the encoder method removed from the current besides the torque, one per chunk of the
        record (:func:`analysis.torque.torque_encoder`); empty for the other methods.
    torque_std_Nm : ndarray or None
        Standard error of the one-phase torque at ``t_s`` from the information the phase carries about it near each
        instant, N·m (:func:`analysis.torque.angle_information_std` at the anti-alias filter's time resolution;
        encoder method only): large where the motor holds torque at an angle at which the phase shows little of it.
    """

    t_s: np.ndarray
    torque_Nm: np.ndarray
    speed_rad_s: np.ndarray
    period_s: float
    clock: ClockFit
    torque_method: TorqueMethod
    aligned: bool
    theta0_rad: float = np.nan
    notes: list[str] = field(default_factory=list)
    torque_noise_Nm: np.ndarray | None = None
    torque_alias_Nm: np.ndarray | None = None
    encoder_jitter: EncoderJitter | None = None
    interference: tuple[torque.Interference, ...] = ()
    torque_std_Nm: np.ndarray | None = None

def prepare_signals(rec: Recording, chain: SignalChain = SignalChain(), torque_std: bool = False) -> PreparedSignals:
    """Torque and speed on the encoder instants from a raw recording: :func:`spans_and_clock`, then
    :func:`torque_on_instants` (``torque_std``: with the torque's standard error, ``torque_std_Nm``).

    Parameters
    ----------
    rec : Recording
        The raw session.
    chain : SignalChain, optional
        Torque estimator, clock alignment and resampling: :func:`analysis.chain.our_chain` (default, encoder
        torque) or :data:`analysis.chain.PAPER_CHAIN`.

    Raises
    ------
    ValueError
        Bad or too short input, or no overlap between the current and the encoder records.
    """
    return torque_on_instants(rec, spans_and_clock(rec, chain), chain, torque_std)

def torque_on_instants(rec: Recording, spans: Spans, chain: SignalChain = SignalChain(),
                       torque_std: bool = False) -> PreparedSignals:
    """Torque by ``chain.torque_method`` at the DAQ samples, moved onto the encoder instants of ``spans`` by
    ``chain``'s resampling, in chunks of ~20 s with overlapping margins; its sign fixed by the acceleration
    (demodulating methods) or by the speed's apexes (hilbert). ``torque_std``: also the one-phase estimate's standard
    error (``torque_std_Nm``; encoder method with anti-alias resampling only) — 0.02 s of CPU for a 60 s session, so
    only where it is used."""
    t_s, speed, t_daq, current, n0, clock = (spans.t_s, spans.speed_rad_s, spans.t_daq_s, spans.current_a,
                                             spans.n0, spans.clock)
    f_pass, f_stop = band_edges_hz(rec)
    antialias = chain.resampling == "antialias"
    sign = apex_sign(speed, rec.period_s) if chain.torque_method == "hilbert" else None
    out = np.empty(t_s.size)
    noise = np.empty(t_s.size) if chain.torque_method == "encoder" and antialias else None
    alias = np.empty((ALIAS_ORDERS, t_s.size), complex) if sign is None and antialias else None
    std = np.empty(t_s.size) if noise is not None and torque_std else None
    theta0 = np.nan if sign is not None else clock.theta0_rad  # NaN: the first chunk estimates it
    found: list[torque.Interference] = []
    gains: list[PhaseGains] = []
    for a, b, m0, m1 in _chunks(current["i_a"].size, rec.rate_hz):
        t0 = (n0 + a - m0) / rec.rate_hz
        sel = (t_daq >= (n0 + a) / rec.rate_hz) & (t_daq < (n0 + b) / rec.rate_hz)
        if not sel.any():
            continue
        piece = {name: c[a - m0:b + m1] for name, c in current.items()}
        t_piece = t0 + np.arange(b + m1 - a + m0) / rec.rate_hz
        if sign is None:
            t_drive = clock.drive_time_s(t_piece)
            theta_m = spans.angle(t_drive)
            tq, theta0 = _demodulated(piece, rec, theta_m, chain.torque_method, theta0,
                                      noise_seed=a if noise is not None else None, found=found, gains_found=gains)
            if std is not None:  # the estimate's own standard error where the angle leaves the phase little of it
                std[sel] = np.interp(t_daq[sel], t_piece, torque.angle_information_std(
                    rec.pole_pairs * theta_m, theta0, rec.rate_hz, rec.k_t_Nm_per_A, found[-1].noise_rms_a,
                    0.5 / f_pass))
            if alias is not None:  # anti-alias resampling: the torque and its noise realisation moved in one filter
                tq = np.atleast_2d(tq)  # call and one spline; the alias terms from the torque alone (alias_terms)
                moved = resample.to_instants(tq, rec.rate_hz, t0, t_daq[sel], f_pass, f_stop)
                out[sel] = moved[0]
                if noise is not None:
                    noise[sel] = moved[1]
                step_s = (1.0 + clock.drift_ppm * 1e-6) / rec.rate_hz  # drive time per DAQ sample
                alias[:, sel] = alias_terms(tq[0], rec.rate_hz, t0, t_drive[0], step_s, t_daq[sel], rec.period_s,
                                            f_pass, f_stop)
                continue
        else:
            k = np.clip(np.searchsorted(t_daq, t_piece), 0, t_daq.size - 1)
            tq = torque_hilbert(piece["i_a"], rec.k_t_Nm_per_A, sign[k])
        out[sel] = chain.to_instants(tq, rec.rate_hz, t0, t_daq[sel], f_pass, f_stop)
    notes = [*spans.notes, *_interference_notes(found), *_gain_notes(gains)]
    prepared = PreparedSignals(t_s, out, speed, rec.period_s, clock, chain.torque_method, chain.align, theta0, notes,
                               noise, alias, spans.encoder_jitter, tuple(found), std)
    return _signed(prepared) if sign is None else prepared

def _chunks(n: int, rate_hz: float) -> Iterator[tuple[int, int, int, int]]:
    """(start, stop, left margin, right margin) in samples, covering 0…n in ~20 s pieces."""
    size, margin = int(_CHUNK_S * rate_hz), int(_MARGIN_S * rate_hz)
    for a in range(0, n, size):
        b = min(n, a + size)
        yield a, b, min(margin, a), min(margin, n - b)


#: What a slow offset of one phase's current can be: while the motor stands still the torque it holds is a constant
#: current too (i_q·sin θ_e with θ_e fixed), so an idle robot window reads amperes of "offset" that is torque.
_OFFSET_CAUSES = "a drifting sensor offset, or torque held while the motor stood still: one phase cannot tell them apart"


def _interference_notes(found: list[torque.Interference]) -> list[str]:
    """One note on the lines and the offset drift removed from the current (strongest chunk's values)."""
    lines: dict[float, float] = {}
    for f in found:
        for hz, amp in zip(f.lines_hz, f.amplitude_a):
            if amp >= _NOTE_MIN_LINE_A:
                key = round(hz, 1)
                lines[key] = max(lines.get(key, 0.0), amp)
    drift = max((f.offset_drift_a for f in found), default=0.0)
    if not lines:
        return [f"current: slow offset removed, moving by {1e3 * drift:.0f} mA ({_OFFSET_CAUSES})"] if drift >= 5e-3 else []
    text = ", ".join(f"{hz:.1f} Hz ({1e3 * a:.0f} mA)" for hz, a in sorted(lines.items()))
    return [f"current: removed interference lines at {text}; slow offset moving by {1e3 * drift:.0f} mA "
            f"({_OFFSET_CAUSES})"]


def _gain_notes(found: list[PhaseGains]) -> list[str]:
    """One note on the phases' relative sensor gains (divided out) when one differs from 1 beyond its 95 %
    interval (in the longest chunk)."""
    if not found:
        return []
    g = max(found, key=lambda x: x.n_samples)
    if all(abs(v - 1.0) <= Z95 * g.sigma[n] for n, v in g.gain.items()):
        return []
    text = ", ".join(f"{n} {v:.4f} ± {Z95 * g.sigma[n]:.1g}" for n, v in g.gain.items())
    return [f"current: phase sensor gains differ (relative to their mean: {text}); divided out"]


def _demodulated(piece: dict[str, np.ndarray], rec: Recording, theta_m_rad: np.ndarray, method: TorqueMethod,
                 theta0: float, noise_seed: int | None = None,
                 found: list[torque.Interference] | None = None,
                 gains_found: list[PhaseGains] | None = None) -> tuple[np.ndarray, float]:
    """Torque of one chunk by the encoder or park method, and the θ_0 used (mod π; estimated if NaN).

    The park method divides three phases by their relative sensor gains, estimated from the chunk itself
    (appended to ``gains_found``).

    With ``noise_seed`` (encoder method) the torque comes with a noise realisation, shape (2, n).
    """
    theta_e = rec.pole_pairs * theta_m_rad
    if method == "encoder":
        if np.isnan(theta0):
            theta0 = phase_offset(piece["i_a"], theta_e, rec.rate_hz, pole_pairs=rec.pole_pairs,
                                  commanded=rec.profile is not None).theta0_rad
        # the sensor DC is estimated jointly by the spline fit, θ_0 refined there
        return torque.torque_encoder(piece["i_a"], theta_e, rec.rate_hz, rec.k_t_Nm_per_A,
                                     PhaseOffset(theta0, 0.0, 0), noise_seed=noise_seed, found=found), theta0
    offsets = {name: phase_offset(c, theta_e, rec.rate_hz, pole_pairs=rec.pole_pairs,
                                  commanded=rec.profile is not None)
               for name, c in piece.items()}
    theta0 = offsets["i_a"].theta0_rad if np.isnan(theta0) else theta0
    gains = phase_gains(piece)
    if gains is not None and gains_found is not None:
        gains_found.append(gains)
    return torque_park(piece, theta_e, rec.k_t_Nm_per_A, theta0, {n: o.dc_a for n, o in offsets.items()},
                       None if gains is None else gains.gain), theta0


def _signed(p: PreparedSignals) -> PreparedSignals:
    """Fix the one bit θ_0 (mod π) leaves open: T_e must correlate positively with the acceleration.

    The speed only decides this global sign, never the torque's shape.
    """
    accel = np.gradient(p.speed_rad_s, p.period_s)
    if np.dot(p.torque_Nm - p.torque_Nm.mean(), accel) >= 0:
        return p
    theta0 = float(np.angle(np.exp(1j * (p.theta0_rad + np.pi))))
    return replace(p, torque_Nm=-p.torque_Nm, theta0_rad=theta0,
                   torque_alias_Nm=None if p.torque_alias_Nm is None else -p.torque_alias_Nm,
                   notes=[*p.notes, f"torque sign from its correlation with the acceleration (θ_0 = {theta0:.3f} rad)"])
