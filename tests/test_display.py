"""Every rich table is readable at 80 columns: drawn on Console(width=80), each key value appears whole, no cell is cut
to "…" and no line is wider than the terminal."""

from __future__ import annotations

import io
import re
from dataclasses import replace
from typing import Any

import numpy as np
import pytest
from rich.console import Console

from acq.commissioning.devices import Section
from acq.monitoring.batch import BatchReport
from acq.monitoring.catalogue import Entry, Outcome
from acq.monitoring.trend import compute_trend
from acq.recording.summary import SessionSummary, StreamSummary, fitted_rate
from acq.ui.display import batch_table, result_table, sections_table, summary_table, trend_table

TRUTH = {"K_Nm_per_rad": 891.0, "Jm_kgm2": 0.003027, "Jl_kgm2": 0.00748, "C_Nms_per_rad": 0.1, "offset_s": 0.037,
         "drift_ppm": 40.0}


def render(renderable: Any, width: int = 80) -> str:
    """What a terminal (or a pipe) of ``width`` columns shows."""
    console = Console(width=width, file=io.StringIO(), color_system=None)
    console.print(renderable)
    text = console.file.getvalue()  # type: ignore[attr-defined]
    assert not re.search(r"…\s*(│|┃|$)", text, re.M), "a cell cut to …"
    assert max(console.measure(line).maximum for line in text.splitlines()) <= width
    return text


def _doc(**changes: Any) -> dict[str, Any]:
    """A result document as acq analyze writes it (values of a 10 s simulated session)."""
    doc = {"K_Nm_per_rad": 895.1, "Jm_kgm2": 0.003045, "Jl_kgm2": 0.007509, "C_Nms_per_rad": 0.09554,
           "ci95": {"K_Nm_per_rad": [879.4, 911.1], "Jm_kgm2": [0.003001, 0.00309], "Jl_kgm2": [0.00734, 0.007683],
                    "C_Nms_per_rad": [0.07691, 0.1187]},
           "antiresonance_hz": 54.95, "resonance_hz": 102.3,
           "clock": {"offset_s": 0.03699852, "drift_ppm": 40.13, "residual_s": 13.3e-6},
           "quality": {"verdict": "ok", "mean_coherence": 0.907,
                       "reasons": ["note: using 0.064–9.972 s, where both streams have data"]},
           "options": {"pipeline": "acq", "torque_method": "encoder", "params": "K,Jm,Jl", "fit": "amplitude",
                       "band_hz": [10.0, 400.0], "align": True, "segment_s": 0.5,
                       "nominal": {"K_Nm_per_rad": 891.0, "Jm_kgm2": 0.003027, "Jl_kgm2": 0.00748}},
           "simulated_truth": TRUTH}
    doc.update(changes)
    return doc


def test_result_table_shows_every_value_whole_at_80_columns() -> None:
    text = render(result_table(_doc()))
    for value in ("895.1", "879.4 – 911.1", "0.003045", "0.003001 – 0.00309", "0.00734 – 0.007683", "+0.46 %",
                  "54.95", "102.3", "36.999", "-1.5 µs", "+0.13 ppm", "13.3", "0.907", "verdict ok",
                  "options: torque encoder · params K,Jm,Jl · fit amplitude · band 10–400 Hz"):
        assert value in text, value


def test_an_interval_that_does_not_determine_its_value_reads_so() -> None:
    """The trial's report: "C 0.237 ± 3.6e+02 %", "1.765 – 2.187e+06": an interval as wide as its value or wider
    says so, its ends to 2 digits in plain decimals (acq.ui.values.readable_number)."""
    from acq.ui.values import interval_text, readable_number

    doc = _doc(C_Nms_per_rad=0.237, ci95={**_doc()["ci95"], "C_Nms_per_rad": [0.0325, 1.728]})
    assert interval_text(doc, "C_Nms_per_rad") == "0.033 – 1.7: not determined"
    assert interval_text(doc, "C_Nms_per_rad", relative=True) == "not determined"
    assert interval_text(_doc(C_Nms_per_rad=10.0, ci95={"C_Nms_per_rad": [1.765, 2.187e6]}), "C_Nms_per_rad") == \
        "1.8 – 2.2e+06: not determined"
    # at the limit: a half-width of 99 % of the value is a number, 100 % is not
    assert interval_text(_doc(C_Nms_per_rad=1.0, ci95={"C_Nms_per_rad": [0.01, 1.99]}), "C_Nms_per_rad",
                         relative=True) == "± 99 %"
    assert interval_text(_doc(C_Nms_per_rad=1.0, ci95={"C_Nms_per_rad": [0.0, 2.0]}), "C_Nms_per_rad",
                         relative=True) == "not determined"
    assert [readable_number(x) for x in (0.000485, 4.63, 358.2, 99.96, 2.187e6, 1.2e-5)] == \
        ["0.00049", "4.6", "360", "100", "2.2e+06", "1.2e-05"]
    wide, narrow = render(result_table(doc), width=120), render(result_table(doc), width=60)
    assert "0.033 – 1.7: not determined" in wide and "not determined" in narrow and "e+02" not in wide + narrow


