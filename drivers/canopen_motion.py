"""CiA 402 motion of one CANopen drive: enable, the triangle by Profile Position, quick stop + disable.

canopen's :class:`~canopen.profiles.p402.BaseNode402` walks the state machine (timeouts from
``state_timeout_s``); the rest is here. The triangle is a loop of alternating absolute targets 0x607A
with the new-set-point handshake: wait until statusword bit 12 (set-point acknowledge) is clear —
the drive's set-point buffer is free — write the target, raise controlword bit 4, wait for bit 12,
lower bit 4. With change-set-immediately (bit 5) clear the drive buffers the next target while the
present move runs, so its own generator makes back-to-back ramps (0x6081/0x6083/0x6084). A
``dwell_s`` waits for target reached (bit 10) and the dwell before the next target.

Speed dither (profile ``speed_dither`` > 0): full cycle c runs to p0 + round(s_c·swing) and back to p0 (the
same start every cycle: no drift), with 0x6081/0x6083/0x6084 at s_c times the nominal ones
(:func:`drivers.motion.speed_factors`), each written and read back before the cycle's first target. They are
written once the set-point buffer is free (bit 12 clear), while the previous cycle's return move runs, so
they must act from the next new set-point on: CiA 402 drives latch the profile parameters with the
set-point (the simulated drive, :mod:`drivers.sim.can_node`, does). A drive that applied them to the move in
progress would run the end of each return move at the next cycle's ramps — its position targets, and so the
return to p0, stay exact; with a ``dwell_s`` the parameters are written at rest and any drive applies them
to the intended move.

Travel limit: before the drive is enabled, 0x607D software position limits are set to the start position ∓ the
bench's ``[limits] max_travel_deg`` (in position units, as 0x6064/0x607A count them) and read back, so the drive itself
refuses a target beyond them; a range that would leave int32 is refused (home the drive nearer 0).

Internal limit: every statusword the motion polls (by SDO, every ``STATUS_POLL_S`` while it waits on a set-point or a
target) is watched for bit 11 "internal limit active" (CiA 402: the drive holds a torque, speed or position limit —
0x6072, 0x607F, 0x607D); each span it stays set is one :func:`drivers.base.limit_event` in the session, from the
first poll that saw it set to the first that saw it clear (or the last poll of the motion). The polls see a span to
within a poll and its SDO round trip; a span shorter than that may pass unseen.

All SDO traffic of the motion goes through one lock (the motion thread and a stop from any other
thread share canopen's SDO client). Every stop is a quick stop on the 0x6085 ramp, a wait for rest
(SWITCH ON DISABLED, or QUICK STOP ACTIVE with target reached), then disable voltage, verified.
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any

from drivers import canopen_od as od
from drivers.base import SW_INTERNAL_LIMIT, LimitSpans, StreamEvent, limit_event
from drivers.config import DriveCanopen, Profile
from acqcore.errors import AcqError, ConfigError, DeviceError
from drivers.motion import half_swing_rad, speed_factors, with_dither_seed

STATUS_POLL_S = 0.01
SW_TARGET_REACHED = 1 << 10
SW_SETPOINT_ACK = 1 << 12
CW_ENABLE = 0x000F
CW_NEW_SETPOINT = 0x0010
CW_QUICK_STOP = 0x0002
CW_DISABLE_VOLTAGE = 0x0000


@contextmanager
def device_step(device: str, what: str) -> Iterator[None]:
    """Turn canopen / python-can failures into one-line :class:`DeviceError` s naming device and step."""
    import can
    from canopen.nmt import NmtError
    from canopen.sdo import SdoAbortedError, SdoCommunicationError

    try:
        yield
    except AcqError:
        raise
    except (SdoAbortedError, SdoCommunicationError, NmtError, can.CanError, RuntimeError, ValueError, OSError) as e:
        raise DeviceError(f"{device}: {what}: {e}") from None


def node402(node_id: int) -> Any:
    """A ``BaseNode402`` with acq's object dictionary that reads the statusword by SDO: acq maps no
    statusword PDO, and canopen would log a warning on every read of its fallback."""
    from canopen.profiles.p402 import BaseNode402

    class Node402(BaseNode402):
        @property
        def statusword(self) -> int:
            return int(self.sdo[od.STATUSWORD].raw)

    return Node402(node_id, od.drive_object_dictionary(node_id))


def _int32(value: int) -> int:
    return (value + 2**31) % 2**32 - 2**31


#: How far from the start of acq's earlier motion (the centre of the 0x607D window it left in the drive) a new start
#: may be, as a share of [limits] max_travel_deg: a motion that ran to its end stands at its start within its position
#: loop's error (counts); one cut short stands up to a whole swing away. 1 % of the travel (1.35° of a 135° joint).
RETURN_SHARE = 0.01


class ProfilePositionMotion:
    """Motion of ``node`` (a started :func:`node402`) for a drive named ``device`` in messages.

    ``on_failure`` is called (from the motion thread) with the error that ended the motion after
    the drive was stopped; ``on_info`` with one-line notes for the session's events; ``on_event`` with the
    "internal limit active" spans (:func:`drivers.base.limit_event`).
    """

    def __init__(self, node: Any, device: str, settings: DriveCanopen, counts_per_rev: int,
                 on_failure: Callable[[DeviceError], None], on_info: Callable[[str], None],
                 travel_counts: int | None = None, on_event: Callable[[StreamEvent], None] | None = None) -> None:
        self._node, self._name, self._s, self._cpr = node, device, settings, counts_per_rev
        self._travel_counts = travel_counts  # [limits] max_travel_deg in position units (0x607D around the start)
        self._on_failure, self._on_info, self._on_event = on_failure, on_info, on_event
        self._motion_start_ns = 0
        self._limit_spans = LimitSpans()
        self.sdo_lock = threading.RLock()
        self._halt_lock = threading.Lock()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._enabled = False
        self._stop_time_s = settings.state_timeout_s

    def start(self, profile: Profile) -> None:
        """Set the ramps from ``profile``, enable, and run the triangle in a thread until :meth:`stop`.

        A dithered profile without a ``dither_seed`` gets one drawn here (the recorder draws it before)."""
        if profile.jerk_time_s:
            raise ConfigError(f"profile: jerk_time_s = {profile.jerk_time_s:g} s, but profile position mode "
                              "(0x6083/0x6084) has no jerk limit; set jerk_time_s = 0 for a CANopen drive")
        profile = with_dither_seed(profile)
        s, node = self._s, self._node
        decel = round(profile.top_speed_rpm / profile.decel_time_s * s.acceleration_units_per_rpm_per_s)
        self._stop_time_s = s.state_timeout_s + profile.decel_time_s * profile.max_speed_factor  # the fastest cycle
        try:
            with self.sdo_lock, device_step(self._name, "setting the profile-position parameters failed"):
                self._set_ramps(profile, float(speed_factors(profile, 0)))
                node.sdo[od.QUICK_STOP_DECELERATION].raw = decel
                p0 = int(node.sdo[od.POSITION_ACTUAL].raw)
                if self._travel_counts is not None:
                    self._set_position_limits(p0, self._travel_counts)
            with self.sdo_lock, device_step(self._name, f"did not reach OPERATION ENABLED within {s.state_timeout_s:g} s"):
                self._enabled = True
                node.state = "OPERATION ENABLED"
        except BaseException:
            self.quick_stop_and_disable()
            raise
        self._stop.clear()
        self._motion_start_ns, self._limit_spans = time.monotonic_ns(), LimitSpans()
        self._thread = threading.Thread(target=self._run_triangle, args=(p0, profile),
                                        name="acq-canopen-motion", daemon=True)
        self._thread.start()

    def _set_ramps(self, profile: Profile, factor: float) -> None:
        """Write 0x6081/0x6083/0x6084 for ``profile`` at ``factor`` times its top speed and read them back (a drive
        that clamps a value, e.g. to its 0x607F limit, would run another motion than the one recorded). A read-back
        one unit off is accepted: a drive that keeps the value in its own internal units rounds it on the way back."""
        s, top_rpm = self._s, profile.top_speed_rpm * factor
        wanted = {od.PROFILE_VELOCITY: round(top_rpm * s.velocity_units_per_rpm),
                  od.PROFILE_ACCELERATION: round(top_rpm / profile.accel_time_s * s.acceleration_units_per_rpm_per_s),
                  od.PROFILE_DECELERATION: round(top_rpm / profile.decel_time_s * s.acceleration_units_per_rpm_per_s)}
        for index, value in wanted.items():
            self._node.sdo[index].raw = value
        for index, value in wanted.items():
            if abs((got := int(self._node.sdo[index].raw)) - value) > 1:
                raise DeviceError(f"{self._name}: 0x{index:04X} reads back {got} after {value} was written "
                                  f"(the drive limits it?)")

    def _set_position_limits(self, p0: int, travel: int) -> None:
        """0x607D software position limits p0 − ``travel`` … p0 + ``travel`` + 1 (position units) around the start
        ``p0``, written while the drive is disabled and read back: the drive itself then refuses to go further than
        [limits] max_travel_deg. The one count more above marks the window as acq's (a width of 2·travel + 1).

        The window stays in the drive when acq stops, and it is what keeps the joint from walking: a motion cut short
        stops up to a swing from its start, and a window centred on each new start would let the next run go a swing
        further (the review: three runs cut at 0.12 s reached 89.7° against ±30°). So acq's own window found in the
        drive is kept, and a start away from its centre is refused. A window someone else set (the joint's stops,
        from the integrator) is left as it is — the drive keeps to it, acq's host check keeps to max_travel_deg — and
        a start outside it is refused.
        """
        limits = self._node.sdo[od.SOFTWARE_POSITION_LIMIT]
        held = (int(limits[1].raw), int(limits[2].raw))
        if held[0] < held[1] and held != (-2**31, 2**31 - 1):  # a window is set in the drive
            if held[1] - held[0] == 2 * travel + 1:  # acq's own, left by an earlier start: that start stays the reference
                centre = held[0] + travel
                if abs(p0 - centre) > RETURN_SHARE * travel:
                    raise DeviceError(
                        f"{self._name}: the joint stands {100 * (p0 - centre) / travel:+.0f} % of [limits] "
                        f"max_travel_deg from where acq's earlier motion started (position {p0}, the centre of the "
                        f"0x607D window {held[0]} … {held[1]} acq left in the drive): bring it back there before acq "
                        "moves it again, or clear 0x607D (or power-cycle the drive) if it was moved there on purpose")
                return
            if not held[0] <= p0 <= held[1]:
                raise DeviceError(f"{self._name}: the joint stands at {p0}, outside the drive's own software position "
                                  f"limits 0x607D {held[0]} … {held[1]}: bring it inside before acq moves it")
            return  # the integrator's stops: kept as they are
        low, high = p0 - travel, p0 + travel + 1
        if low < -2**31 or high > 2**31 - 1:
            raise DeviceError(f"{self._name}: 0x607D software position limits {low} … {high} (start {p0} ± {travel} "
                              "counts, [limits] max_travel_deg) leave the drive's 32-bit position range — home the "
                              "drive nearer 0")
        limits[1].raw, limits[2].raw = low, high
        got = (int(limits[1].raw), int(limits[2].raw))
        if got != (low, high):
            raise DeviceError(f"{self._name}: 0x607D software position limits read back {got[0]} … {got[1]} after "
                              f"{low} … {high} were written ([limits] max_travel_deg)")

    def stop(self) -> None:
        """Stop issuing targets, then quick stop and disable. Idempotent."""
        self._stop.set()
        if self._thread is not None and self._thread is not threading.current_thread():
            self._thread.join(self._stop_time_s + 4 * self._s.sdo_timeout_s)
        self.quick_stop_and_disable()

    def quick_stop_and_disable(self) -> None:
        """Quick stop (controlword 0x0002), wait for rest, disable voltage, verify. Idempotent."""
        self._stop.set()
        with self._halt_lock:
            if not self._enabled:
                return
            node, timeout = self._node, self._stop_time_s
            with self.sdo_lock, device_step(self._name, "quick stop / disable failed"):
                node.controlword = CW_QUICK_STOP
                deadline = time.monotonic() + timeout
                while (sw := int(node.statusword)) & 0x4F != 0x40 and not (sw & 0x6F == 0x07 and sw & SW_TARGET_REACHED):
                    if time.monotonic() > deadline:
                        raise DeviceError(f"{self._name}: not at rest {timeout:g} s after quick stop "
                                          f"(statusword 0x{sw:04X})")
                    time.sleep(STATUS_POLL_S)
                node.controlword = CW_DISABLE_VOLTAGE
                node.state = "SWITCH ON DISABLED"
            self._enabled = False
            self._on_info("drive quick-stopped and disabled (SWITCH ON DISABLED)")

    def _wait_status(self, mask: int, value: int, timeout_s: float | None, what: str) -> bool:
        """Poll the statusword until ``sw & mask == value``; False if stopped, DeviceError after timeout."""
        deadline = None if timeout_s is None else time.monotonic() + timeout_s
        while not self._stop.is_set():
            with self.sdo_lock:
                sw = int(self._node.statusword)
            self._limit_spans.see(bool(sw & SW_INTERNAL_LIMIT), time.monotonic_ns())
            self._report_limit_spans()
            if sw & 0x6F != 0x27:
                raise DeviceError(f"{self._name}: drive left OPERATION ENABLED during the motion (statusword 0x{sw:04X})")
            if sw & mask == value:
                return True
            if deadline is not None and time.monotonic() > deadline:
                raise DeviceError(f"{self._name}: {what} within {timeout_s:g} s (statusword 0x{sw:04X})")
            self._stop.wait(STATUS_POLL_S)
        return False

    def _report_limit_spans(self, final: bool = False) -> None:
        """Each "internal limit active" span that ended (``final``: also one still open) as an event."""
        for start_ns, end_ns in self._limit_spans.take(final):
            if self._on_event is not None:
                self._on_event(limit_event(start_ns, end_ns, self._motion_start_ns))

    def _run_triangle(self, p0: int, profile: Profile) -> None:
        """Alternate absolute targets p0 + round(s_c·swing) and p0 with the new-set-point handshake until stopped;
        with dither the ramps of cycle c ≥ 1 are set before its first target."""
        swing = round(half_swing_rad(profile) / (2 * math.pi) * self._cpr)
        dithered = profile.speed_dither > 0
        try:
            for n in range(2**62):
                cycle, back = divmod(n, 2)
                if profile.dwell_s > 0:
                    if not self._wait_status(SW_TARGET_REACHED, SW_TARGET_REACHED, None, "target not reached"):
                        return
                    if self._stop.wait(profile.dwell_s):
                        return
                if not self._wait_status(SW_SETPOINT_ACK, 0, None, "set-point buffer never freed"):
                    return
                factor = float(speed_factors(profile, cycle))
                with self.sdo_lock:
                    if dithered and cycle > 0 and not back:
                        with device_step(self._name, f"setting the ramps of cycle {cycle} failed"):
                            self._set_ramps(profile, factor)
                    self._node.sdo[od.TARGET_POSITION].raw = _int32(p0 if back else p0 + round(factor * swing))
                    self._node.controlword = CW_ENABLE | CW_NEW_SETPOINT
                acked = self._wait_status(SW_SETPOINT_ACK, SW_SETPOINT_ACK, self._s.state_timeout_s,
                                          "set-point not acknowledged")
                with self.sdo_lock:
                    self._node.controlword = CW_ENABLE
                if not acked:
                    return
        except Exception as e:  # noqa: BLE001 - any failure stops the drive and ends the recording
            error = e if isinstance(e, DeviceError) else DeviceError(f"{self._name}: motion failed: {e}")
            try:
                self.quick_stop_and_disable()
            except AcqError as stop_error:
                self._on_info(str(stop_error))
            self._on_failure(error)
        finally:  # a limit still active when the motion ends: its span as far as the polls saw it
            self._report_limit_spans(final=True)
