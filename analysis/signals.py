"""The signal chain: a raw recording → torque and speed on the encoder's own instants (design §4, §5.1–5.3).

:func:`prepare_signals` runs it in two stages. :func:`spans_and_clock`: gap-free spans, clock fit
(:mod:`analysis.clocks`), speed by backward difference on k·T (:mod:`analysis.encoder`).
:func:`torque_on_instants`: torque by the chosen method at the DAQ samples (:mod:`analysis.torque`,
:mod:`analysis.torque_park`, :mod:`analysis.torque_hilbert`), moved to the encoder instants after a zero-phase
anti-alias filter (:mod:`analysis.resample`); long records are processed in chunks of ~20 s with overlapping
margins, so memory stays a few times one chunk whatever the length.

The :class:`analysis.chain.SignalChain` given decides the differences between our chain and the
paper's (:data:`analysis.chain.PAPER_CHAIN`: Hilbert torque, no alignment — both streams taken as
started together, no drift — and linear interpolation onto the common 1/T grid).
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass, field, replace

import numpy as np

from analysis import encoder, resample, sample_instants, torque
from analysis.chain import SignalChain, TorqueMethod
from analysis.clocks import ClockFit, fit_clock, host_relation
from analysis.recording import CommandedProfile, Recording
from analysis.fit import Z95
from analysis.phase_offset import PhaseOffset, phase_offset
from analysis.quantisation_lock import NOTED_LOCKED_SHARE, locked_share
from analysis.sample_instants import EncoderJitter
from analysis.torque_hilbert import apex_sign, torque_hilbert
from analysis.torque_park import PhaseGains, phase_gains, torque_park

_CHUNK_S = 20.0
_MARGIN_S = 0.1
_PASS_FRACTION = 0.4  # anti-alias pass edge, × encoder rate
_STOP_FRACTION = 0.6  # anti-alias stop edge, × encoder rate
ALIAS_ORDERS = 2  # torque near k·f_enc, k = 1 … ALIAS_ORDERS, folded by the encoder's sampling
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


@dataclass(frozen=True)
class Spans:
    """Stage one of the chain: the gap-free spans of both streams, the clock relating them, the speed.

    Attributes
    ----------
    t_s : ndarray
        Drive time of each encoder instant used, s (k·period_s, where both streams have data).
    t_daq_s : ndarray
        The same instants on the DAQ clock, s.
    speed_rad_s : ndarray
        Motor speed at ``t_s``, rad/s (backward difference).
    current_a : dict of str → ndarray
        The phase currents of the longest gap-free DAQ run within the encoder span, A.
    n0 : int
        DAQ sample index of the first sample of ``current_a``.
    angle : callable
        Motor angle, rad, at a drive time, s (spline through the span's samples).
    clock : ClockFit
        The DAQ → drive clock relation.
    encoder_jitter : EncoderJitter
        The encoder's sample-instant jitter left in the speed.
    notes : list of str
        What a person should know (gaps, spans used, clock stage).
    """

    t_s: np.ndarray
    t_daq_s: np.ndarray
    speed_rad_s: np.ndarray
    current_a: dict[str, np.ndarray]
    n0: int
    angle: Callable[[np.ndarray], np.ndarray]
    clock: ClockFit
    encoder_jitter: EncoderJitter
    notes: list[str]


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


def spans_and_clock(rec: Recording, chain: SignalChain = SignalChain()) -> Spans:
    """The longest gap-free spans of both streams, the clock relating them (fitted from the data when
    ``chain.align``, else both streams taken as started together), and the speed on the encoder instants
    where the current covers them (away from the ends by what ``chain``'s resampling needs).

    Raises
    ------
    ValueError
        Bad or too short input, or no overlap between the current and the encoder records.
    """
    _validate(rec, chain.torque_method)
    notes: list[str] = []
    span = encoder.longest_gap_free_span(rec.encoder_index)
    cycles = rec.encoder_index[span.start:span.stop]
    if span.gaps:
        notes.append(f"encoder: {len(span.gaps)} gap(s), first after cycle {span.gaps[0][0]}: using the longest "
                     f"gap-free span {cycles[0] * rec.period_s:.3f}–{cycles[-1] * rec.period_s:.3f} s")
    if cycles.size < 8:
        raise ValueError(f"only {cycles.size} gap-free encoder samples")
    n0, lo, hi, daq_note = _daq_run(rec)
    if daq_note:
        notes.append(daq_note)
    current = {name: a[lo:hi] for name, a in rec.current_a.items()}
    theta, jitter = _angle_on_grid(rec, span, notes)
    jitter = replace(jitter, locked_share=locked_share(rec.position_counts[span.start:span.stop]))
    if jitter.locked_share >= NOTED_LOCKED_SHARE:
        notes.append(_repeating_quantisation_note(jitter.locked_share, rec.profile))
    angle = encoder.angle_spline(int(cycles[0]), rec.period_s, theta)
    if chain.align:
        clock = fit_clock(current["i_a"], rec.rate_hz, n0, angle, rec.pole_pairs, _host(rec))
        if not rec.host_clock_shared:
            notes.append("clock: the streams' time stamps are not on one host clock; aligned from the data alone")
        notes.extend(clock.notes)
        if clock.method != "angle" and not clock.failure:  # a failure is the verdict's reason, not a note
            notes.append(f"clock: the angle stage failed (too little motion); using the {clock.method} stage")
    else:
        clock = ClockFit(float(cycles[0]) * rec.period_s - n0 / rec.rate_hz, 0.0)
        notes.append("clock: not aligned (streams taken as started together, no drift)")
    # only the current within the encoder span: outside it the angle spline extrapolates (bad θ_0, DC, i_q)
    enc_daq = clock.daq_time_s(cycles[[0, -1]] * rec.period_s) * rec.rate_hz - n0
    first = int(np.clip(np.ceil(enc_daq[0]), 0, hi - lo))
    last = int(np.clip(np.floor(enc_daq[1]) + 1, first, hi - lo))
    current = {name: c[first:last] for name, c in current.items()}
    n0, lo, hi = n0 + first, lo + first, lo + last

    speed = encoder.speed_from_angle(theta, rec.period_s)
    t_s = cycles[1:] * rec.period_s
    f_pass, f_stop = _band_edges_hz(rec)
    t_daq = clock.daq_time_s(t_s)
    edge = chain.edge_s(rec.rate_hz, f_pass, f_stop)
    inside = (t_daq >= n0 / rec.rate_hz + edge) & (t_daq <= (n0 + hi - lo - 1) / rec.rate_hz - edge)
    if inside.sum() < 8:
        raise ValueError("the current and encoder records do not overlap in time")
    if not inside.all():
        notes.append(f"using {t_s[inside][0]:.3f}–{t_s[inside][-1]:.3f} s, where both streams have data")
    return Spans(t_s[inside], t_daq[inside], speed[inside], current, n0, angle, clock, jitter, notes)


def torque_on_instants(rec: Recording, spans: Spans, chain: SignalChain = SignalChain(),
                       torque_std: bool = False) -> PreparedSignals:
    """Torque by ``chain.torque_method`` at the DAQ samples, moved onto the encoder instants of ``spans`` by
    ``chain``'s resampling, in chunks of ~20 s with overlapping margins; its sign fixed by the acceleration
    (demodulating methods) or by the speed's apexes (hilbert). ``torque_std``: also the one-phase estimate's standard
    error (``torque_std_Nm``; encoder method with anti-alias resampling only) — 0.02 s of CPU for a 60 s session, so
    only where it is used."""
    t_s, speed, t_daq, current, n0, clock = (spans.t_s, spans.speed_rad_s, spans.t_daq_s, spans.current_a,
                                             spans.n0, spans.clock)
    f_pass, f_stop = _band_edges_hz(rec)
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
                tq = np.atleast_2d(tq)  # call and one spline; the alias terms from the torque alone (_alias_terms)
                moved = resample.to_instants(tq, rec.rate_hz, t0, t_daq[sel], f_pass, f_stop)
                out[sel] = moved[0]
                if noise is not None:
                    noise[sel] = moved[1]
                step_s = (1.0 + clock.drift_ppm * 1e-6) / rec.rate_hz  # drive time per DAQ sample
                alias[:, sel] = _alias_terms(tq[0], rec.rate_hz, t0, t_drive[0], step_s, t_daq[sel], rec.period_s,
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


def _alias_terms(torque_Nm: np.ndarray, rate_hz: float, t0_s: float, t_drive0_s: float, step_s: float,
                 t_s: np.ndarray, period_s: float, f_pass_hz: float, f_stop_hz: float) -> np.ndarray:
    """The torque shifted down by k/T (k = 1 … ``ALIAS_ORDERS``), anti-aliased and read at the DAQ times ``t_s``, N·m,
    shape (``ALIAS_ORDERS``, len(t_s)), complex.

    What ends up below ``f_stop_hz`` after the shift is the torque's content up to ``ALIAS_ORDERS``/T + ``f_stop_hz``,
    so the torque is first decimated to the lowest rate that keeps that band (:func:`resample.decimate_keeping`:
    6.4 kS/s from 25.6 kS/s with a 1 kHz encoder), and the shifted rows are filtered at that rate: one row through
    the DAQ-rate filter instead of 2·``ALIAS_ORDERS``.

    Parameters
    ----------
    torque_Nm : ndarray
        Torque at the DAQ samples ``t0_s + i/rate_hz`` (DAQ time), N·m.
    t_drive0_s, step_s : float
        Drive time of the first sample and drive time per DAQ sample, s (the clock relation).
    """
    low, rate = resample.decimate_keeping(torque_Nm, rate_hz, ALIAS_ORDERS / period_s + f_stop_hz)
    turn = _turn(t_drive0_s, step_s * rate_hz / rate, low.size, period_s)
    rows = np.empty((2 * ALIAS_ORDERS, low.size))
    z = low * turn
    for order in range(ALIAS_ORDERS):
        rows[2 * order], rows[2 * order + 1] = z.real, z.imag
        z *= turn
    moved = resample.to_instants(rows, rate, t0_s, t_s, f_pass_hz, f_stop_hz)
    return moved[0::2] + 1j * moved[1::2]


def _turn(t_first_s: float, step_s: float, n: int, period_s: float) -> np.ndarray:
    """e^{−2πj·t/T} at the n uniform instants t = ``t_first_s`` + k·``step_s`` (drive clock, s), T = ``period_s``.

    The phase is linear in k = a·L + b, so the values are the outer product of a coarse table (k = a·L) and a fine
    one (k = b): one complex product per sample instead of one complex exponential (30× faster; the phases, taken
    modulo one turn, agree with the direct evaluation to 1e-10 rad).
    """
    span = 1024
    coarse = np.exp(-2j * np.pi * (((t_first_s + np.arange(-(-n // span)) * (span * step_s)) / period_s) % 1.0))
    fine = np.exp(-2j * np.pi * ((np.arange(span) * (step_s / period_s)) % 1.0))
    return (coarse[:, None] * fine).ravel()[:n]


def _band_edges_hz(rec: Recording) -> tuple[float, float]:
    """Pass and stop edges of the anti-alias filter, Hz."""
    return _PASS_FRACTION / rec.period_s, _STOP_FRACTION / rec.period_s


def _validate(rec: Recording, torque_method: TorqueMethod) -> None:
    if "i_a" not in rec.current_a:
        raise ValueError(f"the recording has no phase i_a (phases: {sorted(rec.current_a)})")
    if torque_method == "park" and "i_b" not in rec.current_a:
        raise ValueError("torque method 'park' needs two or three phases; only i_a was recorded")
    if torque_method not in ("hilbert", "encoder", "park"):
        raise ValueError(f"unknown torque method {torque_method!r}: use hilbert, encoder or park")
    n = rec.current_a["i_a"].size
    if any(a.size != n for a in rec.current_a.values()):
        raise ValueError("all phases must have the same number of samples")
    if rec.rate_hz <= 0 or rec.period_s <= 0:
        raise ValueError(f"rate_hz and period_s must be positive, got {rec.rate_hz}, {rec.period_s}")
    if rec.encoder_index.size != rec.position_counts.size:
        raise ValueError("encoder_index and position_counts differ in length")
    if rec.drive_time_s is not None and rec.drive_time_s.size != rec.encoder_index.size:
        raise ValueError("drive_time_s and encoder_index differ in length")


def _repeating_quantisation_note(share: float, profile: CommandedProfile | None) -> str:
    """The note for a record whose quantisation error mostly repeats with the motion (``share`` of it), with what
    to change: the profile's speed_dither, or — for a machine's own motion — nothing acq can set."""
    if profile is None:
        remedy = ("the machine repeats its motion that exactly; a recording of motions that vary from cycle to cycle "
                  "averages it out")
    elif profile.speed_dither:
        remedy = (f"though the profile dithers (speed_dither = {profile.speed_dither:g}), the motion did not vary: "
                  "check that the drive runs the dithered profile")
    else:
        remedy = "set speed_dither (e.g. 0.02, as the shipped triangle_0.2s) in the profile so that it averages out"
    return (f"encoder: {100 * share:.0f} % of its quantisation error repeats with every motion period (the "
            "trajectory repeats to a fraction of a count), so no average removes it and the check for a mode the "
            "two-mass model lacks must allow for it: a mode of a few percent can hide behind it at high frequencies "
            f"— {remedy}")


def _angle_on_grid(rec: Recording, span: encoder.Span, notes: list[str]) -> tuple[np.ndarray, EncoderJitter]:
    """The span's motor angle at k·T, rad — moved there with the drive's time stamps when they are
    usable and leave less position noise than the samples taken as k·T — and the jitter left in it."""
    cycles = rec.encoder_index[span.start:span.stop]
    theta = encoder.counts_to_rad(rec.position_counts[span.start:span.stop], rec.counts_per_rev)
    lsb_rad = 2.0 * np.pi / rec.counts_per_rev
    on_grid = sample_instants.estimate_jitter(theta, rec.period_s, lsb_rad=lsb_rad)
    if rec.drive_time_s is None:
        return theta, on_grid
    deviation = sample_instants.stamp_deviation_s(cycles, rec.drive_time_s[span.start:span.stop], rec.period_s)
    if deviation is None:
        notes.append("encoder: the drive's time stamps are not a scatter around its cycle grid (missing, "
                     "or off by half a cycle or more); sample instants taken as k·T")
        return theta, on_grid
    spread = float(np.sqrt(np.mean(deviation**2)))
    if spread <= 1e-9:
        # exactly k·T: nothing to move — a cycle count, or a drive that latches on its grid (the simulated one); the
        # result's encoder_time_stamps says false, and a note on every such session would say nothing more
        return theta, on_grid
    moved = sample_instants.angle_at_nominal_instants(theta, cycles, rec.period_s, deviation)
    jitter = sample_instants.estimate_jitter(moved, rec.period_s, lsb_rad=lsb_rad, stamped=True,
                                            stamp_spread_s=spread)
    if not jitter.sigma_s <= on_grid.sigma_s:  # coarse or false stamps: they would add the noise they should remove
        notes.append(f"encoder: the drive's time stamps (RMS {1e6 * spread:.1f} µs off the cycle grid) leave more "
                     f"position noise ({1e6 * jitter.sigma_s:.1f} µs) than k·T ({1e6 * on_grid.sigma_s:.1f} µs); "
                     "sample instants taken as k·T")
        return theta, on_grid
    notes.append(f"encoder: sampled at the drive's own time stamps (RMS {1e6 * spread:.1f} µs off the "
                 "cycle grid), moved to k·T")
    return moved, jitter


def _daq_run(rec: Recording) -> tuple[int, int, int, str]:
    """Longest gap-free run of DAQ blocks: (sample index of its first sample, array start, stop, note)."""
    n = rec.current_a["i_a"].size
    if rec.block_first_index is None or rec.block_count is None or rec.block_first_index.size == 0:
        return 0, 0, n, ""
    first = np.asarray(rec.block_first_index, dtype=np.int64)
    count = np.asarray(rec.block_count, dtype=np.int64)
    starts = np.concatenate(([0], np.cumsum(count)[:-1]))
    breaks = np.flatnonzero(first[1:] != first[:-1] + count[:-1]) + 1
    if breaks.size == 0:
        return int(first[0]), 0, n, ""
    edges = np.concatenate(([0], breaks, [first.size]))
    sizes = [int(count[a:b].sum()) for a, b in zip(edges[:-1], edges[1:])]
    best = int(np.argmax(sizes))
    a = int(edges[best])
    note = (f"current: {breaks.size} gap(s) in the DAQ sample count; using the longest gap-free run, "
            f"samples {first[a]}–{first[a] + sizes[best] - 1}")
    return int(first[a]), int(starts[a]), int(starts[a]) + sizes[best], note


def _host(rec: Recording) -> tuple[float, float] | None:
    if not rec.host_clock_shared:
        return None  # stamps of separate tools: their time columns relate nothing
    if rec.block_host_ns is None or rec.encoder_host_ns is None or rec.block_first_index is None:
        return None
    last = np.asarray(rec.block_first_index) + np.asarray(rec.block_count) - 1
    return host_relation(last, rec.block_host_ns, rec.rate_hz, rec.encoder_index, rec.encoder_host_ns, rec.period_s)


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