def _failed_doc() -> dict[str, Any]:
    """The new user's failed result (sim.toml with [sim] pole_pairs = 5): the fit's numbers absurd, an interval
    without an upper end."""
    doc = _doc(K_Nm_per_rad=995.5, Jl_kgm2=3.061e16,
               ci95={"K_Nm_per_rad": [0.0, None], "Jm_kgm2": [0.001, 0.005], "Jl_kgm2": [0.0, None],
                     "C_Nms_per_rad": [0.01, 0.2]})
    doc["quality"] = {"verdict": "failed", "mean_coherence": 0.09, "reasons": [
        "the current turns 1.25× faster than pole_pairs·ω (pole_pairs = 4, counts_per_rev = 131072): check [motor] "
        "pole_pairs = 5 or [encoder] counts_per_rev = 104742"]}
    return doc


def test_a_failed_verdict_shows_no_number_of_its_fit_as_a_result() -> None:
    """The new user's table read K 995.5, J_l 3.061e+16, error "+409220974935903633408.00 %", interval "0 – —"
    under "verdict failed": the fit's numbers are "—", "not a result" (the clock's and the coherence stay)."""
    assert render(result_table(_failed_doc())) == """\
                   identification — verdict failed                    
 quantity            ┃  value ┃ 95 % interval ┃ sim truth ┃     error 
━━━━━━━━━━━━━━━━━━━━━╇━━━━━━━━╇━━━━━━━━━━━━━━━╇━━━━━━━━━━━╇━━━━━━━━━━━
 K [N·m/rad]         │      — │  not a result │       891 │         — 
 J_m [kg·m²]         │      — │  not a result │  0.003027 │         — 
 J_l [kg·m²]         │      — │  not a result │   0.00748 │         — 
 C [N·m·s/rad]       │      — │  not a result │       0.1 │         — 
 f_a [Hz]            │      — │  not a result │           │           
 f_r [Hz]            │      — │  not a result │           │           
 clock offset [ms]   │ 36.999 │               │        37 │   -1.5 µs 
 clock drift [ppm]   │  40.13 │               │        40 │ +0.13 ppm 
 clock residual [µs] │   13.3 │               │           │           
 coherence in band   │  0.090 │               │           │           
options: torque encoder · params K,Jm,Jl · fit amplitude · band 10–400
Hz                                                                    
verdict failed: the fit's K, J_m, J_l, C, f_a and f_r are not a result
(--json keeps them)                                                   
the current turns 1.25× faster than pole_pairs·ω (pole_pairs = 4,     
counts_per_rev = 131072): check [motor] pole_pairs = 5 or [encoder]   
counts_per_rev = 104742                                               
"""
    poor = _failed_doc()
    poor["quality"]["verdict"] = "poor"  # poor and ok show their numbers, as before
    text = render(result_table(poor), width=120)
    assert "995.5" in text and "3.061e+16" in text and "not a result" not in text


def test_params_K_shows_the_inertias_as_fixed_nominal() -> None:
    doc = _doc(K_Nm_per_rad=890.7, Jm_kgm2=0.003027, Jl_kgm2=0.00748,
               ci95={"K_Nm_per_rad": [881.8, 899.6], "Jm_kgm2": [0.003027, 0.003027],
                     "Jl_kgm2": [0.00748, 0.00748], "C_Nms_per_rad": [0.07948, 0.1206]})
    doc["options"]["params"] = "K"
    text = render(result_table(doc))
    assert text.count("fixed (nominal)") == 2 and "0.003027 – 0.003027" not in text
    assert "881.8 – 899.6" in text


