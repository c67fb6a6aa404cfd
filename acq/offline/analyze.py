"""Analyse a session file: session → :mod:`analysis` → ``.result.json`` (the report PNG: :mod:`acq.ui.report_png`).

The only place where the application meets the analysis: it turns an :class:`acq.recording.session.Session`
into the plain arrays of :class:`analysis.Recording`, runs :func:`analysis.analyze` with an
:class:`analysis.AnalysisRequest`, and writes the results beside the session (the raw groups are
never touched). On the simulated bench the result also holds the simulated truth.

Where the results go (:func:`output_paths`): the default analysis writes the session's result,
``<session>.result.json`` and ``<session>.report.png`` — what ``acq view``, the catalogue's default rows and the
trend take as the session's result. Any other request writes beside it, never over it, under a name that says
what differs (:meth:`analysis.AnalysisRequest.variant_label`, which lists the label's parts):
``<session>.<label>.result.json`` and ``<session>.<label>.report.png``, e.g. ``S.band-10-150.result.json`` or
``S.params-K.fit-complex.result.json``.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from acq import __version__
from acq.recording.layout import analysis_time_utc
from acq.recording.reader import load
from acq.recording.session import Session
from acq.recording.storage import free_bytes, refused_write, storage_error, write_text_atomically
from acq.offline.excitation_judge import judged
from analysis import (AnalysisRequest, CommandedProfile, Recording, Result, TooSlowError, TwoMassParams, analyze,
                      code_fingerprint)
from acqcore.errors import ConfigError, StorageError
from drivers.base import limit_span_ns

#: Free bytes needed before drawing a report PNG: the reports are 0.2–0.6 MB (1600×1000 px); ×4 margin.
REPORT_ROOM_BYTES = 4 << 20


@dataclass(frozen=True)
class SessionResult:
    """A session's identification with where its outputs went."""

    session: Session
    result: Result | None  # None: a record acq did not command that did not excite the joint (verdict not excited)
    json_dict: dict[str, Any]
    json_path: Path
    report_path: Path | None
    request: AnalysisRequest = AnalysisRequest()  # as asked, an option naming the default left to it (no nominal)


class ResultNotWritten(StorageError):
    """The identification ran but its ``.result.json`` could not be written (read-only folder, disk full): a failure
    named by the file, with the result in ``done`` (no report path) so the caller can still show the numbers."""

    def __init__(self, message: str, done: SessionResult) -> None:
        super().__init__(message)
        self.done = done


def recording_from_session(session: Session) -> Recording:
    """The session's raw streams as the analysis's plain arrays (nothing resampled or corrected)."""
    session.require_samples()
    cur, enc, bench = session.current, session.encoder, session.bench
    return Recording(
        current_a=dict(cur.phases_a),
        rate_hz=cur.rate_hz,
        encoder_index=enc.index,
        position_counts=enc.position_counts,
        period_s=enc.period_s,
        counts_per_rev=enc.counts_per_rev,
        pole_pairs=bench.motor.pole_pairs,
        k_t_Nm_per_A=bench.motor.torque_constant_Nm_per_A,
        block_first_index=cur.block_first_index,
        block_count=cur.block_count,
        block_host_ns=cur.block_host_ns,
        encoder_host_ns=enc.host_ns,
        host_clock_shared=session.host_clock_shared,
        drive_time_s=enc.drive_time_s,
        profile=None if session.profile is None else CommandedProfile(
            session.profile.accel_time_s, session.profile.decel_time_s, session.profile.jerk_time_s,
            session.profile.speed_dither),
        drive_limited_host_ns=drive_limited_spans(session),
    )


def drive_limited_spans(session: Session) -> np.ndarray | None:
    """The host spans (n, 2; monotonic ns) in which the drive reported "internal limit active", from the session's
    events (:func:`drivers.base.limit_event`); None when it reported none."""
    spans = [span for event in session.events if (span := limit_span_ns(event)) is not None]
    return np.array(spans, dtype=np.int64) if spans else None


