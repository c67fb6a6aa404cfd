"""The figures ``acq selftest`` reads from its short sessions: each a :class:`Check` (✓ / ⚠ / ✗, a figure
and, when it is not ✓, what to change in which config key). Pure computation on sessions read back;
running the devices is :mod:`acq.commissioning.selftest`, drawing the lines :mod:`acq.ui.selftest_cli`.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np

from acq.recording.session import Session
from acq.recording.summary import summarize
from analysis import (MAX_STAMP_DEVIATION, SpeedRatio, cycle_deviation_s, first_move_sign, inertia_from_torque, lower_line,
                      likely_counts_per_rev, longest_gap_free_span, phase_sequence_agreement, ratio_doubt, ratio_fault,
                      sequence_fault, speed_from_counts)
from drivers.config import Bench, DaqNidaqmx, DriveCanopen

CheckStatus = Literal["pass", "warn", "fail"]
RPM_PER_RAD_S = 60.0 / (2.0 * math.pi)
#: A drive whose speed loop follows a slow triangle reaches its top speed within a few %; a wrong
#: counts_per_rev or velocity unit is off by a factor (2×, 4×, 10×…). 15 % separates the two.
SPEED_TOLERANCE = 0.15


@dataclass(frozen=True)
class Check:
    """One selftest line: ``stage`` · ``name``, ✓ pass / ⚠ warn / ✗ fail, the measured ``figure`` in words,
    ``fix`` (what to change where) unless it passed, and the numbers behind it (``values``, SI units); a warning says
    in ``affects`` what it leaves in doubt for the recordings on this bench (the last line of ``acq selftest`` names
    it beside "the bench is ready")."""

    stage: str
    name: str
    status: CheckStatus
    figure: str
    fix: str = ""
    values: dict[str, Any] = field(default_factory=dict)
    affects: str = ""

    def to_json_dict(self) -> dict[str, Any]:
        """The check as JSON-ready values (NaN → None)."""
        doc = asdict(self)
        doc["values"] = {k: (None if isinstance(v, float) and not math.isfinite(v) else v)
                         for k, v in self.values.items()}
        return doc


# ---- streams --------------------------------------------------------------------------------------------

def samples_check(session: Session, stage: str) -> Check:
    """Samples stored and lost (gaps by the stream counters) of a session, and its status."""
    streams = {s.name: s for s in summarize(session).streams}
    cur, enc = streams["current"], streams["encoder"]
    figure = (f"{cur.duration_s:.1f} s: {cur.samples} current + {enc.samples} encoder samples, "
              f"{cur.missing} + {enc.missing} lost")
    values = {"current_samples": cur.samples, "encoder_samples": enc.samples, "current_lost": cur.missing,
              "encoder_lost": enc.missing, "status": session.status}
    if session.status != "complete":
        return Check(stage, "recording", "fail", f"{session.status}: {session.meta.stop_reason}",
                     "see the reason; acq devices lists what this machine sees", values)
    if cur.missing:
        daq = session.bench.daq
        fix = (f"raise [daq] buffer_s = {daq.buffer_s:g} or block_s = {daq.block_s:g} (the host does not read the "
               "card fast enough)" if isinstance(daq, DaqNidaqmx) else "the DAQ lost samples: check the host load")
        return Check(stage, "recording", "fail", figure, fix, values)
    if enc.missing:
        drive = session.bench.drive
        fix = (f"raise [drive] period_s = {drive.period_s:g} or the bitrate (bus load), or check the bus termination"
               if isinstance(drive, DriveCanopen) else
               f"check the link (cable, [drive] baud) or raise [drive] period_s = {drive.period_s:g}")
        if isinstance(drive, DriveCanopen) and enc.missing % _sync_counter_overflow() == 0:
            wrap = _sync_counter_overflow()
            fix = (f"{enc.missing} frames = whole SYNC-counter wraps (0x1019 = {wrap}): more likely "
                   f"the host stalled over half a wrap ({wrap * drive.period_s / 2:g} s) than frames "
                   f"lost — unload the host; else {fix}")
        return Check(stage, "recording", "fail", figure, fix, values)
    return Check(stage, "recording", "pass", figure, values=values)


def _sync_counter_overflow() -> int:
    """The SYNC counter's wrap (imported only for a CANopen bench: python-can stays unloaded otherwise)."""
    from drivers.canopen_stream import SYNC_COUNTER_OVERFLOW

    return SYNC_COUNTER_OVERFLOW


