"""``acq selftest``: first contact with a bench — short checks in order, each a :class:`~acq.commissioning.selftest_checks.Check`.

1. devices: what ``acq devices`` sees for the configured hardware; the devices opened through the registry
   (as ``acq record`` does): the DAQ's channels and coerced rate, the drive reachable (a CANopen drive is
   configured, its heartbeat awaited and its TPDO mapping read back by the adapter; identity 0x1018 read, and the
   0x607D window with the 0x607C home offset);
2. streams: 3 s at standstill through the real recorder into a temporary session — samples lost, DAQ block
   timing, drive period and jitter, the SYNC jitter against half a cycle (what the analysis takes for a jitter
   around the drive's cycle grid: :func:`~acq.commissioning.selftest_checks.sync_jitter_check`), for CANopen the
   SYNC-to-TPDO spacing from the raw ``.blf``, for a serial link frames and CRC errors, current offset and noise;
3. motion: a short slow triangle — encoder speed against the command, the current's electrical frequency
   against pole_pairs·ω, direction, phase order (2–3 phases);
4. identification: a 10 s session of the profile, its verdict, and the torque constant against a known inertia.

On a bench that listens (``[drive] motion = "external"``: the machine's own controller moves the joint) acq
commands no motion and runs what needs none (:func:`_passive_motion_and_identification`): devices and streams
as above, recorded passively (without the current at standstill: the machine may be moving), then 10 s of
the machine's own motion — the electrical speed and phase order on it, and the identification on the
segments that excite (as ``acq monitor``): a window the machine did not excite is a ⚠ that says so, not a
verdict on the bench. The slow move's commanded speed and direction cannot be checked there.

The checks run in this order and stop at the first ✗ (a later check would only repeat its consequence).
The simulated bench runs through the same registry; this module never imports ``drivers.sim``.
"""

from __future__ import annotations

import json
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from acq.commissioning.devices import can_section, ni_section, serial_section
from acq.commissioning.drive_sdo import read_identity, read_position_frame
from acq.commissioning.selftest_checks import (Check, blf_check, daq_blocks_check, direction_check, drive_period_check,
                                               encoder_speed_check, phase_order_check, samples_check, speed_ratio_check,
                                               standstill_current_check, sync_jitter_check, sync_times,
                                               torque_constant_check)
from acq.offline.analyze import analyze_session, joint_travel, recording_from_session
from acq.recording.recorder import Recorder, RecordingResult
from acq.recording.reader import load
from acq.recording.session import Session
from analysis import AnalysisRequest, electrical_speed_ratio, prepare_signals
from drivers.config import Bench, DaqNidaqmx, DriveCanopen, DriveSerial, Profile
from acqcore.errors import AcqError
from drivers.registry import open_bench

STANDSTILL_S = 3.0
IDENTIFICATION_S = 10.0
#: The first move on an unknown bench: one back-and-forth at a fifth of the identification's 1000 rpm
#: (a few electrical periods per ramp even at one pole pair), 0.3 s ramps, 0.2 s rests.
SLOW_MOVE = Profile(kind="triangle", top_speed_rpm=200.0, accel_time_s=0.3, decel_time_s=0.3, dwell_s=0.2,
                    duration_s=2.5)
STANDSTILL = Profile(kind="triangle", top_speed_rpm=1.0, accel_time_s=1.0, decel_time_s=1.0,
                     duration_s=STANDSTILL_S)  # stored in the session; never executed (see _HoldStill)


class Stopped(Exception):
    """A recording of the selftest stopped by Ctrl-C or SIGTERM (the only stop requests a selftest's recorder gets):
    no verdict on the bench, not a failed check. ``stage``: the stage that was recording; ``reason``: the
    recorder's stop reason ("interrupted by user (Ctrl-C)", "stopped by SIGTERM")."""

    def __init__(self, stage: str, reason: str) -> None:
        super().__init__(f"{stage}: {reason}")
        self.stage, self.reason = stage, reason


def _not_stopped(result: RecordingResult, stage: str) -> RecordingResult:
    """``result`` unless a stop request ended it (status ``interrupted``): then :class:`Stopped`."""
    if result.status == "interrupted":
        raise Stopped(stage, result.stop_reason)
    return result


