"""Identification of a robot joint from a raw recording: the package's public face.

Everything outside ``analysis/`` (the application ``acq``) imports from here only; ``bench/`` and
``tests/`` may reach into the modules.

- :func:`analyze` — a :class:`Recording` and an :class:`AnalysisRequest` → :class:`Result`.
- :class:`AnalysisRequest` — what is asked (torque method, free parameters, fit, band, chain, …) and
  :meth:`AnalysisRequest.key`, the catalogue's key; :func:`code_fingerprint` is the code part of it.
- :class:`SignalChain`, :func:`our_chain`, :data:`PAPER_CHAIN` — the signal chain as a strategy.
- :class:`Recording` — one session's raw arrays (:class:`CommandedProfile`: the motion acq commanded); :func:`prepare_signals` — its torque and speed on the
  encoder instants (:class:`PreparedSignals`).
- :class:`Result`, :class:`FigureData`, :class:`TwoMassParams`, :data:`PARAM_NAMES`,
  :data:`PARAM_LABELS`, :data:`Z95`, :class:`Thresholds` — what a result holds and how it is judged.
- :func:`encoder_period_problem`, :func:`min_current_rate_hz`, :func:`min_duration_s`, :func:`min_record_s`,
  :func:`min_speed_rpm` (within :data:`PHASE_WINDOW_S`; :class:`TooSlowError` when a record's motion never reaches it) — what a bench, a record and a profile must offer
  before it records.
- The bench checks of ``acq selftest`` (:mod:`analysis.speed_ratio`, :mod:`analysis.bench_checks`,
  :mod:`analysis.encoder`; the cycle grid of :mod:`analysis.sample_instants`: :func:`cycle_deviation_s`,
  :data:`MAX_STAMP_DEVIATION`; a stream's period from its least-delayed arrival stamps: :func:`lower_line`).
"""

from __future__ import annotations

from analysis.chain import PAPER_CHAIN, Pipeline, SignalChain, TorqueMethod, our_chain
from analysis.clock_host import lower_line
from analysis.bench_checks import first_move_sign, inertia_from_torque, phase_sequence_agreement, sequence_fault
from analysis.encoder import longest_gap_free_span, speed_from_counts
from analysis.excitation import against_limit
from analysis.fit import PARAM_NAMES, Z95
from analysis.frf import min_duration_s
from analysis.limits import encoder_period_problem, min_current_rate_hz, min_record_s
from analysis.model import PARAM_LABELS, TwoMassParams
from analysis.pipeline import Result, analyze
from analysis.recording import CommandedProfile, Recording
from analysis.report import FigureData
from analysis.request import AnalysisRequest, code_fingerprint
from analysis.sample_instants import MAX_STAMP_DEVIATION, cycle_deviation_s
from analysis.segments import excitation_summary, segments_summary
from analysis.fit_problem import UNBRACKETED_NOTE_START
from analysis.signals import PreparedSignals, prepare_signals
from analysis.speed_ratio import SpeedRatio, electrical_speed_ratio, likely_counts_per_rev, ratio_doubt, ratio_fault
from analysis.phase_offset import PHASE_WINDOW_S, TooSlowError, min_speed_rpm
from analysis.verdict_limits import Thresholds

__all__ = [
    "MAX_STAMP_DEVIATION", "UNBRACKETED_NOTE_START", "PAPER_CHAIN", "PARAM_LABELS", "PHASE_WINDOW_S", "PARAM_NAMES", "AnalysisRequest", "CommandedProfile", "FigureData", "Pipeline", "PreparedSignals",
    "Recording", "Result", "SignalChain", "SpeedRatio", "Thresholds", "TooSlowError", "TorqueMethod", "TwoMassParams", "Z95",
    "against_limit", "analyze", "code_fingerprint", "cycle_deviation_s", "electrical_speed_ratio", "encoder_period_problem", "excitation_summary", "segments_summary",
    "min_current_rate_hz",
    "min_duration_s", "min_record_s", "min_speed_rpm", "first_move_sign", "inertia_from_torque",
    "likely_counts_per_rev", "longest_gap_free_span", "lower_line", "our_chain", "phase_sequence_agreement", "prepare_signals",
    "ratio_doubt", "ratio_fault", "sequence_fault", "speed_from_counts",
]
