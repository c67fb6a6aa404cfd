"""A CiA 402 servo drive over CANopen (canopen ``BaseNode402`` on python-can), as a :class:`Drive`.

:meth:`CanopenDrive.start` (drive disabled throughout): open the bus, check the node is a CiA 402
device, NMT PRE-OPERATIONAL, producer heartbeat (0x1017), SYNC counter (0x1019 = 240, or plain SYNC
if the drive has no 0x1019), TPDO ``tpdo`` mapped to 0x6064 position actual (+ 0x606C velocity actual)
with transmission type 1 and **read back** (a differing mapping refuses to record), mode of operation
Profile Position **verified** on 0x6061 (canopen's own setter only logs a refusal), then NMT
OPERATIONAL and the SYNC producer. :meth:`~CanopenDrive.start_motion` sets 0x6081/0x6083/0x6084 (and
the quick-stop ramp 0x6085) from the profile, enables through the 402 state machine (timeouts from
``state_timeout_s``) and runs the triangle as alternating absolute targets 0x607A with the
new-set-point handshake (controlword bit 4 ↔ statusword bit 12, set-of-set-points: the next target is
buffered while the present move runs, so the drive's generator makes back-to-back 0.2 s ramps).

Safety: every stop — end of recording, any exception, Ctrl-C (through the recorder's
:meth:`stop_motion`), heartbeat loss, NMT state change, motion-thread failure — is a quick stop on
the 0x6085 ramp followed by disable voltage, verified on the statusword. Heartbeat loss and the
other failures seen while streaming surface as :class:`DeviceError` from :meth:`read` once the
frames received before are delivered (the recorder then ends the session ``failed``, data kept).

The encoder stream itself (SYNC counter, capture, decoding, raw ``.blf`` log) is
:mod:`drivers.canopen_stream`. Units: positions in drive position units (``counts_per_rev`` per
motor revolution), velocities ``velocity_units_per_rpm``, accelerations ``acceleration_units_per_rpm_per_s``.
"""

from __future__ import annotations

import math
import queue
import threading
import time
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING

from drivers.base import DriveInfo, EncoderBlock, EventKind, StreamEvent, StreamName
from drivers.config import Bench, DriveCanopen, Profile
from drivers.errors import AcqError, ConfigError, DeviceError
from drivers.motion import half_swing_rad

if TYPE_CHECKING:
    from drivers.sim.bench import SimBench
    from drivers.sim.can_node import SimCanNode

QUEUE_FRAMES = 20_000
BATCH_S = 0.05
STATUS_POLL_S = 0.01
NMT_OPERATIONAL = 5
SW_TARGET_REACHED = 1 << 10
SW_SETPOINT_ACK = 1 << 12
CW_ENABLE = 0x000F
CW_NEW_SETPOINT = 0x0010
CW_QUICK_STOP = 0x0002
CW_DISABLE_VOLTAGE = 0x0000


def frame_bits(data_bytes: int) -> int:
    """Worst-case length of a CAN 2.0A data frame on the wire, bits: 47 + 8·n plus stuff bits
    (one per 4 of the 34 + 8·n stuffed bits), interframe space included."""
    return 47 + 8 * data_bytes + (34 + 8 * data_bytes - 1) // 4


def bus_load(bitrate: float, period_s: float, tpdo_bytes: Sequence[int], *, sync_bytes: int = 1,
             heartbeat_period_s: float = 0.1, sdo_poll_s: float = STATUS_POLL_S) -> float:
    """Worst-case bus load (fraction of ``bitrate``, bit/s) of SYNC every ``period_s`` (s) with the
    TPDOs of ``tpdo_bytes`` answering each, a heartbeat and the motion thread's SDO status poll."""
    bits_per_s = ((frame_bits(sync_bytes) + sum(frame_bits(n) for n in tpdo_bytes)) / period_s
                  + frame_bits(1) / heartbeat_period_s + 2 * frame_bits(8) / sdo_poll_s)
    return bits_per_s / bitrate


def check_bus_load(s: DriveCanopen) -> float:
    """The load ``[drive]`` asks for; :class:`ConfigError` naming the figure if above ``max_bus_load``."""
    tpdo = [8 if s.map_velocity else 4]
    load = bus_load(s.bitrate, s.period_s, tpdo, heartbeat_period_s=s.heartbeat_period_s)
    if load > s.max_bus_load:
        raise ConfigError(
            f"[drive] CAN bus load {load:.0%} > max_bus_load {s.max_bus_load:.0%}: SYNC at {1 / s.period_s:g} Hz "
            f"with a {tpdo[0]}-byte TPDO at {s.bitrate / 1000:g} kbit/s (worst-case bit stuffing) — "
            "raise period_s or bitrate")
    return load