def request_for(session: Session, request: AnalysisRequest = AnalysisRequest()) -> AnalysisRequest:
    """``request`` with the bench's nominal plant when it names none, and then, when the bench knows its inertia
    (``[nominal] inertia_known``), the tolerance of that inertia (``[nominal] inertia_tolerance``)."""
    if request.nominal is not None:
        return request
    nominal = session.bench.nominal
    return replace(request, nominal=TwoMassParams(K_Nm_per_rad=nominal.K_Nm_per_rad, Jm_kgm2=nominal.Jm_kgm2,
                                                  Jl_kgm2=nominal.Jl_kgm2,
                                                  C_Nms_per_rad=0.0),  # the bench gives no damping; C is always fitted
                   inertia_tolerance=nominal.inertia_tolerance if nominal.inertia_known else None)


def sha256_of(path: Path) -> str:
    """SHA-256 of a file, hex."""
    with path.open("rb") as f:  # read into one reused buffer: ≈ 4 % less CPU than a new bytes object per chunk
        return hashlib.file_digest(f, "sha256").hexdigest()


def simulated_truth(session: Session) -> dict[str, float] | None:
    """The plant the simulated bench ran, when the current came from it (None for hardware).

    The true clock offset refers to the simulator's drive cycle 0; it is given only when the stored
    encoder index is that cycle (transport ``sim``) — a CANopen or serial index starts at its own first
    SYNC or frame. With ``[sim] robot_payload_inertia`` the true J_l includes the session's ``payload_kg`` tag
    (None without the tag: the payload is unknown).
    """
    sim = session.bench.sim
    if sim is None or session.bench.daq.driver != "sim":
        return None
    offset = sim.daq_offset_s if session.encoder.transport == "sim" else None
    payload = session.tags.get("payload_kg")
    Jl = (sim.Jl_kgm2 + sim.payload_Jl_kgm2(float(payload or 0.0), session.bench.gear.ratio)
          if payload is not None or not sim.robot_payload_inertia else None)
    return {"K_Nm_per_rad": sim.K_at_start_Nm_per_rad(), "Jm_kgm2": sim.Jm_kgm2, "Jl_kgm2": Jl,
            "C_Nms_per_rad": sim.C_Nms_per_rad, "offset_s": offset, "drift_ppm": sim.daq_drift_ppm}


def joint_travel(session: Session) -> tuple[float, float]:
    """Encoder counts the joint travelled in ``session`` (back and forth added up), and the least an analysis needs:
    half an electrical revolution, in counts."""
    counts = session.encoder.position_counts
    travel = float(abs(counts[1:] - counts[:-1]).sum()) if counts.size > 1 else 0.0
    return travel, session.bench.encoder.counts_per_rev / (2 * session.bench.motor.pole_pairs)


def idle_reason(session: Session) -> str | None:
    """Why a record acq did not command (no profile: a passive or listening record, a monitor's window, an import)
    holds nothing to analyse: the joint travelled less than half an electrical revolution — the reason of the
    monitor's verdict ``not excited``. None when it travelled more, or when acq commanded the motion (a commanded
    record that never moves is a bench fault: the analysis' error names it)."""
    if session.profile is not None:
        return None
    travel, need = joint_travel(session)
    if travel >= need:
        return None
    where = "window" if "monitor_window" in session.tags else "record"
    if session.damage:  # on a damaged file's readable part the travel says nothing of the rest (the second read)
        n = session.encoder.position_counts.size
        where = f"{where}'s readable part ({n * session.encoder.period_s:.1f} s; {session.damage[0]})"
    return (f"the joint travelled {travel:.0f} counts, less than half an electrical revolution ({need:.0f} counts): "
            f"the machine did not move it in this {where}")


def not_excited_json(session: Session, request: AnalysisRequest, reason: str) -> dict[str, Any]:
    """The ``.result.json`` document of a record whose joint never moved (:func:`idle_reason`) or never turned fast
    enough for the one-phase angle: verdict ``not excited`` with the reason, no numbers."""
    doc: dict[str, Any] = {"options": request.to_json_dict(),
                           "quality": {"verdict": "not excited", "reasons": [reason]}}
    return _identified(doc, session)


