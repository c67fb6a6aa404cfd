"""What an analysis is asked to do: one frozen :class:`AnalysisRequest`, and the key its results are kept under.

The request is the only shape of an analysis's options: the command line builds it, a batch or the
monitor hands it to its workers, the catalogue files a result under :meth:`AnalysisRequest.key` (the
request as asked plus :func:`code_fingerprint`: a result of other options or other code is not current).
"""

from __future__ import annotations

import functools
import hashlib
import json
import math
from dataclasses import asdict, dataclass, fields, replace
from pathlib import Path
from typing import Any

import numpy
import scipy

from analysis.chain import PAPER_CHAIN, Pipeline, SignalChain, TorqueMethod, our_chain
from analysis.fit import PARAM_NAMES, FitKind, FitParams, default_band_hz
from analysis.model import TwoMassParams
from analysis.recording import Recording


@dataclass(frozen=True)
class AnalysisRequest:
    """What the analysis does.

    Attributes
    ----------
    torque_method : {"encoder", "hilbert", "park"} or None
        Torque estimator; None: park with two or more phases, else encoder (ignored by ``pipeline="paper"``,
        which uses hilbert).
    params : {"K,Jm,Jl", "K"}
        Free parameters besides C; ``"K"`` fixes J_m, J_l to ``nominal``.
    fit : {"amplitude", "complex"}
        Fit |H| or the complex H.
    band_hz : tuple of float or None
        Fit band (low, high), Hz; None for 10 Hz … min(0.4·f_enc, 500 Hz).
    align : bool
        Align the clocks from the data (ignored by ``pipeline="paper"``, which does not).
    segment_s : float
        Welch segment length, s.
    nominal : TwoMassParams or None
        The bench's nominal values (needed for ``params="K"``; otherwise one extra fit start). None: the
        application fills in the bench's (:func:`acq.offline.analyze.analyze_session`).
    inertia_tolerance : float or None
        When the bench knows its inertia (``[nominal] inertia_known``): how far, as a fraction, the true J_m + J_l may
        lie from ``nominal``'s (``[nominal] inertia_tolerance``). A fitted J_m + J_l whose interval lies wholly outside
        that band is a torque-scale mistake (:func:`analysis.diagnose.inertia_fault`). None: no inertia known, no
        such check. Filled in by the application with ``nominal``.
    pipeline : {"acq", "paper"}
        Our chain or the paper's (:mod:`analysis.chain`).
    partial : bool
        Also analyse the intact part of a session still being recorded or damaged (read by the application
        that turns a session file into a :class:`Recording`; the analysis of a recording ignores it).
    select_segments : bool or None
        Average only the Welch segments that excite the joint in the fit band (:mod:`analysis.segments`;
        for motion that excites in parts, e.g. a robot program); the result then says which moves do. None: when
        acq did not command the motion (the recording has no profile: a machine's own program moved the joint, as
        in ``acq monitor``'s windows, or the data were imported), with our chain (:meth:`selects_segments`) — so
        ``acq analyze`` of a monitor's window analyses it as the monitor did.
    """

    torque_method: TorqueMethod | None = None
    params: FitParams = "K,Jm,Jl"
    fit: FitKind = "amplitude"
    band_hz: tuple[float, float] | None = None
    align: bool = True
    segment_s: float = 0.5
    nominal: TwoMassParams | None = None
    inertia_tolerance: float | None = None
    pipeline: Pipeline = "acq"
    partial: bool = False
    select_segments: bool | None = None

    def selects_segments(self, rec: Recording) -> bool:
        """Whether this request averages only the exciting segments of ``rec`` (see ``select_segments``)."""
        if self.select_segments is not None:
            return self.select_segments
        return self.pipeline == "acq" and rec.profile is None

    def chain(self, rec: Recording) -> SignalChain:
        """The signal chain this request asks for on ``rec`` (the torque method resolved by its phases)."""
        if self.pipeline == "paper":
            return PAPER_CHAIN
        method = self.torque_method or ("park" if len(rec.current_a) >= 2 else "encoder")
        return our_chain(method, self.align)

    def as_default_where_it_is(self, rec: Recording) -> AnalysisRequest:
        """This request with each option that names what the default does on ``rec`` anyway left to the default: the
        torque method ``rec``'s phases pick, the default band of its encoder period, the segment selection its
        motion gets. The same analysis as the default request's, so the same result file and catalogue key
        (``acq analyze S --torque encoder`` on one phase is the session's result, not a comparison beside it)."""
        default = AnalysisRequest(pipeline=self.pipeline)
        same = {"torque_method": self.torque_method is not None and (
                    self.pipeline == "paper" or self.torque_method == default.chain(rec).torque_method),
                "band_hz": self.band_hz is not None and all(  # 0.4/period carries float noise: 1e-9, far below a bin
                    math.isclose(a, b, rel_tol=1e-9) for a, b in zip(self.band_hz, default_band_hz(rec.period_s))),
                "select_segments": self.select_segments is not None
                and self.select_segments == default.selects_segments(rec)}
        return replace(self, **{name: None for name, equal in same.items() if equal})

    def names_options_of_the_default(self) -> bool:
        """Whether :meth:`as_default_where_it_is` may change this request on some recording: one of the options it
        looks at is given (without one it is this request on every recording, and no session need be read for it)."""
        return any(v is not None for v in (self.torque_method, self.band_hz, self.select_segments))

    def key(self) -> str:
        """The catalogue's key of this request: its fields as asked and the analysis code that answers them
        (:func:`code_fingerprint`), canonical JSON — a change of either is not current."""
        return json.dumps({**asdict(self), "analysis": code_fingerprint()}, sort_keys=True)

    def variant_label(self) -> str:
        """What this request asks beyond the default analysis, as a part of a file name ('' for the default request:
        the session's own result; anything else is a comparison, kept beside it and never trended in its place).

        The parts, in this order and joined by ``.``: ``paper`` (the paper's chain), ``torque-<method>`` (a torque
        method named, even the one the default would pick), ``params-K``, ``fit-complex``, ``band-<lo>-<hi>`` (the
        band as given, Hz, ``%g``), ``no-align``, ``segment-<s>s``, ``segments-on``/``segments-off`` (a segment
        selection asked for, not left to the recording: the monitor's own results are the default's) — letters,
        digits, ``-`` and ``.`` only. The paper's chain ignores the torque method and the alignment, so they are not in
        its label. Not in the label: ``partial`` (the intact part of a session is its result so far), ``nominal`` and
        ``inertia_tolerance`` (the bench's, filled in by the application).
        """
        default = AnalysisRequest()
        paper = self.pipeline == "paper"
        parts = ["paper"] if paper else []
        if self.torque_method is not None and not paper:
            parts.append(f"torque-{self.torque_method}")
        if self.params != default.params:
            parts.append(f"params-{self.params.replace(',', '-')}")
        if self.fit != default.fit:
            parts.append(f"fit-{self.fit}")
        if self.band_hz is not None:
            parts.append("band-{:g}-{:g}".format(*self.band_hz))
        if not self.align and not paper:
            parts.append("no-align")
        if self.segment_s != default.segment_s:
            parts.append(f"segment-{self.segment_s:g}s")
        if self.select_segments is not None:  # asked for: a result the recording's default would not give
            parts.append("segments-on" if self.select_segments else "segments-off")
        return ".".join(parts)

    def to_json_dict(self, chain: SignalChain | None = None) -> dict[str, Any]:
        """The options as JSON-ready values: as asked, or with what ``chain`` (this request's) really did."""
        nominal = None if self.nominal is None else {n: getattr(self.nominal, n) for n in PARAM_NAMES[:3]}
        return {"pipeline": self.pipeline, "torque_method": self.torque_method if chain is None else chain.torque_method,
                "params": self.params, "fit": self.fit, "band_hz": None if self.band_hz is None else list(self.band_hz),
                "align": self.align if chain is None else chain.align, "segment_s": self.segment_s, "nominal": nominal,
                "inertia_tolerance": self.inertia_tolerance,
                **({"select_segments": True} if self.select_segments else {})}

    @classmethod
    def from_json_dict(cls, options: dict[str, Any]) -> AnalysisRequest:
        """The request a result's ``options`` document came from (the torque method as it was resolved, the
        nominal values and the inertia's tolerance left to the application). Raises ValueError or TypeError for a
        document that is none."""
        known = {f.name for f in fields(cls)} - {"nominal", "inertia_tolerance", "partial"}
        values = {k: v for k, v in options.items() if k in known}
        if values.get("pipeline", "acq") != "acq":
            values.pop("torque_method", None)
        band = values.pop("band_hz", None)
        return cls(**values, band_hz=(float(band[0]), float(band[1])) if band else None)


@functools.cache
def code_fingerprint() -> str:
    """SHA-256 (first 16 hex digits) of the analysis package's source and the numpy/scipy it runs on: results of
    other code are not current."""
    digest = hashlib.sha256(f"numpy {numpy.__version__} scipy {scipy.__version__}".encode())
    for source in sorted(Path(__file__).parent.glob("*.py")):
        digest.update(source.name.encode() + b"\0" + source.read_bytes())
    return digest.hexdigest()[:16]