def test_papers_table_cuts_no_value() -> None:
    doc = _doc(K_Nm_per_rad=1569.0, C_Nms_per_rad=0.7324, clock={"offset_s": 0.0, "drift_ppm": 0.0, "residual_s": None})
    doc["options"] |= {"pipeline": "paper", "torque_method": "hilbert", "align": False}
    doc["quality"] = {"verdict": "poor", "mean_coherence": 0.69, "reasons": [
        "the two-mass model misses |H| by 29 % RMS, 5.3× what noise explains — another mode or a nonlinearity in "
        "the band; try --band", "note: clock: not aligned (streams taken as started together, no drift)"]}
    text = render(result_table(doc))
    for value in ("1569", "+76.09 %", "+632.40 %", "-37.000 ms", "-40.00 ppm", "paper's chain (--paper)",
                  "nonlinearity"):
        assert value in text, value


def _entry(i: int, k: float, truth: float) -> Entry:
    return Entry(f"id{i}", f"id{i}", f"/s/{i}.h5", "joint1", f"2026-11-29T19:5{i}:02.5+00:00",
                 {"pose": "home", "payload_kg": 2.0}, "ok", [], None, k, (k * 0.982, k * 1.018),
                 54.9 * (k / 891) ** 0.5, 102.3 * (k / 891) ** 0.5, "{}", "2026-11-30T00:00:00+00:00", truth)


def test_trend_table_at_80_columns_keeps_K_change_and_spelled_out_states() -> None:
    ks = (894.7, 856.8, 816.5, 742.7, 700.8)
    trend = compute_trend("joint1", [_entry(i, k, t) for i, (k, t) in enumerate(zip(ks, (891, 853, 815, 740, 700)))])
    text = render(trend_table(trend))
    for value in ("894.7", "742.7", "700.8", "-17.0", "-21.7", "baseline", "ALARM: EWMA", "ALARM:", "threshold",
                  "11-29 19:53", "11-29 19:54", "(UTC 2026)", "every session tagged pose=home payload_kg=2"):
        assert value in text, value
    assert "not shown at this width: sim K N·m/rad" in text
    wide = render(trend_table(trend), width=160)
    for value in ("2026-11-29 19:50:02", "878.6–910.8", "ALARM: threshold + EWMA", "891.0"):
        assert value in wide, value
    assert "not shown" not in wide


def test_a_monitors_trend_numbers_its_windows_as_the_monitor_does_and_leaves_its_bookkeeping_tags_out() -> None:
    """The new-user trial: the monitor's "window 9" was the trend's "#10", and at 160 columns each row was 17 lines
    tall with the monitor's own tags (monitor_daq_driver=sim, monitor_pole_pairs=4, …)."""
    from acq.monitoring.window_bench import FACT_TAGS

    bookkeeping = {"monitor_id": "vm:/m:049fad40", "monitor_elapsed_s": 0.0, "monitor_every_s": 5.0,
                   "alarm_baseline_sessions": 2, "alarm_threshold_pct": 10.0, "alarm_ewma_lambda": 0.2,
                   **{tag: 1.0 for tag in FACT_TAGS}}
    entries = [replace(_entry(i, k, 891.0), tags={"payload_kg": 1.0 + i, "monitor_window": i, **bookkeeping})
               for i, k in enumerate((891.0, 890.0, 889.0))]
    entries[1] = replace(entries[1], verdict="not excited", K_Nm_per_rad=None, K_ci95=(None, None))
    text = render(trend_table(compute_trend("joint1", entries)), width=160)
    rows = [line for line in text.splitlines() if "│" in line]
    assert [row.split("│")[0].strip() for row in rows] == ["1", "2", "3"]  # one line each, numbered from 1
    assert "window 2 below" in rows[1] and "payload_kg=2" in rows[1]
    assert "monitor_" not in text.replace("acq monitor's", "") and "alarm_" not in text
    flat = " ".join(text.split())
    assert "acq monitor's own tags (window number, identity, alarm rules, bench facts) not shown: --json has every " \
           "tag" in flat and "window 2 skipped: verdict not excited" in flat
    assert re.search(r"^\s*window ┃", text, re.M)


def test_trend_without_a_baseline_says_what_it_needs_and_shows_a_missing_interval_as_one_dash() -> None:
    failed = Entry("id0", "id0", "/s/0.h5", "joint1", "2026-11-29T19:50:02.5+00:00", {}, None, [], "0.h5: too short",
                   None, (None, None), None, None, "{}", "2026-11-30T00:00:00+00:00", None)
    trend = compute_trend("joint1", [failed])
    wide = render(trend_table(trend), width=200)
    assert "—–—" not in wide and re.search(r"│ +— +│", wide)
    assert ("no baseline yet (it needs 1 session of verdict ok, 0 so far); ALARM below −10 % (threshold) or EWMA "
            "(λ = 0.2) below its −3σ limit (EWMA); rules: acq's defaults #1 skipped") in " ".join(wide.split())
    assert "σ =" not in wide and "baseline —" not in wide