def daq_blocks_check(session: Session) -> Check:
    """How regularly the DAQ's blocks reached the host (a late read risks the card's buffer)."""
    cur = session.current
    block_s = float(np.median(cur.block_count)) / cur.rate_hz
    gaps_s = np.diff(cur.block_host_ns) * 1e-9
    longest = float(np.max(gaps_s)) if gaps_s.size else float("nan")
    figure = f"{int(np.median(cur.block_count))}-sample blocks every {1e3 * block_s:.1f} ms, longest wait {1e3 * longest:.1f} ms"
    values = {"block_s": block_s, "longest_wait_s": longest}
    daq = session.bench.daq
    if isinstance(daq, DaqNidaqmx) and longest > 0.5 * daq.buffer_s:
        return Check("streams", "DAQ blocks", "warn", figure,
                     f"a read waited over half the card's buffer: raise [daq] buffer_s = {daq.buffer_s:g}", values,
                     "a busier host may overrun the card's buffer and lose samples")
    return Check("streams", "DAQ blocks", "pass", figure, values=values)


def drive_period_check(session: Session) -> Check:
    """The drive's period and jitter: counters against host stamps (and the drive's own time if sent).

    The period is the slope under the least-delayed arrivals (:func:`analysis.clock_host.lower_line`): a host that
    holds the reader off and then delivers a burst tilts a least-squares line through every stamp (1.0103 ms on a 1 ms
    listening bus with 31 ms of latency scatter, read as "set period_s"); the jitter is the stamps' RMS about it."""
    enc, stated = session.encoder, session.bench.drive.period_s
    k = enc.index.astype(np.float64)
    host_s = (enc.host_ns - enc.host_ns[0]) * 1e-9
    nominal_s = (k - k[0]) * stated  # the drive's time as stated: lower_line takes the delays against it
    intercept, rate, _ = lower_line(nominal_s, host_s)
    slope = rate * stated
    jitter = float(np.std(host_s - (intercept + rate * nominal_s)))
    values: dict[str, Any] = {"period_host_s": float(slope), "host_jitter_s": jitter}
    figure = f"period {1e3 * slope:.4f} ms on the host clock, host-stamp jitter {1e3 * jitter:.2f} ms RMS"
    if enc.drive_time_s is not None and enc.drive_time_s.size > 2:
        span = longest_gap_free_span(enc.index)
        steps = np.diff(enc.drive_time_s[span.start:span.stop])
        values.update(period_drive_s=float(np.median(steps)), drive_jitter_s=float(np.std(steps)))
        figure += f"; drive time {1e3 * np.median(steps):.4f} ms ± {1e6 * np.std(steps):.1f} µs"
    if abs(slope / stated - 1.0) > 0.01:  # a crystal is off by ppm, a wrong setting by a factor
        return Check("streams", "drive period", "fail", figure,
                     f"[drive] period_s = {stated:g}: the drive streams every {slope:.6g} s — set period_s to the "
                     "drive's cycle", values)
    return Check("streams", "drive period", "pass", figure, values=values)


def standstill_current_check(session: Session) -> Check:
    """Per phase: mean (sensor offset + holding current) and white noise at standstill; hum if RMS ≫ white."""
    parts, values, worst = [], {}, 1.0
    for name, x in session.current.phases_a.items():
        white = 1.4826 * float(np.median(np.abs(np.diff(x, 2)))) / math.sqrt(6.0)
        rms = float(np.std(x))
        values[name] = {"mean_A": float(np.mean(x)), "white_noise_A": white, "rms_A": rms}
        parts.append(f"{name} mean {1e3 * np.mean(x):+.1f} mA, noise {1e3 * white:.1f} mA")
        worst = max(worst, rms / white if white > 0 else math.inf)
    figure = "; ".join(parts)
    if worst > 3.0:  # white noise alone gives RMS = white; more is hum, drift or a moving joint
        return Check("streams", "current at standstill", "warn", f"{figure} (RMS {worst:.1f}× the white noise)",
                     "interference at standstill (mains hum, ground loop): check the sensor's shield and ground",
                     values, "the interference adds to the current's noise, and so to K's uncertainty")
    return Check("streams", "current at standstill", "pass", figure, values=values)


