"""Stage one of the signal chain: the gap-free spans of both streams, the clock relating them, and the speed on the
encoder's instants (design §4, §5.1).

The gap-free runs of the encoder and of the DAQ in which both streams have data the longest
(:mod:`analysis.shared_runs`), the motor angle at k·T (moved there with the drive's time
stamps when they help, :mod:`analysis.sample_instants`), the clock fit (:mod:`analysis.clocks`) and the speed by
backward difference (:mod:`analysis.encoder`), on the instants where the current covers them.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from analysis import encoder, sample_instants
from analysis.antialias import band_edges_hz
from analysis.chain import SignalChain, TorqueMethod
from analysis.clock_host import HostRelation, host_relation
from analysis.clock_model import ClockFit
from analysis.clocks import fit_clock
from analysis.quantisation_lock import NOTED_LOCKED_SHARE, locked_share
from analysis.recording import CommandedProfile, Recording
from analysis.sample_instants import EncoderJitter
from analysis.shared_runs import daq_runs, shared_runs


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
        The phase currents of the gap-free DAQ run used (:func:`analysis.shared_runs.shared_runs`), within the encoder
        span, A.
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

def spans_and_clock(rec: Recording, chain: SignalChain = SignalChain()) -> Spans:
    """The gap-free spans of both streams that share the most time (:func:`analysis.shared_runs.shared_runs`), the
    clock relating them (fitted from the data when
    ``chain.align``, else both streams taken as started together), and the speed on the encoder instants
    where the current covers them (away from the ends by what ``chain``'s resampling needs).

    Raises
    ------
    ValueError
        Bad or too short input, or no overlap between the current and the encoder records.
    """
    _validate(rec, chain.torque_method)
    notes: list[str] = []
    host = _host(rec)
    span, run = shared_runs(rec, host)
    cycles = rec.encoder_index[span.start:span.stop]
    if span.gaps:
        longest = span.count == encoder.longest_gap_free_span(rec.encoder_index).count
        notes.append(f"encoder: {len(span.gaps)} gap(s), first after cycle {span.gaps[0][0]}: using the "
                     f"{'longest ' * longest}gap-free span {cycles[0] * rec.period_s:.3f}–"
                     f"{cycles[-1] * rec.period_s:.3f} s{_shared(longest, 'current')}")
    if cycles.size < 8:
        raise ValueError(f"only {cycles.size} gap-free encoder samples")
    n0, lo, hi = run.first_index, run.start, run.stop
    runs = daq_runs(rec)
    if len(runs) > 1:
        longest = run.count == max(r.count for r in runs)
        notes.append(f"current: {len(runs) - 1} gap(s) in the DAQ sample count; using the {'longest ' * longest}"
                     f"gap-free run, samples {n0}–{n0 + run.count - 1}{_shared(longest, 'encoder')}")
    current = {name: a[lo:hi] for name, a in rec.current_a.items()}
    theta, jitter = _angle_on_grid(rec, span, notes)
    jitter = replace(jitter, locked_share=locked_share(rec.position_counts[span.start:span.stop]))
    if jitter.locked_share >= NOTED_LOCKED_SHARE:
        notes.append(_repeating_quantisation_note(jitter.locked_share, rec.profile))
    angle = encoder.angle_spline(int(cycles[0]), rec.period_s, theta)
    if chain.align:
        clock = fit_clock(current["i_a"], rec.rate_hz, n0, angle, rec.pole_pairs, host)
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
    f_pass, f_stop = band_edges_hz(rec)
    t_daq = clock.daq_time_s(t_s)
    edge = chain.edge_s(rec.rate_hz, f_pass, f_stop)
    inside = (t_daq >= n0 / rec.rate_hz + edge) & (t_daq <= (n0 + hi - lo - 1) / rec.rate_hz - edge)
    if inside.sum() < 8:
        raise ValueError("the current and encoder records do not overlap in time")
    if not inside.all():
        notes.append(f"using {t_s[inside][0]:.3f}–{t_s[inside][-1]:.3f} s, where both streams have data")
    return Spans(t_s[inside], t_daq[inside], speed[inside], current, n0, angle, clock, jitter, notes)

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


def _shared(longest: bool, other: str) -> str:
    """What a note adds when the run used of a stream with gaps is not its longest: the longest the ``other`` stream
    shares (:func:`analysis.shared_runs.shared_runs`)."""
    return "" if longest else f", the longest that the {other}'s data share"


def _host(rec: Recording) -> HostRelation | None:
    if not rec.host_clock_shared:
        return None  # stamps of separate tools: their time columns relate nothing
    if rec.block_host_ns is None or rec.encoder_host_ns is None or rec.block_first_index is None:
        return None
    last = np.asarray(rec.block_first_index) + np.asarray(rec.block_count) - 1
    return host_relation(last, rec.block_host_ns, rec.rate_hz, rec.encoder_index, rec.encoder_host_ns, rec.period_s)