def result_json(session: Session, result: Result) -> dict[str, Any]:
    """The ``--json`` / ``.result.json`` document: the result's keys plus what identifies the session."""
    return _identified(result.to_json_dict(), session)


def _identified(doc: dict[str, Any], session: Session) -> dict[str, Any]:
    """``doc`` with what identifies the session, the analysis' time and version, and the simulated truth."""
    doc["session"] = {
        "path": str(session.path),
        "session_id": session.meta.session_id,
        "joint": session.meta.joint,
        "created_utc": session.meta.created_utc,
        "status": session.status,
        "sha256": sha256_of(session.path),
        "tags": session.tags,
    }
    doc["analyzed_utc"] = analysis_time_utc()
    doc["acq_version"] = __version__
    doc["analysis_fingerprint"] = code_fingerprint()
    truth = simulated_truth(session)
    if truth is not None:
        doc["simulated_truth"] = truth
    return doc


def analyze_session(path: Path | str, request: AnalysisRequest = AnalysisRequest(), *, write: bool = True,
                    report: bool = True, result_dir: Path | None = None) -> SessionResult:
    """Identify the joint of one session as ``request`` asks (with the bench's nominal plant unless it names one);
    write ``<session>.result.json`` (:func:`output_paths`: beside the session, or in ``result_dir``; a request other
    than the default writes ``<session>.<label>.result.json`` beside it).

    A record acq did not command (no profile: a monitor's window, a passive recording, an import) that did not excite
    the joint — it never moved (:func:`idle_reason`), never turned fast enough for the one-phase angle
    (:class:`analysis.TooSlowError`), or its analysis found too little excitation
    (:func:`acq.offline.excitation_judge.judged`) — gets verdict ``not excited`` and why, without numbers or report:
    the monitor files its windows through here, so both give one judgement.

    The report PNG is not drawn here: with ``report`` its path is set, and :func:`acq.ui.report_png.draw_report`
    draws it once the result (and the catalogue entry) stand. Bad or unusable input (too short, bad band, …) raises
    :class:`ConfigError` naming the session; so does a session still ``recording`` or damaged unless ``request.partial``
    (then its intact part is analysed and the result says ``"partial": true``). A failed write raises
    :class:`ResultNotWritten` naming the file (and holding the result), leaving no temp file.
    """
    session = load(path)
    session.require_usable(partial=request.partial)
    notes = partial_notes(session)
    why = f" ({notes[0].removeprefix('note: ')})" if notes else ""  # on part of a session: what was left out
    try:
        asked = filed_request(session, request)  # spelled-out defaults: the session's own result, not a variant
        rec = recording_from_session(session)
        request = request_for(session, asked)
        idle = idle_reason(session)
        result = analyze(rec, request) if idle is None else None
    except TooSlowError as e:
        if session.profile is not None:  # acq commanded too slow a motion: the profile's fault, the error says how
            raise ConfigError(f"{session.path}: {e}{why}") from None
        idle, result = str(e), None  # the machine's own motion never ran fast enough for the one-phase angle
    except ValueError as e:  # on part of a session, the error may come of what is missing: the note says what
        raise ConfigError(f"{session.path}: {e}{why}") from None
    doc = result_json(session, result) if result is not None else not_excited_json(session, request, str(idle))
    if session.profile is None and result is not None:  # the machine's motion: did it excite the joint at all?
        doc = judged(doc)
        result = result if doc["quality"]["verdict"] != "not excited" else None  # nothing to draw, no numbers
    doc["quality"]["reasons"][:0] = notes
    doc["partial"] = bool(notes)  # the note says why
    doc["session"]["damage"] = list(session.damage)
    json_path, png_path = output_paths(session.path, request, result_dir)
    report_path = png_path if report and write and result is not None else None  # nothing to draw when not excited
    if write:
        try:
            refused = refused_write(json_path.parent)
            if refused is not None:  # before the room: a tiny read-only mount has none either, and read "disk full"
                raise StorageError(f"{refused}: {json_path}")
            if report_path is not None and free_bytes(report_path.parent) < REPORT_ROOM_BYTES:
                # before anything is written (no result without its report) and before Qt's PNG writer, whose libpng
                # prints its own line on stderr when the disk fills under it
                raise StorageError(f"disk full: {report_path}")
            write_json(doc, json_path)
        except (StorageError, OSError) as e:
            message = str(e) if isinstance(e, StorageError) else str(storage_error(e, json_path))
            raise ResultNotWritten(message, SessionResult(session, result, doc, json_path, None, asked)) from None
        if report_path is None:  # no picture of this result: one of an earlier result would be taken for it
            png_path.unlink(missing_ok=True)
    return SessionResult(session, result, doc, json_path, report_path, asked)