def test_batch_table_wraps_a_long_error_and_keeps_K_whole() -> None:
    done = {"K_Nm_per_rad": 893.41, "quality": {"verdict": "ok"}}
    error = ("/srv/sessions/2026-11-29T19-55-04_joint1.h5: signals last 0.600 s; the FRF needs at least 0.750 s "
             "(two 0.5 s Welch segments)")
    report = BatchReport([Outcome("/srv/sessions/2026-11-29T19-55-02_joint1.h5", "a", "{}", {"joint": "joint1"}, done,
                                  None, 1.0),
                          Outcome("/srv/sessions/2026-11-29T19-55-04_joint1.h5", "b", "{}", {"joint": "joint1"}, None,
                                  error, 0.1)], [], 1.4)
    text = render(batch_table(report))
    for value in ("2026-11-29T19-55-02_joint1.h5", "893.4", "failed", "Welch", "joint joint1", "2 analysed (1 failed)"):
        assert value in text, value
    failed = {"K_Nm_per_rad": 8904.2, "quality": {"verdict": "failed"}}  # a failed verdict's K is not a result
    report = BatchReport([Outcome("/s/a_joint1.h5", "a", "{}", {"joint": "joint1"}, failed, None, 1.0)], [], 1.0)
    assert " a_joint1.h5 │       — │ failed  \n" in render(batch_table(report))


def test_summary_table_at_80_columns() -> None:
    summary = SessionSummary("/tmp/disp/2026-11-29T19-54-08_joint1.h5", "joint1", "complete", "recorded 10 s",
                             "2026-11-29T19:54:08.123+00:00",
                             (StreamSummary("current", 256000, 10.0, 25600.0, 25599.04, 0, 0, 25599.11),
                              StreamSummary("encoder", 10000, 10.0, 1000.0, 1061.35, 3, 12, 999.96)), 0)
    text = " ".join(render(summary_table(summary)).split())  # the title and caption wrap at spaces
    for value in ("256000", "25600.0", "25599.11", "999.96", "12", "missing", "2026-11-29 19:54:08 UTC",
                  "recorded 10 s", "rate fit", "(Theil–Sen) line", "not shown at this width: first–last Hz"):
        assert value in text, value
    assert "1061.35" not in text  # the first-to-last rate, left out at 80 columns (the caption says so)
    assert "1061.35" in render(summary_table(summary), width=120)


def test_the_rate_is_a_line_through_the_host_stamps_that_a_late_start_and_a_burst_do_not_move() -> None:
    """The new-user trial's CANopen session: its first TPDOs reached the host late, then in a burst; acq info said
    1061.35 Hz of a 1000 Hz drive (first to last host stamp) while acq selftest said "period 0.9999 ms"."""
    rng = np.random.default_rng(1)
    index = np.arange(4043)
    host_s = 1e-3 * index + 0.4e-3 + rng.exponential(0.2e-3, index.size)  # on time, with the bus's latency
    host_s[:250] = 0.25 + 5e-6 * index[:250]  # the first 250 held back 0.25 s, then in a burst 5 µs apart
    host_ns = (1e9 * host_s).astype(np.int64)
    first_last = (index[-1] - index[0]) / (host_s[-1] - host_s[0])
    assert first_last > 1060.0  # what acq info showed
    assert fitted_rate(index, host_ns) == pytest.approx(1000.0, rel=1e-4)
    assert np.isnan(fitted_rate(index[:1], host_ns[:1]))


def test_devices_table_at_80_columns_wraps_reasons_at_spaces() -> None:
    sections = [Section("NI-DAQmx devices", [("cDAQ1Mod1", "NI 9234", "cDAQ1Mod1/ai0, cDAQ1Mod1/ai1, cDAQ1Mod1/ai2")]),
                Section("CAN interfaces (python-can)", empty_because="python-can detects no CAN interface (no adapter "
                                                                     "plugged in, or its driver is missing)"),
                Section("Simulated bench", [("sim", "simulated DAQ + drive", "configs/benches/sim.toml")])]
    text = render(sections_table(sections))
    for value in ("cDAQ1Mod1/ai0,", "NI 9234", "Simulated bench", "configs/benches/sim.toml", "adapter"):
        assert value in text, value