class _HoldStill:
    """A drive that ignores ``start_motion``: the recorder then records the joint at rest."""

    def __init__(self, drive: Any) -> None:
        self._drive = drive

    def start_motion(self, profile: Profile) -> None:
        """Do not move."""

    def __getattr__(self, name: str) -> Any:
        return getattr(self._drive, name)


def run_selftest(bench: Bench, profile: Profile | None, work_dir: Path, *, fast: bool = False) -> Iterator[Check]:
    """Run the checks in order, yielding each as it completes; stop after the first that fails.

    Parameters
    ----------
    bench, profile : the bench config and the identification's motion (None on a bench that :meth:`drivers.config.Bench.listens`).
    work_dir : folder for the short sessions (and their raw logs).
    fast : simulated parts run as fast as possible (as ``acq record --fast``).
    """
    passive = (_passive_motion_and_identification,)
    for stage in (_devices_and_streams, *(passive if bench.listens() else (_motion, _identification))):
        for check in stage(bench, profile, work_dir, fast):
            yield check
            if check.status == "fail":
                return


def _toml(value: Any) -> str:
    """A config value as it is written in the TOML file (strings quoted, lists in brackets)."""
    return json.dumps(list(value) if isinstance(value, tuple) else value, ensure_ascii=False)


def _listed(bench: Bench) -> Iterator[Check]:
    """What ``acq devices`` sees of the configured hardware (simulated parts are always there)."""
    daq, drive = bench.daq, bench.drive
    if isinstance(daq, DaqNidaqmx):
        ni = ni_section()
        seen = {name for name, _, _ in ni.rows}
        wanted = {c.split("/")[0] for c in daq.physical_channels}
        if ni.install:  # no device can be seen before the package and the driver are there
            yield Check("devices", "acq devices", "fail", ni.empty_because,
                        f"{ni.install}; then acq devices lists the card — or use configs/benches/sim.toml")
            return
        if ni.empty_because or not wanted <= seen:
            yield Check("devices", "acq devices", "fail", ni.empty_because or f"NI-DAQmx sees {sorted(seen)}",
                        f"[daq] physical_channels = {_toml(daq.physical_channels)}: no device "
                        f"{', '.join(sorted(wanted - seen))} — check the cable and NI MAX, or the device name")
            return
    if isinstance(drive, DriveSerial) and not drive.simulated_device:
        ports = {name for name, _, _ in serial_section().rows}
        if drive.port not in ports:
            yield Check("devices", "acq devices", "fail", f"serial ports seen: {sorted(ports) or 'none'}",
                        f"[drive] port = {_toml(drive.port)} is not there: set it to one of the ports listed")
            return
    if isinstance(drive, DriveCanopen) and not drive.simulated_node:
        channels = {name for name, _, _ in can_section().rows}
        if drive.channel not in channels:  # python-can's detection is best effort: the open decides
            yield Check("devices", "acq devices", "warn", f"python-can detects {sorted(channels) or 'no interface'}",
                        f"[drive] channel = {_toml(drive.channel)} not detected; bring it up "
                        f"(ip link set {drive.channel} up type can bitrate {drive.bitrate})",
                        affects="none once the drive opens (python-can's detection is best effort)")
            return
    yield Check("devices", "acq devices", "pass", "the configured devices are listed")