def _blf_frames(blf_path: Path, settings: DriveCanopen) -> dict[str, tuple[np.ndarray, list[bytes]]]:
    """The host stamps (s) and payloads of the SYNC, TPDO and heartbeat frames in the raw ``.blf``, in log order."""
    import can

    from drivers.canopen_od import tpdo_cob_id

    frames: dict[str, tuple[list[float], list[bytes]]] = {"sync": ([], []), "tpdo": ([], []), "hb": ([], [])}
    ids = {0x80: "sync", tpdo_cob_id(settings.tpdo, settings.node_id): "tpdo", 0x700 + settings.node_id: "hb"}
    with can.BLFReader(str(blf_path)) as reader:
        for msg in reader:
            kind = ids.get(msg.arbitration_id)
            if kind is not None and not msg.is_error_frame:
                frames[kind][0].append(msg.timestamp)
                frames[kind][1].append(bytes(msg.data))
    return {k: (np.asarray(t), data) for k, (t, data) in frames.items()}


def blf_check(blf_path: Path, settings: DriveCanopen, listens: bool = False) -> Check:
    """From the raw ``.blf``: SYNC period, SYNC-to-TPDO spacing, heartbeat period (``listens``: the SYNC and the drive's
    TPDO timing are the machine's master's, which acq does not set).

    The period is the least-squares slope of the SYNC frames' host stamps over their cycle numbers (the SYNC counter,
    :func:`sync_times`): a producer that falls behind and catches up the SYNCs it owes, or a host that stamps frames
    as a batch, packs several SYNCs within microseconds, so the median of consecutive spacings reads a fraction of the
    cycle (0.286 ms on a 1 ms bus) and their standard deviation the bursts, not the cycle; the slope keeps the rate.
    How irregular the SYNC is the "SYNC jitter" check measures, against the cycle grid.
    """
    frames = _blf_frames(blf_path, settings)
    sync, tpdo, hb = (frames[k][0] for k in ("sync", "tpdo", "hb"))
    if sync.size < 3 or tpdo.size < 3:
        return Check("streams", "CAN frames", "fail", f"{blf_path.name}: {sync.size} SYNC, {tpdo.size} TPDO frames",
                     f"no SYNC/TPDO traffic logged: check [drive] tpdo = {settings.tpdo}, node_id = {settings.node_id}")
    index, stamps = _sync_cycles(frames["sync"], settings)
    period_s = float(np.polyfit(index - index[0], stamps - stamps[0], 1)[0])
    prev = np.searchsorted(sync, tpdo, side="right") - 1
    delay = tpdo[prev >= 0] - sync[prev[prev >= 0]]
    hb_period = float(np.median(np.diff(hb))) if hb.size > 2 else float("nan")
    values = {"sync_period_s": period_s, "sync_frames": int(sync.size), "sync_cycles": int(index[-1] - index[0]),
              "sync_to_tpdo_median_s": float(np.median(delay)), "sync_to_tpdo_p99_s": float(np.percentile(delay, 99)),
              "heartbeat_period_s": hb_period}
    figure = (f"SYNC every {1e3 * period_s:.3f} ms ({sync.size} SYNC frames over {stamps[-1] - stamps[0]:.1f} s), TPDO "
              f"{1e6 * values['sync_to_tpdo_median_s']:.0f} µs after SYNC (99 %: "
              f"{1e6 * values['sync_to_tpdo_p99_s']:.0f} µs), heartbeat every {1e3 * hb_period:.0f} ms")
    if values["sync_to_tpdo_p99_s"] > period_s:
        fix = (f"TPDOs arrive later than one SYNC period ({1e3 * period_s:.3f} ms, the machine's master's): acq pairs a "
               "TPDO with the SYNC before it, so one after the next SYNC is placed a cycle late — the SYNC period, the "
               "bus load and the drive's TPDO timing are the master's to set, not acq's (it listens): have the "
               "machine's integrator check them" if listens else
               f"TPDOs arrive later than one SYNC period: raise [drive] period_s = {settings.period_s:g}")
        return Check("streams", "CAN frames", "warn", figure, fix, values,
                     "TPDOs placed a cycle late" if listens else "TPDOs that miss their SYNC's window are lost samples")
    return Check("streams", "CAN frames", "pass", figure, values=values)


