"""A CiA 402 servo drive over CANopen (canopen ``BaseNode402`` on python-can), as a :class:`Drive`.

Imported only when a bench names ``[drive] driver = "canopen"`` (the registry's lazy import), so
canopen and python-can are needed only then. This module runs the drive's life cycle (start, read, stop) and
watches its stream's health. :meth:`CanopenDrive.start` (drive disabled throughout): open the bus (own frames
echoed, to pair TPDOs with SYNC), check the node is a CiA 402 device, NMT PRE-OPERATIONAL, producer heartbeat
(0x1017), then the SDO steps of :mod:`drivers.canopen_setup`, each verified on the drive (SYNC counter 0x1019 = 240
or plain SYNC, TPDO ``tpdo`` mapping read back — with ``map_timestamp`` also 0x1013 —, Profile Position, the bench's
``[limits]`` read back, the position frame; 0x607D software position limits follow around the start position when
the motion starts), then NMT OPERATIONAL and the SYNC producer. A bus load above ``max_bus_load`` is refused before
(:mod:`drivers.canopen_bus_load`). Motion (enable, the triangle by Profile Position, quick stop and disable) is
:mod:`drivers.canopen_motion`; the encoder stream (SYNC counter, notifier-side capture, decoding, raw ``.blf`` log)
is :mod:`drivers.canopen_stream`.

Safety: every stop — end of recording, any exception, Ctrl-C (through the recorder's
:meth:`stop_motion`), heartbeat loss, NMT state change, motion-thread failure — is a quick stop on
the 0x6085 ramp followed by disable voltage, verified on the statusword. Heartbeat loss and the
other failures seen while streaming surface as :class:`DeviceError` from :meth:`read` once the
frames received before are delivered (the recorder then ends the session ``failed``, data kept).

Listen-only (``[drive] motion = "external"``, :meth:`CanopenDrive.start` → ``_start_listening``): the machine's
own master runs NMT, SYNC and the motion, so acq sends no NMT, no SYNC, no SDO write and no RPDO; it records the
TPDO the master set up (COB-ID and mapping from the bench config or the drive's EDS/DCF,
:mod:`drivers.canopen_eds`), pairing each with the master's SYNC before it, stamped on arrival; a statusword mapped in
it is watched for bit 11 "internal limit active" (each span an event, :func:`drivers.base.limit_event`). With
``configure = true`` it first maps its own TPDO ``tpdo`` by SDO (still no NMT, SYNC or motion). No heartbeat is
required (the master owns the drive's heartbeat), and the bus-load check of acq's own traffic does not apply.

Units: positions in drive position units (``counts_per_rev`` per motor revolution, default the
encoder's), velocities ``velocity_units_per_rpm``, accelerations ``acceleration_units_per_rpm_per_s``.
"""
from __future__ import annotations

import queue
import threading
import time
from pathlib import Path
import canopen

from drivers import canopen_od as od
from drivers.canopen_bus_load import check_bus_load
from drivers.canopen_eds import PassiveTpdo, passive_tpdo
from drivers.base import DriveInfo, EncoderBlock, EventKind, StreamEvent, StreamName, limit_event
from drivers.canopen_motion import ProfilePositionMotion, device_step, node402
from drivers.canopen_setup import (check_position_frame, enable_sync_counter, map_tpdo, set_profile_position,
                                   write_limits)
from drivers.canopen_stream import (SYNC_COB_ID, SYNC_COUNTER_OVERFLOW, FrameCapture, RawFrameLog, SyncProducer,
                                    SyncUnwrapper, TpdoDecoder, TpdoLayout)
from drivers.config import Bench, DriveCanopen, Limits, Profile
from drivers.limits import missing_limits, travel_counts
from acqcore.errors import AcqError, ConfigError, DeviceError

QUEUE_FRAMES = 20_000
BATCH_S = 0.05
NMT_OPERATIONAL = 5