def _node402_class() -> type:
    from canopen.profiles.p402 import BaseNode402

    class Node402(BaseNode402):
        """``BaseNode402`` reading the statusword by SDO: acq maps no statusword PDO, and canopen
        would log a warning on every read of its fallback."""

        @property
        def statusword(self) -> int:
            return int(self.sdo[0x6041].raw)

    return Node402


class CanopenDrive:
    """A CiA 402 drive on a CAN bus (implements :class:`drivers.base.Drive`).

    Parameters
    ----------
    settings : the bench's ``[drive]`` section.
    counts_per_rev : drive position units per motor revolution.
    sim_node : the simulated drive to start and stop with this adapter (``simulated_node = true``).
    """

    def __init__(self, settings: DriveCanopen, counts_per_rev: int, sim_node: SimCanNode | None = None) -> None:
        from drivers import canopen_od as od

        self._s, self._cpr, self.sim_node = settings, counts_per_rev, sim_node
        self._od = od
        self.name = f"CANopen node {settings.node_id} on {settings.interface}:{settings.channel}"
        self._network = None
        self._node = None
        self._sync = None
        self._capture = None
        self._decoder = None
        from drivers.canopen_stream import RawFrameLog

        self._raw = RawFrameLog()
        self._events: list[StreamEvent] = []
        self._events_lock = threading.Lock()
        self._sdo_lock = threading.RLock()
        self._halt_lock = threading.Lock()
        self._motion_stop = threading.Event()
        self._motion_thread: threading.Thread | None = None
        self._enabled = False
        self._failure: DeviceError | None = None
        self._hb_ns = 0
        self._hb_state = 0
        self._reported = {"overruns": 0, "errors": 0, "bad_length": 0}
        self._stop_time_s = settings.state_timeout_s

    # ---- Drive protocol ----------------------------------------------------------------------------
    def start(self) -> DriveInfo:
        """Configure in PRE-OPERATIONAL, start the TPDO stream on SYNC (the drive stays disabled)."""
        import canopen

        from drivers.canopen_stream import SYNC_COB_ID, SYNC_COUNTER_OVERFLOW, FrameCapture, SyncProducer, SyncUnwrapper, TpdoDecoder

        s, od = self._s, self._od
        try:
            with self._step(f"cannot open the CAN interface at {s.bitrate / 1000:g} kbit/s"):
                self._network = canopen.Network()
                self._network.listeners.append(self._raw)
                self._network.connect(interface=s.interface, channel=s.channel, bitrate=s.bitrate,
                                      receive_own_messages=True)
            if self.sim_node is not None:
                self.sim_node.start()
            node = _node402_class()(s.node_id, od.drive_object_dictionary(s.node_id))
            self._network.add_node(node)
            self._node = node
            node.sdo.RESPONSE_TIMEOUT = s.sdo_timeout_s
            node.TIMEOUT_SWITCH_STATE_FINAL = s.state_timeout_s
            node.TIMEOUT_SWITCH_STATE_SINGLE = s.state_timeout_s
            with self._step("no answer to SDO upload of 0x1000 device type"):
                device_type = int(node.sdo[od.DEVICE_TYPE].raw)
            if device_type & 0xFFFF != 402:
                raise DeviceError(f"{self.name}: not a CiA 402 drive (0x1000 device type 0x{device_type:08X})")
            with self._step("NMT PRE-OPERATIONAL / heartbeat set-up failed"):
                node.nmt.state = "PRE-OPERATIONAL"
                node.nmt.add_heartbeat_callback(self._on_heartbeat)
                node.sdo[od.HEARTBEAT_TIME].raw = max(1, round(s.heartbeat_period_s * 1000))
                node.nmt.wait_for_heartbeat(s.heartbeat_timeout_s)
            overflow = self._enable_sync_counter(SYNC_COUNTER_OVERFLOW)
            cob_id = self._map_tpdo()
            self._set_profile_position()
            self._capture = FrameCapture(with_counter=overflow > 0, max_frames=QUEUE_FRAMES)
            self._network.subscribe(SYNC_COB_ID, self._capture.on_sync)
            self._network.subscribe(cob_id, self._capture.on_tpdo)
            with self._step("NMT OPERATIONAL / SYNC start failed"):
                node.nmt.state = "OPERATIONAL"
                self._wait_operational_heartbeat()
                self._sync = SyncProducer(self._network.bus, s.period_s, overflow)
                first_sync_ns = time.monotonic_ns()
                self._sync.start()
            unwrapper = SyncUnwrapper(overflow or None, s.period_s, first_sync_ns)
            self._decoder = TpdoDecoder(unwrapper, s.map_velocity, self._cpr / 60.0 / s.velocity_units_per_rpm)
        except BaseException:
            self.stop()
            raise
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
        s, od, node = self._s, self._od, self._node
        top_rpm = profile.top_speed_rpm
        accel = round(top_rpm / profile.accel_time_s * s.acceleration_units_per_rpm_per_s)
        decel = round(top_rpm / profile.decel_time_s * s.acceleration_units_per_rpm_per_s)
        self._stop_time_s = s.state_timeout_s + profile.decel_time_s
        try:
            with self._sdo_lock, self._step("setting the profile-position parameters failed"):
                node.sdo[od.PROFILE_VELOCITY].raw = round(top_rpm * s.velocity_units_per_rpm)
                node.sdo[od.PROFILE_ACCELERATION].raw = accel
                node.sdo[od.PROFILE_DECELERATION].raw = decel
                node.sdo[od.QUICK_STOP_DECELERATION].raw = decel
                p0 = int(node.sdo[od.POSITION_ACTUAL].raw)
            with self._sdo_lock, self._step(f"did not reach OPERATION ENABLED within {s.state_timeout_s:g} s"):
                self._enabled = True
                node.state = "OPERATION ENABLED"
        except BaseException:
            self._quick_stop_and_disable()
            raise
        swing = round(half_swing_rad(profile) / (2 * math.pi) * self._cpr)
        self._motion_stop.clear()
        self._motion_thread = threading.Thread(target=self._run_triangle, args=(p0, swing, profile.dwell_s),
                                               name="acq-canopen-motion", daemon=True)
        self._motion_thread.start()

    def read(self, timeout_s: float) -> EncoderBlock | None:
        """TPDO samples received since the last read (batched ~50 ms), or None after ``timeout_s`` (s).

        Raises :class:`DeviceError` after a heartbeat loss or another failure, once the samples
        received before it have been returned.
        """
        frames = self._collect(0.0 if self._failure else timeout_s)
        self._raw.drain()
        self._check_health()
        block = self._decoder.decode(frames) if frames and self._decoder is not None else None
        self._report_counters()
        if self._failure is not None and block is None:
            raise self._failure
        return block

    def stop_motion(self) -> None:
        """Stop issuing targets, quick stop on the 0x6085 ramp, disable voltage. Idempotent."""
        self._motion_stop.set()
        if self._motion_thread is not None and self._motion_thread is not threading.current_thread():
            self._motion_thread.join(self._stop_time_s + self._s.sdo_timeout_s * 4)
        self._quick_stop_and_disable()

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
                if self._node is not None:
                    self._node.nmt.state = "PRE-OPERATIONAL"
            except Exception as e:  # noqa: BLE001 - the bus may be gone; close it anyway
                errors.append(f"NMT PRE-OPERATIONAL failed: {e}")
            self._network.disconnect()
            self._network = None
        self._raw.stop()
        if self.sim_node is not None:
            self.sim_node.stop()
        for e in errors:
            self._event("error", e)

    def events(self) -> list[StreamEvent]:
        """Return and forget the events noticed since the last call."""
        with self._events_lock:
            out, self._events = self._events, []
        return out

    # ---- configuration -----------------------------------------------------------------------------
    @contextmanager
    def _step(self, what: str) -> Iterator[None]:
        """Turn canopen / python-can failures into one-line :class:`DeviceError` s naming the step."""
        import can
        from canopen.nmt import NmtError
        from canopen.sdo import SdoAbortedError, SdoCommunicationError

        try:
            yield
        except AcqError:
            raise
        except (SdoAbortedError, SdoCommunicationError, NmtError, can.CanError, RuntimeError, ValueError,
                OSError) as e:
            raise DeviceError(f"{self.name}: {what}: {e}") from None

    def _wait_operational_heartbeat(self) -> None:
        """Wait for a heartbeat reporting OPERATIONAL (one in flight may still say PRE-OPERATIONAL)."""
        deadline = time.monotonic() + self._s.heartbeat_timeout_s
        while self._hb_state != NMT_OPERATIONAL:
            if time.monotonic() > deadline:
                raise DeviceError(f"{self.name}: no heartbeat in NMT OPERATIONAL within "
                                  f"{self._s.heartbeat_timeout_s:g} s (last state {self._hb_state})")
            self._node.nmt.wait_for_heartbeat(self._s.heartbeat_timeout_s)

    def _enable_sync_counter(self, overflow: int) -> int:
        """0x1019 = ``overflow`` if the drive has it (then SYNC carries the counter), else 0."""
        from canopen.sdo import SdoAbortedError

        with self._step("writing 0x1019 SYNC counter overflow failed"):
            try:
                self._node.sdo[self._od.SYNC_OVERFLOW].raw = overflow
            except SdoAbortedError:
                self._event("info", "drive has no SYNC counter (0x1019): plain SYNC, the host counts them")
                return 0
        return overflow

    def _map_tpdo(self) -> int:
        """Map the TPDO (CiA 301 sequence via canopen), read it back, refuse a difference; its COB-ID."""
        s, od, node = self._s, self._od, self._node
        wanted = [od.map_entry(od.POSITION_ACTUAL, 32)] + ([od.map_entry(od.VELOCITY_ACTUAL, 32)] if s.map_velocity else [])
        cob_id = od.tpdo_cob_id(s.tpdo, s.node_id)
        pdo = node.tpdo[s.tpdo]
        with self._step(f"writing the TPDO{s.tpdo} mapping failed"):
            pdo.clear()
            for entry in wanted:
                pdo.add_variable(entry >> 16, 0, entry & 0xFF)
            pdo.cob_id, pdo.trans_type, pdo.enabled, pdo.rtr_allowed = cob_id, 1, True, False
            pdo.save()
            self._network.unsubscribe(cob_id, pdo.on_message)  # our capture reads this COB-ID, not canopen's map
        with self._step(f"reading the TPDO{s.tpdo} mapping back failed"):
            comm, mapping = node.sdo[od.TPDO_COMM + s.tpdo - 1], node.sdo[od.TPDO_MAP + s.tpdo - 1]
            got_cob, got_type = int(comm[1].raw), int(comm[2].raw)
            got = [int(mapping[i].raw) for i in range(1, int(mapping[0].raw) + 1)]
        if got != wanted or got_type != 1 or got_cob & 0x7FF != cob_id or got_cob & od.PDO_INVALID:
            raise DeviceError(
                f"{self.name}: TPDO{s.tpdo} read back differs from what was written — wrote {_entries(wanted)} "
                f"type 1 COB-ID 0x{cob_id:X}, read {_entries(got)} type {got_type} COB-ID 0x{got_cob:X}")
        return cob_id

    def _set_profile_position(self) -> None:
        """Mode of operation 1 (0x6060), verified on 0x6061 within ``state_timeout_s``."""
        od, node, timeout = self._od, self._node, self._s.state_timeout_s
        with self._step("checking 0x6502 supported drive modes failed"):
            supported = node.is_op_mode_supported("PROFILED POSITION")
        if not supported:
            raise DeviceError(f"{self.name}: the drive does not support Profile Position (0x6502)")
        with self._step("switching the mode of operation failed"):
            node.sdo[od.MODE].raw = od.MODE_PROFILE_POSITION
            deadline = time.monotonic() + timeout
            while (shown := int(node.sdo[od.MODE_DISPLAY].raw)) != od.MODE_PROFILE_POSITION:
                if time.monotonic() > deadline:
                    raise DeviceError(f"{self.name}: the drive refused Profile Position: 0x6061 mode display "
                                      f"is {shown}, not {od.MODE_PROFILE_POSITION}, {timeout:g} s after writing 0x6060")
                time.sleep(STATUS_POLL_S)

    # ---- motion ------------------------------------------------------------------------------------
    def _statusword(self) -> int:
        with self._sdo_lock:
            return int(self._node.statusword)

    def _wait_status(self, mask: int, value: int, timeout_s: float | None, what: str) -> bool:
        """Poll the statusword until ``sw & mask == value``; False if stopped, DeviceError after timeout."""
        deadline = None if timeout_s is None else time.monotonic() + timeout_s
        while not self._motion_stop.is_set():
            sw = self._statusword()
            if sw & 0x6F != 0x27:
                raise DeviceError(f"{self.name}: drive left OPERATION ENABLED during the motion (statusword 0x{sw:04X})")
            if sw & mask == value:
                return True
            if deadline is not None and time.monotonic() > deadline:
                raise DeviceError(f"{self.name}: {what} within {timeout_s:g} s (statusword 0x{sw:04X})")
            self._motion_stop.wait(STATUS_POLL_S)
        return False

    def _run_triangle(self, p0: int, swing: int, dwell_s: float) -> None:
        """Alternate absolute targets p0 + swing and p0 with the new-set-point handshake until stopped."""
        od, timeout = self._od, self._s.state_timeout_s
        target_of = (p0 + swing, p0)
        try:
            for n in range(2**62):
                if dwell_s > 0:
                    if not self._wait_status(SW_TARGET_REACHED, SW_TARGET_REACHED, None, "target not reached"):
                        return
                    if self._motion_stop.wait(dwell_s):
                        return
                if not self._wait_status(SW_SETPOINT_ACK, 0, None, "set-point buffer never freed"):
                    return
                with self._sdo_lock:
                    self._node.sdo[od.TARGET_POSITION].raw = _int32(target_of[n % 2])
                    self._node.controlword = CW_ENABLE | CW_NEW_SETPOINT
                acked = self._wait_status(SW_SETPOINT_ACK, SW_SETPOINT_ACK, timeout, "set-point not acknowledged")
                with self._sdo_lock:
                    self._node.controlword = CW_ENABLE
                if not acked:
                    return
        except Exception as e:  # noqa: BLE001 - any failure stops the drive and ends the recording
            self._fail(e if isinstance(e, DeviceError) else DeviceError(f"{self.name}: motion failed: {e}"))

    def _quick_stop_and_disable(self) -> None:
        """Quick stop (controlword 0x0002), wait for rest, disable voltage, verify. Idempotent."""
        with self._halt_lock:
            if not self._enabled:
                return
            node, timeout = self._node, self._stop_time_s
            with self._sdo_lock, self._step("quick stop / disable failed"):
                node.controlword = CW_QUICK_STOP
                deadline = time.monotonic() + timeout
                while (sw := int(node.statusword)) & 0x4F != 0x40 and not (sw & 0x6F == 0x07 and sw & SW_TARGET_REACHED):
                    if time.monotonic() > deadline:
                        raise DeviceError(f"{self.name}: not at rest {timeout:g} s after quick stop (statusword 0x{sw:04X})")
                    time.sleep(STATUS_POLL_S)
                node.controlword = CW_DISABLE_VOLTAGE
                node.state = "SWITCH ON DISABLED"
            self._enabled = False
            self._event("info", "drive quick-stopped and disabled (SWITCH ON DISABLED)")

    # ---- streaming health --------------------------------------------------------------------------
    def _on_heartbeat(self, nmt_state: int) -> None:
        self._hb_ns, self._hb_state = time.monotonic_ns(), nmt_state

    def _collect(self, timeout_s: float) -> list[tuple[int, bytes, int]]:
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
        if self._failure is not None or self._capture is None:
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
        self._motion_stop.set()
        try:
            self._quick_stop_and_disable()
        except AcqError as e:
            self._event("error", str(e))
        if self._sync is not None:
            self._sync.stop()

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

    def _event(self, kind: EventKind, detail: str, stream: StreamName = "drive") -> None:
        with self._events_lock:
            self._events.append(StreamEvent(time.monotonic_ns(), stream, kind, detail))