def sync_times(blf_path: Path, settings: DriveCanopen) -> tuple[np.ndarray, np.ndarray]:
    """The SYNC frames of the raw ``.blf``: their cycle index (from the SYNC counter, 0x1019, where they carry one;
    else their order) and host stamps, s."""
    return _sync_cycles(_blf_frames(blf_path, settings)["sync"], settings)


def _sync_cycles(sync: tuple[np.ndarray, list[bytes]], settings: DriveCanopen) -> tuple[np.ndarray, np.ndarray]:
    """The cycle index and host stamps, s, of SYNC frames (their stamps and payloads, :func:`_blf_frames`)."""
    from drivers.canopen_stream import SYNC_COUNTER_OVERFLOW  # python-can: only where a .blf is read

    stamps, payloads = sync
    counters = np.array([p[0] if p else 0 for p in payloads], dtype=np.int64)
    if counters.size and np.all(counters > 0):  # 1…overflow: a step of 0 or less wrapped
        # the counter's own overflow — the master's 0x1019 when acq listens, else the one acq sets — not the largest
        # counter seen, which SYNC frames lost at the top of the count would lower (the second read)
        wrap = max(settings.sync_counter_overflow or SYNC_COUNTER_OVERFLOW, int(counters.max()))
        steps = (np.diff(counters) - 1) % wrap + 1
        return np.r_[0, np.cumsum(steps)], stamps
    return np.arange(stamps.size), stamps


#: The bound: no cycle of an identification may be half a cycle or more off its grid
#: (:data:`analysis.MAX_STAMP_DEVIATION`). The clock fit (analysis.clocks) takes drive cycle k at exactly k·T: a
#: zero-mean scatter only adds noise to its windowed phase fits, and analysis.sample_instants moves each sample to k·T
#: with the drive's stamps — which it refuses for the whole record once one deviates half a cycle (the spline move needs
#: a deviation much smaller than T, and a stamp half a cycle off could belong to the neighbouring cycle). On CANopen a
#: SYNC that far off also breaks the synchronous window (CiA 301: TPDO k before SYNC k+1) by which each sample is paired
#: with its SYNC. What a smaller jitter costs (speed noise at speed, without stamps) the identification's verdict judges
#: from its own spectra.
def sync_jitter_check(index: np.ndarray, times_s: np.ndarray, period_s: float, source: str, identification_s: float,
                      from_drive: bool, listens: bool = False) -> Check:
    """The drive cycle's irregularity (``times_s`` of cycles ``index``, s, measured by ``source``) against half a cycle.

    The scatter σ is robust (1.4826 × the median absolute deviation from the cycle grid: one stall does not stand
    for the jitter; the largest deviation is judged on its own). The largest deviation a Gaussian jitter reaches in
    the identification's N = ``identification_s``/T cycles is ≈ σ·√(2 ln N); at half a cycle or more
    (:data:`analysis.MAX_STAMP_DEVIATION`) it is a ⚠. A deviation already seen that large in the drive's own stamps
    (``from_drive``) is a ✗; in host stamps, which carry the host's own latency (an upper bound of the drive's
    irregularity), a ⚠. On a bench that ``listens`` the SYNC is the machine's master's: the remedy is its integrator's.
    """
    bound_s = MAX_STAMP_DEVIATION * period_s
    dev = cycle_deviation_s(index, times_s, period_s)
    if dev is None:
        return Check("streams", "SYNC jitter", "warn", f"{source}: too few cycles to measure",
                     "record the standstill again (acq selftest) and check that the drive streams",
                     affects="the drive cycle's timing is unmeasured")
    sigma = 1.4826 * float(np.median(np.abs(dev - np.median(dev))))
    largest = float(np.max(np.abs(dev)))
    cycles = max(identification_s / period_s, 2.0)
    expected = sigma * math.sqrt(2.0 * math.log(cycles))
    values = {"sigma_s": sigma, "largest_s": largest, "expected_largest_s": expected, "bound_s": bound_s,
              "period_s": period_s, "source": source}
    figure = (f"{1e6 * sigma:.1f} µs RMS, largest {1e6 * largest:.0f} µs off the {1e3 * period_s:g} ms cycle grid "
              f"({source}); bound {1e6 * bound_s:.0f} µs")
    remedy = ("the SYNC is the machine's master's, not acq's (it listens): have the machine's integrator give it a "
              "hardware-timed SYNC or unload the host that produces it" if listens else
              "use a hardware-timed SYNC (SocketCAN's broadcast manager, the interface's own timer, or the drive as SYNC "
              "producer) or unload the host that produces it")
    why = ("half a cycle or more, where the analysis refuses the drive's time stamps (a drive that samples at SYNC "
           f"arrival then has samples it cannot place) and a TPDO can miss its SYNC's window — {remedy}")
    if largest >= bound_s and from_drive:
        return Check("streams", "SYNC jitter", "fail", figure, f"a cycle {1e6 * largest:.0f} µs off its grid, {why}",
                     values)
    if largest >= bound_s or expected >= bound_s:
        seen = (f"a cycle {1e6 * largest:.0f} µs off its grid" if largest >= bound_s else
                f"{1e6 * sigma:.0f} µs RMS reaches ≈ {1e6 * expected:.0f} µs in the {identification_s:g} s "
                "identification")
        return Check("streams", "SYNC jitter", "warn", figure, f"{seen}, {why}", values,
                     "the analysis may refuse a recording's drive time stamps, and TPDOs may miss their SYNC")
    return Check("streams", "SYNC jitter", "pass", figure, values=values)