class CanopenDrive:
    """A CiA 402 drive on a CAN bus (implements :class:`drivers.base.Drive`).

    Parameters
    ----------
    settings : the bench's ``[drive]`` section.
    counts_per_rev : drive position units per motor revolution.
    passive : the master's TPDO to record (``motion = "external"`` with ``configure = false``), else None.
    """

    def __init__(self, settings: DriveCanopen, counts_per_rev: int, passive: PassiveTpdo | None = None,
                 limits: Limits | None = None, gear_ratio: float = 1.0) -> None:
        self._s, self._cpr, self._passive = settings, counts_per_rev, passive
        self._limits, self._gear_ratio = limits, gear_ratio
        self.name = f"CANopen node {settings.node_id} on {settings.interface}:{settings.channel}"
        self._network: canopen.Network | None = None
        self._node: canopen.profiles.p402.BaseNode402 | None = None
        self._sync: SyncProducer | None = None
        self._capture: FrameCapture | None = None
        self._decoder: TpdoDecoder | None = None
        self._raw = RawFrameLog()
        self._events: list[StreamEvent] = []
        self._events_lock = threading.Lock()
        self._motion: ProfilePositionMotion | None = None
        self._failure: DeviceError | None = None
        self._hb_ns = 0
        self._hb_state = 0
        self._reported = {"overruns": 0, "errors": 0, "bad_length": 0}

    # ---- Drive protocol ----------------------------------------------------------------------------
    def start(self) -> DriveInfo:
        """Configure in PRE-OPERATIONAL, start the TPDO stream on SYNC (the drive stays disabled); with
        ``motion = "external"`` listen only (see the module doc)."""
        s = self._s
        if s.motion == "external":
            return self._start_listening()
        try:
            self._open_bus()
            node = node402(s.node_id)
            self._network.add_node(node)
            self._node = node
            travel = (None if self._limits is None else
                      travel_counts(self._limits.max_travel_deg, self._gear_ratio, self._cpr))
            self._motion = ProfilePositionMotion(node, self.name, s, self._cpr, self._fail, self._info, travel,
                                                 self._add_event)
            node.sdo.RESPONSE_TIMEOUT = s.sdo_timeout_s
            node.TIMEOUT_SWITCH_STATE_FINAL = s.state_timeout_s
            node.TIMEOUT_SWITCH_STATE_SINGLE = s.state_timeout_s
            with device_step(self.name, "no answer to SDO upload of 0x1000 device type"):
                device_type = int(node.sdo[od.DEVICE_TYPE].raw)
            if device_type & 0xFFFF != 402:
                raise DeviceError(f"{self.name}: not a CiA 402 drive (0x1000 device type 0x{device_type:08X})")
            with device_step(self.name, "NMT PRE-OPERATIONAL / heartbeat set-up failed"):
                node.nmt.state = "PRE-OPERATIONAL"
                node.nmt.add_heartbeat_callback(self._on_heartbeat)
                node.sdo[od.HEARTBEAT_TIME].raw = max(1, round(s.heartbeat_period_s * 1000))
                node.nmt.wait_for_heartbeat(s.heartbeat_timeout_s)
            overflow = enable_sync_counter(node, self.name, SYNC_COUNTER_OVERFLOW, self._info)
            cob_id, _ = map_tpdo(self._network, node, self.name, s)
            set_profile_position(node, self.name, s.state_timeout_s)
            if self._limits is not None:
                write_limits(node, self.name, self._limits, s.velocity_units_per_rpm)
                check_position_frame(node, self.name, self._info)
            self._capture = FrameCapture(with_counter=overflow > 0, max_frames=QUEUE_FRAMES)
            self._network.subscribe(SYNC_COB_ID, self._capture.on_sync)
            self._network.subscribe(cob_id, self._capture.on_tpdo)
            with device_step(self.name, "NMT OPERATIONAL / SYNC start failed"):
                node.nmt.state = "OPERATIONAL"
                self._wait_operational_heartbeat()
                self._sync = SyncProducer(self._network.bus, s.period_s, overflow)
                first_sync_ns = time.monotonic_ns()
                self._sync.start()
                self._wait_first_sync(self._s.heartbeat_timeout_s, "the interface does not echo the host's own SYNC "
                                      "frames (receive_own_messages), so TPDOs cannot be paired with their SYNC")
            unwrapper = SyncUnwrapper(overflow or None, s.period_s, first_sync_ns)
            self._decoder = TpdoDecoder(unwrapper, s.map_velocity, self._cpr / 60.0 / s.velocity_units_per_rpm,
                                        with_timestamp=s.map_timestamp)
        except BaseException:
            self.stop()
            raise
        return DriveInfo(period_s=s.period_s, counts_per_rev=self._cpr, transport="canopen",
                         timestamp_kind="sync_counter", device=self.name)

    def _open_bus(self) -> None:
        s = self._s
        with device_step(self.name, f"cannot open the CAN interface at {s.bitrate / 1000:g} kbit/s"):
            self._network = canopen.Network()
            self._network.listeners.append(self._raw)
            self._network.connect(interface=s.interface, channel=s.channel, bitrate=s.bitrate,
                                  receive_own_messages=True)

    def _start_listening(self) -> DriveInfo:
        """Record the master's TPDO on the master's SYNC; send nothing (``configure``: SDO mapping only)."""
        s = self._s
        try:
            self._open_bus()
            if s.configure:
                node = node402(s.node_id)
                self._network.add_node(node)  # subscribes to the drive's SDO answers; sends nothing by itself
                self._node = node
                node.sdo.RESPONSE_TIMEOUT = s.sdo_timeout_s
                cob_id, entries = map_tpdo(self._network, node, self.name, s)
                source = f"TPDO{s.tpdo} mapped by acq (SDO)"
            else:
                assert self._passive is not None  # open_drive resolves it
                cob_id, entries, source = self._passive.cob_id, list(self._passive.entries), self._passive.source
            layout = TpdoLayout.from_entries(entries)
            overflow = s.sync_counter_overflow
            self._capture = FrameCapture(with_counter=overflow > 0, max_frames=QUEUE_FRAMES)
            self._network.subscribe(SYNC_COB_ID, self._capture.on_sync)
            self._network.subscribe(cob_id, self._capture.on_tpdo)
            self._wait_first_sync(s.state_timeout_s, "no SYNC from the machine's master (is the machine running, "
                                  "on this bus?)")
            if (self._capture.first_sync_bytes > 0) != (overflow > 0):
                raise DeviceError(
                    f"{self.name}: the master's SYNC carries {self._capture.first_sync_bytes} data byte(s) but [drive] "
                    f"sync_counter_overflow = {overflow} — set it to the master's 0x1019 value (0: a SYNC without counter)")
            unwrapper = SyncUnwrapper(overflow or None, s.period_s, self._capture.first_sync_ns)
            self._decoder = TpdoDecoder(unwrapper, False, self._cpr / 60.0 / s.velocity_units_per_rpm, layout=layout)
        except BaseException:
            self.stop()
            raise
        self._event("info", f"listen-only: COB-ID 0x{cob_id:X} mapping {od.entries_text(entries)} ({source}), SYNC of the "
                            "machine's master; no NMT, SYNC, SDO write or motion command sent"
                            + (" after the SDO mapping" if s.configure else ""))
        return DriveInfo(period_s=s.period_s, counts_per_rev=self._cpr, transport="canopen",
                         timestamp_kind="sync_counter", device=self.name)

    def keep_raw_frames(self, session_path: Path) -> Path:
        """Write every CAN frame of the session (from bus open) to ``<session>.can.blf``; return its path."""
        path = Path(session_path).with_suffix(".can.blf")
        self._raw.open(path)
        self._event("info", f"raw CAN frames in {path.name}")
        return path

    def start_motion(self, profile: Profile) -> None:
        """Set the profile-position ramps, enable (CiA 402), run the triangle until :meth:`stop_motion`."""
        if self._s.motion == "external":
            raise ConfigError("[drive] motion = \"external\": the machine's master moves the drive, acq never "
                              "commands motion")
        self._motion.start(profile)

    def read(self, timeout_s: float) -> EncoderBlock | None:
        """TPDO samples received since the last read (batched ~50 ms), or None after ``timeout_s`` (s).

        Raises :class:`DeviceError` after a heartbeat loss or another failure, once the samples
        received before it have been returned.
        """
        frames = self._collect(0.0 if self._failure else timeout_s)
        self._raw.drain()
        self._check_health()
        block = self._decoder.decode(frames) if frames and self._decoder is not None else None
        self._report_limits()
        self._report_counters()
        if self._failure is not None and block is None:
            raise self._failure
        return block

    def stop_motion(self) -> None:
        """Stop issuing targets, quick stop on the 0x6085 ramp, disable voltage. Idempotent."""
        if self._motion is not None:
            self._motion.stop()

    def stop(self) -> None:
        """Disable, stop SYNC, back to PRE-OPERATIONAL, close the bus and the raw log. Idempotent."""
        errors: list[str] = []
        try:
            self.stop_motion()
        except AcqError as e:
            errors.append(str(e))
        if self._sync is not None:
            self._sync.stop()
            self._sync = None
        if self._network is not None:
            try:
                if self._node is not None and self._s.motion == "commanded":  # listening: the master owns NMT
                    self._node.nmt.state = "PRE-OPERATIONAL"
            except Exception as e:  # noqa: BLE001 - the bus may be gone; close it anyway
                errors.append(f"NMT PRE-OPERATIONAL failed: {e}")
            self._network.disconnect()
            self._network = None
        self._raw.stop()
        self._report_limits(final=True)
        for e in errors:
            self._event("error", e)

    def events(self) -> list[StreamEvent]:
        """Return and forget the events noticed since the last call."""
        with self._events_lock:
            out, self._events = self._events, []
        return out

    # ---- start-up waits (the SDO steps: drivers.canopen_setup) -------------------------------------
    def _wait_operational_heartbeat(self) -> None:
        """Wait for a heartbeat reporting OPERATIONAL (one in flight may still say PRE-OPERATIONAL)."""
        deadline = time.monotonic() + self._s.heartbeat_timeout_s
        while self._hb_state != NMT_OPERATIONAL:
            if time.monotonic() > deadline:
                raise DeviceError(f"{self.name}: no heartbeat in NMT OPERATIONAL within "
                                  f"{self._s.heartbeat_timeout_s:g} s (last state {self._hb_state})")
            self._node.nmt.wait_for_heartbeat(self._s.heartbeat_timeout_s)

    def _wait_first_sync(self, timeout_s: float, why: str) -> None:
        """Wait for a SYNC on the bus (acq's own, echoed by ``receive_own_messages``, or the master's); the
        DeviceError says ``why`` none came within ``timeout_s`` (s)."""
        deadline = time.monotonic() + timeout_s
        while self._capture.syncs == 0:
            if time.monotonic() > deadline:
                raise DeviceError(f"{self.name}: no SYNC within {timeout_s:g} s: {why}")
            time.sleep(self._s.period_s)

    # ---- streaming health --------------------------------------------------------------------------
    def _on_heartbeat(self, nmt_state: int) -> None:
        self._hb_ns, self._hb_state = time.monotonic_ns(), nmt_state

    def _collect(self, timeout_s: float) -> list[tuple[int, bytes, int, int]]:
        if self._capture is None:
            return []
        q, out = self._capture.frames, []
        try:
            out.append(q.get(timeout=timeout_s) if timeout_s > 0 else q.get_nowait())
            end = time.monotonic() + BATCH_S
            while (left := end - time.monotonic()) > 0:
                out.append(q.get(timeout=left))
        except queue.Empty:
            pass
        while True:
            try:
                out.append(q.get_nowait())
            except queue.Empty:
                return out

    def _check_health(self) -> None:
        if self._failure is not None or self._capture is None or self._s.motion == "external":
            return
        age_s = (time.monotonic_ns() - self._hb_ns) * 1e-9
        if age_s > self._s.heartbeat_timeout_s:
            self._fail(DeviceError(f"{self.name}: heartbeat lost (none for {age_s:.2f} s, timeout "
                                   f"{self._s.heartbeat_timeout_s:g} s)"))
        elif self._hb_state != NMT_OPERATIONAL:
            self._fail(DeviceError(f"{self.name}: drive left NMT OPERATIONAL (heartbeat state {self._hb_state})"))

    def _fail(self, error: DeviceError) -> None:
        """Stop the SYNC stream and the drive; :meth:`read` raises ``error`` once the queue is drained."""
        if self._failure is not None:
            return
        self._failure = error
        self._event("error", str(error))
        try:
            if self._motion is not None:
                self._motion.quick_stop_and_disable()
        except AcqError as e:
            self._event("error", str(e))
        if self._sync is not None:
            self._sync.stop()

    def _report_limits(self, final: bool = False) -> None:
        """The "internal limit active" spans of a statusword mapped in the recorded TPDO (a master's, listening) as
        events; ``final``: also one still open. acq's own TPDO maps none: the motion polls the statusword
        (:mod:`drivers.canopen_motion`)."""
        if self._decoder is None or self._capture is None:
            return
        for start_ns, end_ns in self._decoder.take_limit_spans(final):
            self._add_event(limit_event(start_ns, end_ns, self._capture.first_sync_ns, "the first SYNC"))

    def _report_counters(self) -> None:
        if self._capture is None or self._decoder is None:
            return
        now = {"overruns": self._capture.overruns, "errors": self._capture.errors,
               "bad_length": self._decoder.bad_length}
        what = {"overruns": "TPDO frames dropped: receive queue full (overrun)",
                "errors": "errors in the CAN receive callback (see log)",
                "bad_length": "TPDO frames of the wrong length skipped"}
        for key, value in now.items():
            if value > self._reported[key]:
                self._event("warning", f"{value - self._reported[key]} {what[key]}", "encoder")
                self._reported[key] = value

    def _info(self, detail: str) -> None:
        self._event("info", detail)

    def _event(self, kind: EventKind, detail: str, stream: StreamName = "drive") -> None:
        self._add_event(StreamEvent(time.monotonic_ns(), stream, kind, detail))

    def _add_event(self, event: StreamEvent) -> None:
        with self._events_lock:
            self._events.append(event)


def open_drive(bench: Bench, sim_bench: object, fast: bool) -> CanopenDrive:
    """Registry factory: a CANopen drive on ``[drive] interface``/``channel`` (``sim_bench`` and ``fast``
    unused: a simulated node is put on the bus by :mod:`drivers.sim.peers`, chosen by the registry).
    Refuses (``ConfigError``) a bus load above ``max_bus_load`` (the rules between keys are validators of
    :class:`DriveCanopen`) and a commanding drive without ``[limits]``; listening, reads the master's TPDO from the
    config or the EDS/DCF first."""
    s = bench.drive
    assert isinstance(s, DriveCanopen)
    if s.motion == "external":  # acq adds no cyclic traffic: the load is the machine's
        passive = None if s.configure else passive_tpdo(s)
        return CanopenDrive(s, s.counts_per_rev or bench.encoder.counts_per_rev, passive)
    check_bus_load(s)
    limits = bench.motion_limits()
    if limits is None:  # acq never enables a drive it has not told the joint's limits
        raise ConfigError(f"bench config: {missing_limits(bench)}")
    return CanopenDrive(s, s.counts_per_rev or bench.encoder.counts_per_rev, limits=limits, gear_ratio=bench.gear.ratio)