def _devices_and_streams(bench: Bench, profile: Profile | None, work_dir: Path, fast: bool) -> Iterator[Check]:
    listed = list(_listed(bench))
    yield from listed
    if any(c.status == "fail" for c in listed):
        return
    try:
        current, drive = open_bench(bench, fast=fast)
        recorder = (Recorder(bench, None, current, drive, work_dir, STANDSTILL_S, tags={"selftest": "streams"})
                    if bench.listens() else  # the machine's motion, whatever it does: no command
                    Recorder(bench, STANDSTILL, current, _HoldStill(drive), work_dir, STANDSTILL_S,
                             tags={"selftest": "standstill"}))
        recorder.start_devices()
    except AcqError as e:
        yield Check("devices", "open", "fail", str(e), "the message names the key or the device; "
                    "acq devices lists what this machine sees", {"exit_code": e.exit_code})
        return
    result = None
    try:
        yield _daq_check(bench, recorder)
        yield _drive_check(bench, recorder)
        result = recorder.run()  # releases the devices whatever happens
    finally:
        if result is None:  # stopped at a device check (or interrupted): release the started devices
            drive.stop()
            current.stop()
    session = load(_not_stopped(result, "streams").path)
    yield samples_check(session, "streams")
    if session.status != "complete":
        return
    yield daq_blocks_check(session)
    yield drive_period_check(session)
    blf = result.path.with_suffix(".can.blf")
    yield _sync_jitter(session, blf if isinstance(bench.drive, DriveCanopen) and blf.exists() else None)
    if isinstance(bench.drive, DriveCanopen) and blf.exists():
        yield blf_check(blf, bench.drive, bench.listens())
    stats = getattr(drive, "stats", None)  # a serial link's frame and CRC counters
    if callable(stats):
        yield _serial_check(stats(), bench)
    if not bench.listens():  # a listening bench's joint may be moving: no standstill to measure offset and noise on
        yield standstill_current_check(session)


def _sync_jitter(session: Session, blf: Path | None) -> Check:
    """The drive cycle's irregularity, from the best timing the session has: the drive's own time stamps (0x1013 /
    the serial frame's drive time: when it really sampled), else the SYNC frames' host stamps in the raw ``.blf``
    (SocketCAN stamps them in the kernel), else the host arrival stamps of the samples (the host's latency in them)."""
    enc, period_s, listens = session.encoder, session.encoder.period_s, session.bench.listens()
    if enc.drive_time_s is not None:
        return sync_jitter_check(enc.index, enc.drive_time_s, period_s, "the drive's own time stamps",
                                 IDENTIFICATION_S, from_drive=True, listens=listens)
    if blf is not None:
        index, stamps_s = sync_times(blf, session.bench.drive)
        return sync_jitter_check(index, stamps_s, period_s, f"host stamps of the SYNC frames in {blf.name}",
                                 IDENTIFICATION_S, from_drive=False, listens=listens)
    return sync_jitter_check(enc.index, enc.host_ns * 1e-9, period_s, "host arrival stamps of the samples, an upper "
                             "bound", IDENTIFICATION_S, from_drive=False, listens=listens)


def _listening_text(drive: DriveCanopen) -> str:
    """What opening a listening CANopen drive established: the master's SYNC heard and the TPDO recorded (its mapping
    taken from where, :func:`drivers.canopen_eds.passive_tpdo`, or mapped by acq); no profile, no heartbeat asked."""
    if drive.configure:
        mapping = f"TPDO{drive.tpdo} mapped by acq (SDO)"
    else:
        from drivers.canopen_eds import passive_tpdo

        tpdo = passive_tpdo(drive)
        mapping = f"TPDO 0x{tpdo.cob_id:X} as {tpdo.source} state it (not read back)"
    return (f"listening: the machine's master's SYNC heard, {mapping}; no NMT, SYNC or motion sent, so no profile "
            "verified")


def _daq_check(bench: Bench, recorder: Recorder) -> Check:
    info = recorder.current_info
    figure = f"{info.device}: {', '.join(info.channels)} at {info.rate_hz:g} Hz"
    values = {"device": info.device, "channels": list(info.channels), "rate_hz": info.rate_hz,
              "requested_rate_hz": bench.daq.rate_hz}
    if list(info.channels) != list(bench.daq.channels):
        return Check("devices", "DAQ", "fail", figure, f"[daq] channels = {_toml(bench.daq.channels)}: the card "
                     f"delivers {_toml(info.channels)}", values)
    if abs(info.rate_hz / bench.daq.rate_hz - 1.0) > 0.01:
        return Check("devices", "DAQ", "warn", f"{figure} (coerced from {bench.daq.rate_hz:g} Hz)",
                     f"[daq] rate_hz = {bench.daq.rate_hz:g}: the card runs {info.rate_hz:g} Hz — state that rate",
                     values, f"[daq] rate_hz is not the {info.rate_hz:g} Hz the card runs")
    return Check("devices", "DAQ", "pass", figure, values=values)