# ---- motion ---------------------------------------------------------------------------------------------

def encoder_speed_check(session: Session, top_speed_rpm: float) -> Check:
    """The encoder's peak speed (stated counts_per_rev) against the commanded top speed."""
    enc = session.encoder
    span = longest_gap_free_span(enc.index)
    omega = speed_from_counts(enc.position_counts[span.start:span.stop], enc.counts_per_rev, enc.period_s)
    per = max(1, round(0.01 / enc.period_s))  # 10 ms mean: one count of quantisation is not a speed
    smooth = np.convolve(np.abs(omega), np.ones(per) / per, mode="valid")
    peak_rpm = float(np.max(smooth)) * RPM_PER_RAD_S if smooth.size else 0.0
    q = peak_rpm / top_speed_rpm
    values = {"peak_rpm": peak_rpm, "commanded_rpm": top_speed_rpm, "ratio": q}
    figure = f"peak {peak_rpm:.0f} rpm of {top_speed_rpm:g} rpm commanded ({q:.2f}×)"
    if peak_rpm < 0.05 * top_speed_rpm:
        return Check("motion", "encoder speed", "fail", figure,
                     "the encoder saw no move: is the drive enabled and the motor free? check [drive] and the wiring",
                     values)
    if abs(q - 1.0) > SPEED_TOLERANCE:
        cpr = session.bench.encoder.counts_per_rev
        fix = f"check [encoder] counts_per_rev = {likely_counts_per_rev(cpr * q, SPEED_TOLERANCE / 3)}"
        if isinstance(session.bench.drive, DriveCanopen):
            fix += f" or [drive] velocity_units_per_rpm = {session.bench.drive.velocity_units_per_rpm * q:.4g}"
        return Check("motion", "encoder speed", "fail", figure, fix, values)
    return Check("motion", "encoder speed", "pass", figure, values=values)


def speed_ratio_check(ratio: SpeedRatio | None, bench: Bench) -> Check:
    """The current's electrical frequency against pole_pairs·ω (see :mod:`analysis.speed_ratio`)."""
    p, cpr = bench.motor.pole_pairs, bench.encoder.counts_per_rev
    if ratio is None:
        return Check("motion", "electrical speed", "fail", "no electrical frequency in the current during the move",
                     "the current sensor sees no phase current: check [daq] channels / physical_channels and the "
                     "sensor's wiring")
    values = {"ratio": ratio.ratio, "spread": ratio.spread, "lag_s": ratio.lag_s}
    figure = f"the current turns at {ratio.ratio:.3f}× pole_pairs·ω (pole_pairs = {p}, counts_per_rev = {cpr})"
    doubt = ratio_doubt(ratio, p)
    if doubt is not None:
        return Check("motion", "electrical speed", "warn", doubt,
                     "pole_pairs and counts_per_rev stay unchecked: check that the motor turns freely through the slow "
                     "move and that the current sensor reads a phase current", values,
                     "pole_pairs and counts_per_rev are unchecked")
    fault = ratio_fault(ratio, p, cpr)
    if fault is not None:
        figure, what = fault.split(": check ", 1)
        return Check("motion", "electrical speed", "fail", figure, f"check {what}", values)
    return Check("motion", "electrical speed", "pass", figure, values=values)


