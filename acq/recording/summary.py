"""What a session holds, in numbers: samples, durations, rates measured on the host clock and gaps per stream."""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np
from scipy.stats import theilslopes

from acq.recording.session import Session


#: Points (evenly spaced) the rate's line is fitted through: Theil–Sen takes every pair's slope, O(n²) in time and
#: memory; 1000 points (5·10⁵ slopes, 0.08 s) gave the 4 s CANopen session 1000.003 Hz, 2000 points 1000.004 Hz.
FIT_POINTS = 1000


@dataclass(frozen=True)
class StreamSummary:
    """One stream: samples stored, seconds covered, nominal and host-measured rates (Hz), gaps.

    ``effective_rate_hz`` is the samples between the first and the last host stamp over the time between them: a
    first sample that arrived late, or a burst, moves it (a CANopen drive's first TPDOs: 1004 Hz of a 1000 Hz
    stream). ``fitted_rate_hz`` is the slope of a robust line through every host stamp against its sample index
    (:func:`fitted_rate`), which neither moves."""

    name: str
    samples: int
    duration_s: float
    nominal_rate_hz: float
    effective_rate_hz: float
    gaps: int
    missing: int
    fitted_rate_hz: float = float("nan")


@dataclass(frozen=True)
class SessionSummary:
    """A session at a glance; ``encoder_extras`` names the optional encoder columns the drive gave (the drive's time
    stamps ``drive_time_s``, ``velocity_counts_per_s``, ``velocity_demand_counts_per_s``); ``speed_dither`` and
    ``dither_seed`` are those of the profile as executed (0 and None: a motion that repeats exactly, or none
    commanded — ``commanded`` False when the machine's own controller moved the joint)."""

    path: str
    joint: str
    status: str
    stop_reason: str
    created_utc: str
    streams: tuple[StreamSummary, ...]
    events: int
    encoder_extras: tuple[str, ...] = ()
    commanded: bool = True
    speed_dither: float = 0.0
    dither_seed: int | None = None

    def to_json_dict(self) -> dict[str, object]:
        return asdict(self)


def _gaps(index: np.ndarray) -> tuple[int, int]:
    steps = np.diff(index)
    jumps = steps[steps > 1]
    return int(jumps.size), int((jumps - 1).sum())


def _rate(span_samples: float, host_first_ns: int, host_last_ns: int) -> float:
    span_s = (host_last_ns - host_first_ns) * 1e-9
    return float(span_samples / span_s) if span_s > 0 else float("nan")


def fitted_rate(index: np.ndarray, host_ns: np.ndarray) -> float:
    """Samples per second of host time: 1 / the Theil–Sen slope (median of the pairwise slopes) of host stamp against
    sample index, through at most :data:`FIT_POINTS` evenly spaced samples; NaN with fewer than two.

    Host stamps lag the samples by a delay that varies (the bus, the driver, the scheduler): a late first sample or a
    burst makes a few stamps outliers, which the median of the slopes ignores while fewer than ~29 % of the points
    are (the estimator's breakdown point)."""
    if index.size < 2:
        return float("nan")
    step = -(-index.size // FIT_POINTS)  # rounded up: at most FIT_POINTS (1999 samples took all 1999, 0.2 s)
    i = (index[::step] - index[0]).astype(float)
    t_s = (host_ns[::step] - host_ns[0]).astype(float) * 1e-9
    slope_s = theilslopes(t_s, i).slope
    return float(1.0 / slope_s) if slope_s > 0 else float("nan")


def summarize(session: Session) -> SessionSummary:
    """Count samples and gaps from the stream indices; rates measured against the host clock."""
    cur, enc = session.current, session.encoder
    n_cur = cur.sample_count
    cur_gaps, cur_missing = _gaps(cur.sample_index())
    cur_rate = float("nan")
    # a block's host stamp: when the read of its last sample returned
    block_end = cur.block_first_index + cur.block_count
    if cur.block_count.size > 1:
        span = block_end[-1] - block_end[0]
        cur_rate = _rate(span, int(cur.block_host_ns[0]), int(cur.block_host_ns[-1]))
    n_enc = int(enc.index.size)
    enc_gaps, enc_missing = _gaps(enc.index)
    enc_rate = _rate(float(enc.index[-1] - enc.index[0]), int(enc.host_ns[0]), int(enc.host_ns[-1])) if n_enc > 1 else float("nan")
    streams = (
        StreamSummary("current", n_cur, n_cur / cur.rate_hz, cur.rate_hz, cur_rate, cur_gaps, cur_missing,
                      fitted_rate(block_end, cur.block_host_ns)),
        StreamSummary("encoder", n_enc, (n_enc + enc_missing) * enc.period_s, 1.0 / enc.period_s, enc_rate,
                      enc_gaps, enc_missing, fitted_rate(enc.index, enc.host_ns)),
    )
    return SessionSummary(
        path=str(session.path),
        joint=session.meta.joint or "",
        status=session.status,
        stop_reason=session.meta.stop_reason,
        created_utc=session.meta.created_utc or "",
        streams=streams,
        events=len(session.events),
        encoder_extras=tuple(name for name in ("drive_time_s", "velocity_counts_per_s", "velocity_demand_counts_per_s")
                             if getattr(enc, name) is not None),
        commanded=session.profile is not None,
        speed_dither=0.0 if session.profile is None else session.profile.speed_dither,
        dither_seed=None if session.profile is None else session.profile.dither_seed,
    )