def _drive_check(bench: Bench, recorder: Recorder) -> Check:
    info = recorder.drive_info
    figure = f"{info.device}: {info.transport}, period {1e3 * info.period_s:g} ms, {info.counts_per_rev} counts/rev"
    values = {"device": info.device, "transport": info.transport, "period_s": info.period_s,
              "counts_per_rev": info.counts_per_rev}
    drive = bench.drive
    if isinstance(drive, DriveCanopen):
        figure += "; " + (_listening_text(drive) if bench.listens() else
                          f"heartbeat, TPDO{drive.tpdo} mapping read back and Profile Position verified")
        identity = read_identity(drive)
        if isinstance(identity, str):  # 0x1018 is mandatory (vendor ID) in CiA 301: say so, but it blocks nothing
            return Check("devices", "drive", "warn", f"{figure}; identity 0x1018: {identity}",
                         f"the node at [drive] node_id = {drive.node_id} does not give its identity: check it is "
                         "the drive you mean", values, "the drive's identity is unconfirmed")
        values["identity"] = identity
        figure += "; identity 0x1018 " + ", ".join(f"{k} 0x{v:08X}" for k, v in identity.items())
        if not bench.listens():  # acq sets its travel window in 0x6064's frame (a home offset was refused at start)
            figure += "; " + read_position_frame(drive)
    return Check("devices", "drive", "pass", figure, values=values)


def _serial_check(stats: Any, bench: Bench) -> Check:
    rate = stats.crc_errors / max(stats.frames + stats.crc_errors, 1)
    figure = f"{stats.frames} frames, {stats.crc_errors} CRC errors ({rate:.2%}), {stats.resyncs} resyncs"
    values = {"frames": stats.frames, "crc_errors": stats.crc_errors, "crc_error_rate": rate, "resyncs": stats.resyncs}
    if stats.crc_errors:
        return Check("streams", "serial link", "warn" if rate < 0.01 else "fail", figure,
                     f"CRC errors on a standing link: check the cable and its shield, [drive] baud = {bench.drive.baud}"
                     f" and parity = {_toml(bench.drive.parity)}", values,
                     "frames with CRC errors are lost samples")
    return Check("streams", "serial link", "pass", figure, values=values)


def _record(bench: Bench, profile: Profile | None, work_dir: Path, fast: bool, duration_s: float, tag: str,
            stage: str) -> Path:
    """Record ``duration_s`` of ``profile`` (None: passively) through the registry and the recorder; the session's
    path (:class:`Stopped` when Ctrl-C or SIGTERM ended it)."""
    current, drive = open_bench(bench, fast=fast)
    recorder = Recorder(bench, profile, current, drive, work_dir, duration_s, tags={"selftest": tag})
    return _not_stopped(recorder.run(), stage).path


def _motion(bench: Bench, profile: Profile, work_dir: Path, fast: bool) -> Iterator[Check]:
    session = load(_record(bench, SLOW_MOVE, work_dir, fast, SLOW_MOVE.duration_s, "slow move", "motion"))
    moved = samples_check(session, "motion")
    if moved.status == "fail":
        yield moved
        return
    yield encoder_speed_check(session, SLOW_MOVE.top_speed_rpm)
    rec = recording_from_session(session)
    ratio = electrical_speed_ratio(rec.current_a["i_a"], rec.rate_hz, rec.encoder_index, rec.position_counts,
                                   rec.period_s, rec.counts_per_rev, rec.pole_pairs)
    yield speed_ratio_check(ratio, bench)
    yield direction_check(session)
    yield phase_order_check(session, ratio.lag_s if ratio is not None else 0.0)


def _identification(bench: Bench, profile: Profile, work_dir: Path, fast: bool) -> Iterator[Check]:
    path = _record(bench, profile, work_dir, fast, IDENTIFICATION_S, "identification", "identification")
    recorded = samples_check(load(path), "identification")
    if recorded.status == "fail":  # frames lost while moving: the identification would only echo it
        yield recorded
        return
    yield from _identified(bench, path)