def direction_check(session: Session) -> Check:
    """The first move is commanded forward (the triangle starts with +speed): the encoder must count up."""
    sign = first_move_sign(session.encoder.position_counts)
    values = {"first_move_sign": sign}
    if sign < 0:
        return Check("motion", "direction", "fail", "the encoder counts down while the drive moves forward",
                     "reverse the encoder's counting direction in the drive (CiA 402 polarity 0x607E, or swap its "
                     "A/B lines) — acq reads the position as the drive reports it", values)
    return Check("motion", "direction", "pass", "forward move counted up", values=values)


def phase_order_check(session: Session, lag_s: float) -> Check:
    """With 2–3 phases: the current's phase sequence must turn with the encoder."""
    cur, enc = session.current, session.encoder
    names = list(cur.phases_a)
    if len(names) < 2:
        return Check("motion", "phase order", "pass", "one phase recorded: no sequence to check")
    agree = phase_sequence_agreement(cur.phases_a, cur.rate_hz, enc.index, enc.position_counts, enc.period_s, lag_s)
    values = {"agreement": agree}
    fault = sequence_fault(agree, names)
    if fault is not None:
        figure, fix = fault.split(": set ", 1)
        return Check("motion", "phase order", "fail", figure, f"set {fix}", values)
    figure = f"phase sequence {'/'.join(n[2:] for n in names)} turns with the encoder (correlation {agree:+.2f})"
    if agree > 0.5:
        return Check("motion", "phase order", "pass", figure, values=values)
    return Check("motion", "phase order", "warn", figure,
                 "the sequence is unclear (little motion?): repeat with a longer move", values,
                 "the phase order is unchecked")


def torque_constant_check(t_s: np.ndarray, torque_Nm: np.ndarray, speed_rad_s: np.ndarray, bench: Bench) -> Check:
    """k_t (and the sensor scale) against a known inertia: J from torque/acceleration vs [nominal] Jm + Jl."""
    fit = inertia_from_torque(t_s, torque_Nm, speed_rad_s, bench.gear.ratio)
    nominal = bench.nominal.Jm_kgm2 + bench.nominal.Jl_kgm2
    q = fit.J_kgm2 / nominal
    values = {"J_from_torque_kgm2": fit.J_kgm2, "J_std_kgm2": fit.J_std_kgm2, "J_nominal_kgm2": nominal, "ratio": q}
    figure = f"torque/acceleration gives J = {fit.J_kgm2:.4g} kg·m², {q:.2f}× [nominal] Jm + Jl = {nominal:.4g}"
    if not bench.nominal.inertia_known:
        return Check("identification", "torque constant", "warn", figure,
                     "k_t and the current sensor's scale are not checked (a wrong one scales K, J_m, J_l and C alike): "
                     "set [nominal] Jm_kgm2 and Jl_kgm2 from the datasheet or CAD and inertia_known = true", values,
                     "k_t and the current sensor's scale are unchecked (a wrong one scales K alike)")
    if abs(q - 1.0) > max(bench.nominal.inertia_tolerance, 4.0 * fit.J_std_kgm2 / nominal):
        kt = bench.motor.torque_constant_Nm_per_A
        daq = bench.daq
        sensor = ("the current sensor's scale" if not isinstance(daq, DaqNidaqmx) else
                  f"[daq] sensor_A_per_V = {daq.sensor_A_per_V / q:.4g}" if daq.measurement == "voltage" else
                  f"[daq] sensor_A_per_A = {daq.sensor_A_per_A / q:.4g}")
        return Check("identification", "torque constant", "fail",
                     f"{figure}: the torque reads {q:.2f}× too {'high' if q > 1 else 'low'}",
                     f"check [motor] torque_constant_Nm_per_A = {kt / q:.4g} or {sensor}", values)
    return Check("identification", "torque constant", "pass", figure, values=values)
