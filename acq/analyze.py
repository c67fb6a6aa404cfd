"""Analyse a session file: session → :mod:`analysis` → result table, ``.result.json``, ``.report.png``.

The only place where the application meets the analysis: it turns an :class:`acq.session.Session`
into the plain arrays of :class:`analysis.signals.Recording`, runs
:func:`analysis.pipeline.analyze`, and writes the results beside the session (the raw groups are
never touched). On the simulated bench the table also shows the simulated truth and the error.
"""

from __future__ import annotations

import functools
import hashlib
import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy
import scipy
from rich.markup import escape
from rich.table import Table

import analysis
from acq import __version__
from acq.session import Session, load, utc_now_iso
from acq.storage import atomic_path, free_bytes, write_text_atomically
from analysis.model import TwoMassParams
from analysis.pipeline import AnalysisOptions, Pipeline, Result, analyze
from analysis.signals import Recording, TorqueMethod
from drivers.errors import ConfigError, StorageError

PARAMS = (("K_Nm_per_rad", "K", "N·m/rad"), ("Jm_kgm2", "J_m", "kg·m²"), ("Jl_kgm2", "J_l", "kg·m²"),
          ("C_Nms_per_rad", "C", "N·m·s/rad"))


#: Free bytes needed before drawing a report PNG: the reports are 0.2–0.6 MB (1600×1000 px); ×4 margin.
REPORT_ROOM_BYTES = 4 << 20

@dataclass(frozen=True)
class SessionResult:
    """A session's identification with where its outputs went."""

    session: Session
    result: Result
    json_dict: dict[str, Any]
    json_path: Path
    report_path: Path | None


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
    )


def options_for(session: Session, *, torque: TorqueMethod | None = None, params: str = "K,Jm,Jl",
                fit: str = "amplitude", band_hz: tuple[float, float] | None = None,
                pipeline: Pipeline = "acq") -> AnalysisOptions:
    """Analysis options with the bench's nominal plant; torque defaults to park with ≥ 2 phases."""
    nominal = session.bench.nominal
    if torque is None:
        torque = "park" if len(session.current.phases_a) >= 2 else "encoder"
    return AnalysisOptions(
        torque_method=torque, params=params, fit=fit, band_hz=band_hz, pipeline=pipeline,  # type: ignore[arg-type]
        nominal=TwoMassParams(K_Nm_per_rad=nominal.K_Nm_per_rad, Jm_kgm2=nominal.Jm_kgm2, Jl_kgm2=nominal.Jl_kgm2,
                              C_Nms_per_rad=0.0),  # the bench gives no damping; the fit always fits C
    )


@functools.cache
def analysis_fingerprint() -> str:
    """SHA-256 (first 16 hex digits) of the analysis package's source and the numpy/scipy it runs on: results of
    other code are not current."""
    digest = hashlib.sha256(f"numpy {numpy.__version__} scipy {scipy.__version__}".encode())
    for source in sorted(Path(analysis.__file__).parent.glob("*.py")):
        digest.update(source.name.encode() + b"\0" + source.read_bytes())
    return digest.hexdigest()[:16]