def _int32(value: int) -> int:
    return (value + 2**31) % 2**32 - 2**31


def _entries(entries: list[int]) -> str:
    return "[" + ", ".join(f"0x{e >> 16:04X}:{(e >> 8) & 0xFF:02X}/{e & 0xFF}" for e in entries) + "]"


def open_drive(bench: Bench, sim_bench: SimBench | None, fast: bool) -> CanopenDrive:
    """Registry factory. Refuses (``ConfigError``) a bus load above ``max_bus_load`` and, for the
    simulated node, ``--fast`` (a CAN bus runs in real time) and interfaces other than ``virtual``."""
    s = bench.drive
    assert isinstance(s, DriveCanopen)
    check_bus_load(s)
    if s.heartbeat_timeout_s <= s.heartbeat_period_s:
        raise ConfigError(f"[drive] heartbeat_timeout_s = {s.heartbeat_timeout_s:g} must exceed heartbeat_period_s "
                          f"= {s.heartbeat_period_s:g}")
    cpr = s.counts_per_rev or bench.encoder.counts_per_rev
    if not s.simulated_node:
        return CanopenDrive(s, cpr)
    if s.interface != "virtual":
        raise ConfigError(f"[drive] simulated_node = true needs interface = \"virtual\", not {s.interface!r}")
    if fast:
        raise ConfigError("--fast: the simulated CANopen drive runs on the bus in real time; record without --fast")
    from drivers.sim.can_node import SimCanNode

    assert sim_bench is not None
    return CanopenDrive(s, cpr, SimCanNode(bench, sim_bench))
