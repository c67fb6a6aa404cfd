"""The spans in which the drive reported holding the motor at one of its limits, as the analysis's verdict uses them.

A CiA 402 drive sets statusword bit 11 "internal limit active" while a torque (0x6072), speed (0x607F) or position
(0x607D) limit holds the motor; the recorder keeps each span as an event, and the application passes the spans in
:attr:`analysis.recording.Recording.drive_limited_host_ns` (host monotonic ns, the clock of ``encoder_host_ns``).
Inside such a span the torque read from the phase current as k_t·i_q is not known to be the motor's: a torque limit
is commonly set near the motor's peak torque, where k_t falls (magnetic saturation), and bit 11 does not say which
limit acted or how far into saturation the motor went. So a record with any such span gets a
reason naming it and the share of the record it covers (:func:`drive_limit_reason`), and its verdict is at best
``poor``; a record without one is untouched. A precaution, not a measured bias: the simulated drive clamps its torque
ideally (k_t constant), and there a 6 s record of ``triangle_0.2s`` with 19 % of it at a 7 N·m clamp still read
K = 897 N·m/rad (truth 891, interval 882–911) — the simulator cannot show what a real motor does at its limit.
"""

from __future__ import annotations

import numpy as np

from analysis.recording import Recording


def limited_share(spans_host_ns: np.ndarray, encoder_host_ns: np.ndarray) -> float:
    """Share (0…1) of the encoder samples whose host stamp lies in one of ``spans_host_ns`` (shape (n, 2): start, end,
    ns)."""
    if encoder_host_ns.size == 0:
        return 0.0
    inside = np.zeros(encoder_host_ns.size, dtype=bool)
    for start, end in spans_host_ns:
        inside |= (encoder_host_ns >= start) & (encoder_host_ns <= end)
    return float(np.mean(inside))


def drive_limit_reason(rec: Recording) -> str | None:
    """Why the record's identification is not ``ok`` because the drive held a limit in it; None without such a span."""
    spans = rec.drive_limited_host_ns
    if spans is None or len(spans) == 0:
        return None
    spans = np.asarray(spans, dtype=np.int64).reshape(-1, 2)
    total_s = float(np.sum(spans[:, 1] - spans[:, 0])) * 1e-9
    origin = spans[0, 0] if rec.encoder_host_ns is None or rec.encoder_host_ns.size == 0 else rec.encoder_host_ns[0]
    share = "" if rec.encoder_host_ns is None else f", {limited_share(spans, rec.encoder_host_ns):.0%} of the record"
    first = (spans[0] - origin) * 1e-9
    return (f"drive: internal limit active (CiA 402 0x6041 bit 11) in {len(spans)} span(s), {total_s:.2f} s in all"
            f"{share} (first from {first[0]:.2f} s to {first[1]:.2f} s): the drive held the motor at a torque, speed or "
            "position limit, where the torque read as k_t·i need not be the motor's — lengthen accel_time_s / "
            "decel_time_s or lower top_speed_rpm, or raise [limits] if the joint allows")