def sha256_of(path: Path) -> str:
    """SHA-256 of a file, hex."""
    digest = hashlib.sha256()
    with path.open("rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            digest.update(chunk)
    return digest.hexdigest()


def simulated_truth(session: Session) -> dict[str, float] | None:
    """The plant the simulated bench ran, when the current came from it (None for hardware).

    The true clock offset refers to the simulator's drive cycle 0; it is given only when the stored
    encoder index is that cycle (transport ``sim``) — a CANopen or serial index starts at its own first
    SYNC or frame.
    """
    sim = session.bench.sim
    if sim is None or session.bench.daq.driver != "sim":
        return None
    offset = sim.daq_offset_s if session.encoder.transport == "sim" else None
    return {"K_Nm_per_rad": sim.K_Nm_per_rad, "Jm_kgm2": sim.Jm_kgm2, "Jl_kgm2": sim.Jl_kgm2,
            "C_Nms_per_rad": sim.C_Nms_per_rad, "offset_s": offset, "drift_ppm": sim.daq_drift_ppm}


def result_json(session: Session, result: Result) -> dict[str, Any]:
    """The ``--json`` / ``.result.json`` document: the result's keys plus what identifies the session."""
    doc = result.to_json_dict()
    doc["session"] = {
        "path": str(session.path),
        "session_id": session.attrs.get("session_id"),
        "joint": session.attrs.get("joint"),
        "created_utc": session.attrs.get("created_utc"),
        "status": session.status,
        "sha256": sha256_of(session.path),
        "tags": session.tags,
    }
    doc["analyzed_utc"] = utc_now_iso()
    doc["acq_version"] = __version__
    doc["analysis_fingerprint"] = analysis_fingerprint()
    truth = simulated_truth(session)
    if truth is not None:
        doc["simulated_truth"] = truth
    return doc


def analyze_session(path: Path | str, options: AnalysisOptions | None = None, *, write: bool = True,
                    report: bool = True, partial: bool = False, **option_kwargs: Any) -> SessionResult:
    """Identify the joint of one session; write ``<session>.result.json`` (and the report PNG).

    Bad or unusable input (too short, bad band, …) raises :class:`ConfigError` naming the session; so does a
    session still ``recording`` or damaged unless ``partial`` (then its intact part is analysed and the result
    says ``"partial": true``). A failed write raises :class:`StorageError` naming the file, leaving no temp file.
    """
    session = load(path)
    session.require_usable(partial=partial)
    opts = options if options is not None else options_for(session, **option_kwargs)
    nyquist_hz = 0.5 / session.encoder.period_s
    if opts.band_hz is not None and opts.band_hz[1] > nyquist_hz:
        lo, hi = opts.band_hz
        raise ConfigError(f"--band {lo:g},{hi:g}: HI must not exceed {nyquist_hz:g} Hz, the Nyquist frequency of "
                          f"{session.path.name}'s encoder (period {session.encoder.period_s:g} s)")
    try:
        result = analyze(recording_from_session(session), opts)
    except ValueError as e:
        raise ConfigError(f"{session.path}: {e}") from None
    doc = result_json(session, result)
    doc["partial"] = bool(session.damage) or session.status == "recording"
    doc["session"]["damage"] = list(session.damage)
    json_path = session.path.with_name(session.path.stem + ".result.json")
    report_path = session.path.with_name(session.path.stem + ".report.png") if report else None
    if write:
        if report_path is not None and free_bytes(report_path.parent) < REPORT_ROOM_BYTES:
            # before anything is written (no result without its report) and before Qt's PNG writer, whose libpng
            # prints its own line on stderr when the disk fills under it
            raise StorageError(f"disk full: {report_path}")
        write_text_atomically(json_path, json.dumps(doc, indent=2))  # a reader never sees half a result
        if report_path is not None:
            from acq.plots import render_report_png

            with atomic_path(report_path) as tmp_png:
                render_report_png(result.figures, tmp_png, title=f"{session.attrs.get('joint')} · {session.path.name}",
                                  values=doc)
    return SessionResult(session, result, doc, json_path, report_path if write else None)


def format_value(x: float | None, spec: str = ".4g", scale: float = 1.0) -> str:
    """``x · scale`` formatted with ``spec``; "—" for a value that is missing, NaN or infinite."""
    return "—" if x is None or not math.isfinite(x) else format(x * scale, spec)


def _scaled(x: float | None, factor: float) -> float | None:
    return None if x is None else x * factor


def result_table(doc: dict[str, Any]) -> Table:
    """The identified values with 95 % intervals, frequencies, clock relation and verdict (fits 80 columns)."""
    truth = doc.get("simulated_truth") or {}
    quality, clock = doc["quality"], doc["clock"]
    table = Table(title=f"identification — verdict [bold]{escape(quality['verdict'])}[/bold]")
    for column in ("quantity", "value", "95 % interval", *(("sim truth", "error") if truth else ())):
        table.add_column(column, justify="left" if column == "quantity" else "right", no_wrap=True)
    for key, name, unit in PARAMS:
        value, (lo, hi) = doc[key], doc["ci95"][key]
        row = [escape(f"{name} [{unit}]"), format_value(value), f"{format_value(lo)} – {format_value(hi)}"]
        if truth:
            err = None if value is None else 100.0 * (value - truth[key]) / truth[key]
            row += [format_value(truth[key]), "—" if err is None else f"{err:+.2f} %"]
        table.add_row(*row)
    offset_ms, true_offset_ms = _scaled(clock["offset_s"], 1e3), _scaled(truth.get("offset_s"), 1e3)
    rows = [("f_a [Hz]", format_value(doc["antiresonance_hz"]), None),
            ("f_r [Hz]", format_value(doc["resonance_hz"]), None),
            ("clock offset [ms]", format_value(offset_ms, ".3f"),
             (true_offset_ms, None if offset_ms is None or true_offset_ms is None
              else f"{(offset_ms - true_offset_ms) * 1e3:+.1f} µs")),
            ("clock drift [ppm]", format_value(clock["drift_ppm"], ".2f"),
             (truth.get("drift_ppm"), None if clock["drift_ppm"] is None or "drift_ppm" not in truth
              else f"{clock['drift_ppm'] - truth['drift_ppm']:+.2f} ppm")),
            ("clock residual [µs]", format_value(_scaled(clock["residual_s"], 1e6), ".1f"), None),
            ("coherence in band", format_value(quality["mean_coherence"], ".3f"), None)]
    for name, value, compared in rows:
        row = [escape(name), value, ""]
        if truth:
            true_value, error = compared or (None, None)
            row += [format_value(true_value, ".4g"), error or ""]
        table.add_row(*row)
    if quality["reasons"]:
        table.caption = escape("\n".join(quality["reasons"]))
    return table