def filed_request(session: Session, request: AnalysisRequest) -> AnalysisRequest:
    """``request`` as its result on ``session`` is filed: the result's file name (:func:`output_paths`) and its
    catalogue key, of a success and of a failure alike. Each option that names what the default does on this session
    anyway is left to the default (:meth:`analysis.AnalysisRequest.as_default_where_it_is`), so ``--band 10,400`` on
    a 1 kHz encoder is the session's own result. A stream with too few samples raises :class:`ConfigError`
    (:meth:`~acq.recording.session.Session.require_samples`)."""
    return request.as_default_where_it_is(recording_from_session(session))


def partial_notes(session: Session) -> list[str]:
    """The note that says a result rests on part of the session only (damaged: the spans left out; still
    ``recording``: what was stored), first among the result's reasons; none for a whole session."""
    if session.damage:
        return [f"note: partial: only the readable part of a damaged session was analysed; left out: "
                f"{'; '.join(session.damage)}"]
    if session.status == "recording":
        return ["note: partial: the session is still being recorded (status recording); only what was stored was "
                "analysed"]
    return []


def output_paths(session_path: Path, request: AnalysisRequest, result_dir: Path | None = None) -> tuple[Path, Path]:
    """The result document and report PNG of ``request`` on a session: ``<session>.result.json`` and
    ``<session>.report.png`` beside the session, or in ``result_dir`` (``--result-dir``: a read-only archive); any
    other request than the default (the paper's chain, ``--band``, ``--params K``, …: a comparison or an experiment,
    not the session's result) writes ``<session>.<label>.result.json`` and ``<session>.<label>.report.png``
    (:meth:`analysis.AnalysisRequest.variant_label`) beside them instead of replacing them."""
    label = request.variant_label()
    stem = session_path.stem + (f".{label}" if label else "")
    folder = session_path.parent if result_dir is None else result_dir
    return folder / (stem + ".result.json"), folder / (stem + ".report.png")


def write_json(doc: dict[str, Any], path: Path) -> None:
    """Write a result document through a temporary file of this writer, so a reader never sees half of it."""
    write_text_atomically(path, result_text(doc))


def result_text(doc: dict[str, Any]) -> str:
    """A result document as :func:`write_json` writes it (a reader may compare a file with it)."""
    return json.dumps(doc, indent=2)


def report_not_drawn(done: SessionResult, why: str) -> SessionResult:
    """``done`` after its report PNG failed (``why``): a note in ``quality.reasons`` ("note: report not drawn: …"),
    rewritten into the ``.result.json``, and no report path. A picture that fails is not a failed identification."""
    return replace(done, json_dict=write_report_note(done.json_dict, done.json_path, why), report_path=None)


def write_report_note(doc: dict[str, Any], json_path: Path, why: str) -> dict[str, Any]:
    """The result document ``doc`` with the note "note: report not drawn: ``why``" in ``quality.reasons``, written
    to ``json_path``; returns it."""
    quality = doc["quality"]
    reasons = [*quality["reasons"], f"note: report not drawn: {why}"]
    noted = {**doc, "quality": {**quality, "reasons": reasons}}
    write_json(noted, json_path)
    return noted
