"""Which gap-free run of each stream the analysis uses: of every pair of an encoder span and a DAQ run, the one in
which both streams have data the longest.

A hole in one stream (a damaged chunk, a lost read) splits it into runs. Each stream's longest run, taken apart, can
lie on the other side of a hole in the other stream (current 4.9–10 s, encoder 0–5.0 s: they share 0.1 s, where the
current's first run and the encoder's share 4.8 s). The runs are related before the clocks are aligned, in the
streams' own time — drive time k·T of the encoder's cycle k, DAQ time n/rate of sample n — through the host clock's
relation when the streams share one (:func:`analysis.clock_host.host_relation`: within milliseconds), else as started
together (no drift). When no pair shares any time by that relation (it can be off by a clock offset no host clock
resolves), each stream's longest run is used, as the clock alignment then decides.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from analysis.clock_host import HostRelation
from analysis.encoder import Span, gap_free_spans
from analysis.recording import Recording


@dataclass(frozen=True)
class DaqRun:
    """A gap-free run of DAQ samples.

    Attributes
    ----------
    first_index : int
        DAQ sample index of its first sample.
    start, stop : int
        Array positions of the run in the recording's phases, ``stop`` exclusive.
    """

    first_index: int
    start: int
    stop: int

    @property
    def count(self) -> int:
        """Samples in the run."""
        return self.stop - self.start


def daq_runs(rec: Recording) -> list[DaqRun]:
    """Every gap-free run of DAQ blocks (a block whose first sample index is not the previous block's end starts a
    new one), in order; the whole record as one run without a block table."""
    n = rec.current_a["i_a"].size
    if rec.block_first_index is None or rec.block_count is None or rec.block_first_index.size == 0:
        return [DaqRun(0, 0, n)]
    first = np.asarray(rec.block_first_index, dtype=np.int64)
    count = np.asarray(rec.block_count, dtype=np.int64)
    starts = np.concatenate(([0], np.cumsum(count)[:-1]))
    breaks = np.flatnonzero(first[1:] != first[:-1] + count[:-1]) + 1
    edges = np.concatenate(([0], breaks, [first.size]))
    return [DaqRun(int(first[a]), int(starts[a]), int(starts[a] + count[a:b].sum()))
            for a, b in zip(edges[:-1], edges[1:])]


def shared_runs(rec: Recording, relation: HostRelation | None) -> tuple[Span, DaqRun]:
    """The encoder span and the DAQ run that share the most time (the first such pair), each stream's longest when no
    pair shares any.

    Parameters
    ----------
    rec : Recording
        The recording (its encoder index and DAQ block table).
    relation : HostRelation or None
        Offset, s, and drift, ppm, of t_drive = offset + t_daq·(1 + drift·10⁻⁶) from the host stamps; None: the
        streams taken as started together (the first encoder cycle with the first DAQ sample, no drift).
    """
    spans, runs = gap_free_spans(rec.encoder_index), daq_runs(rec)
    cycles = np.asarray(rec.encoder_index, dtype=np.int64)
    if relation is None:  # started together: the record's first encoder cycle with its first DAQ sample (an imported
        # encoder keeps the drive's cycle numbers, which need not start at 0)
        offset_s = float(cycles[0]) * rec.period_s - min(r.first_index for r in runs) / rec.rate_hz
        drift_ppm = 0.0
    else:
        offset_s, drift_ppm = relation.offset_s, relation.drift_ppm
    scale = (1.0 + drift_ppm * 1e-6) / rec.rate_hz
    enc_lo = np.array([cycles[s.start] for s in spans]) * rec.period_s
    enc_hi = np.array([cycles[s.stop - 1] for s in spans]) * rec.period_s
    daq_lo = offset_s + np.array([r.first_index for r in runs]) * scale
    daq_hi = offset_s + np.array([r.first_index + r.count - 1 for r in runs]) * scale
    shared = np.minimum(enc_hi[:, None], daq_hi[None, :]) - np.maximum(enc_lo[:, None], daq_lo[None, :])
    if not np.max(shared) > 0.0:
        return max(spans, key=lambda s: s.count), max(runs, key=lambda r: r.count)
    e, d = np.unravel_index(int(np.argmax(shared)), shared.shape)
    return spans[int(e)], runs[int(d)]
