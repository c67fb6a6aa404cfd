"""How many Welch segments a coherence-based judgement needs, and the words for a record that averages fewer.

The verdict weighs a misfit against what noise explains, read from the coherence γ². With n averaged segments
of two unrelated signals γ̂² exceeds 1 − α^(1/(n−1)) with probability α (Carter, Knapp & Nuttall, "Estimation of the
magnitude-squared coherence function via overlapped FFT processing", 1973; for independent segments — Welch's 50 %
overlapped Hann segments are less so, so this is the least a record needs). Where that chance level lies above the
band's own coherence limit (:attr:`analysis.verdict_limits.Thresholds.coherence_poor`), a coherence at the limit cannot be
told from chance and neither can a misfit from noise: 2 segments give 0.95, 3 give 0.78, 4 give 0.63 against 0.72.
"""

from __future__ import annotations

import math

from analysis.frf import FrequencyResponse, segment_layout

#: Chance a coherence of unrelated signals exceeds the level :func:`chance_coherence` gives: 5 %, the 95 % of the
#: verdict's intervals.
CHANCE = 0.05


def chance_coherence(n_segments: int) -> float:
    """The coherence that ``n_segments`` averaged segments of unrelated signals exceed with probability
    :data:`CHANCE` (1 for a single segment: it always reads 1)."""
    return 1.0 - CHANCE ** (1.0 / (n_segments - 1)) if n_segments > 1 else 1.0


def segments_to_tell(limit: float) -> int:
    """The fewest averaged segments whose chance coherence (:func:`chance_coherence`) lies below ``limit``."""
    return max(2, math.floor(1.0 + math.log(CHANCE) / math.log(1.0 - limit)) + 1)


def few_averages(frf: FrequencyResponse, limit: float) -> str | None:
    """Why a misfit cannot be weighed against noise when ``frf`` averages too few Welch segments to tell the band's
    coherence ``limit`` from chance: how many it averaged, the chance level, and the record's span that holds enough
    (or, when the record held enough, that too few of them excite). None when it averaged enough."""
    n, need = frf.n_segments, segments_to_tell(limit)
    if n >= need:
        return None
    _, step = segment_layout(frf.segment_s, frf.period_s)
    step_s = step * frf.period_s
    recorded = n if frf.selection is None else int(frf.selection.keep.size)
    said = (f"only {n} Welch segment{'s' if n != 1 else ''} of {frf.segment_s:g} s (the band's "
            f"{1.0 / frf.segment_s:g} Hz resolution) are averaged: with fewer than {need} the coherence cannot tell the "
            f"band's limit {limit:g} from chance (its 95 % point with {n}: {chance_coherence(n):.2f}), so what noise "
            "explains is not known")
    if recorded >= need:
        return f"{said} — only {n} of the record's {recorded} segments excite the joint"
    need_s = frf.segment_s + (need - 1) * step_s
    return (f"{said} — the record is short for the band: it holds {recorded}, and {need} need {need_s:.2f} s where "
            "both streams have data (a longer record: acq monitor --window, acq record's duration)")