def _passive_motion_and_identification(bench: Bench, profile: Profile | None, work_dir: Path,
                                       fast: bool) -> Iterator[Check]:
    """On a listening bench: 10 s of the machine's own motion, the motion checks that need no command, and the
    identification on the segments that excite."""
    path = _record(bench, None, work_dir, fast, IDENTIFICATION_S, "machine's motion", "motion")
    session = load(path)
    recorded = samples_check(session, "motion")
    if recorded.status == "fail":
        yield recorded
        return
    travel, need = joint_travel(session)
    if travel < need:
        yield Check("motion", "machine's motion", "warn", f"the joint travelled {travel:.0f} counts in "
                    f"{IDENTIFICATION_S:g} s, less than half an electrical revolution ({need:.0f} counts)",
                    _WHILE_IT_RUNS, {"travel_counts": travel}, "the motion checks and K are unchecked")
        return
    revolutions = travel / bench.encoder.counts_per_rev
    yield Check("motion", "machine's motion", "pass", f"the joint travelled {revolutions:.1f} motor revolutions in "
                f"{IDENTIFICATION_S:g} s (the machine's own motion; acq commanded none)",
                values={"travel_counts": travel})
    rec = recording_from_session(session)
    ratio = electrical_speed_ratio(rec.current_a["i_a"], rec.rate_hz, rec.encoder_index, rec.position_counts,
                                   rec.period_s, rec.counts_per_rev, rec.pole_pairs)
    if ratio is None:  # a program's moves need not give one: the commanded slow move's "no current" does not follow
        yield Check("motion", "electrical speed", "warn", "the machine's motion gives no steady ratio of the current's "
                    "electrical frequency to pole_pairs·ω (its half-periods scatter, or its moves are too short)",
                    "pole_pairs, counts_per_rev and the phase order stay unchecked on a listening bench: take them "
                    "from the motor's and the encoder's data sheets",
                    affects="pole_pairs, counts_per_rev and the phase order are unchecked")
    else:
        yield speed_ratio_check(ratio, bench)
        yield phase_order_check(session, ratio.lag_s)
    yield from _identified(bench, path)


#: What a listening bench's selftest asks for when the machine's motion does not serve (it cannot command any).
_WHILE_IT_RUNS = ("run acq selftest again while the machine runs a program with fast moves of this joint (acq "
                  "commands no motion on a bench with [drive] motion = \"external\")")


def _identified(bench: Bench, path: Path) -> Iterator[Check]:
    """The identification of a recorded session: its verdict (a passive recording, analysed on the segments that
    excite, that does not excite: a ⚠ saying so) and the torque constant against a known inertia."""
    done = analyze_session(path, report=False)
    doc = done.json_dict
    reasons = [r for r in doc["quality"]["reasons"] if not r.startswith("note: ")]
    if doc["quality"]["verdict"] == "not excited":  # the machine's motion, not the bench, fell short
        yield Check("identification", f"identification ({IDENTIFICATION_S:g} s)", "warn",
                    "not excited: " + "; ".join(reasons), _WHILE_IT_RUNS,
                    {"verdict": "not excited"}, "K is unchecked (the machine did not excite the joint)")
        return
    quality = doc["quality"]
    values = {k: doc[k] for k in ("K_Nm_per_rad", "Jm_kgm2", "Jl_kgm2", "C_Nms_per_rad")}
    values["verdict"] = quality["verdict"]
    k, (lo, hi) = doc["K_Nm_per_rad"], doc["ci95"]["K_Nm_per_rad"]
    figure = (f"verdict {quality['verdict']}: K = {k:.4g} N·m/rad ({lo:.4g} – {hi:.4g}), f_a {doc['antiresonance_hz']:.0f} "
              f"Hz, f_r {doc['resonance_hz']:.0f} Hz" if k is not None and lo is not None and hi is not None else
              f"verdict {quality['verdict']}")
    status = {"ok": "pass", "poor": "warn", "failed": "fail"}[quality["verdict"]]
    yield Check("identification", f"identification ({IDENTIFICATION_S:g} s)", status, figure,  # type: ignore[arg-type]
                "; ".join(reasons), values, "K of this profile's recordings may be poor" if status == "warn" else "")
    if status == "fail":
        return
    session = done.session
    rec = recording_from_session(session)
    sig = prepare_signals(rec, AnalysisRequest().chain(rec))
    yield torque_constant_check(sig.t_s, sig.torque_Nm, sig.speed_rad_s, bench)
