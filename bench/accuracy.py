"""Accuracy of the identification on the simulated bench, ours next to the paper's pipeline (prints figures).

    python bench/accuracy.py [--seeds 10 | --seed-list 0,1,2] [--jobs 2] [--scenarios 1,7] [--markdown]

Every run is one 10 s simulated session (0.2 s triangle, 25.6 kS/s current, 1 kHz encoder, host
jitter 0.2 ms, current noise) with a DAQ clock offset of 10–60 ms and a drift of 20–60 ppm, each
of random sign (drawn from the seed). The plant is the paper's, or the paper's with K and the
inertias scaled by 0.5–2 while the bench's *nominal* values stay the paper's, so the fit cannot
lean on them. The same recording is analysed twice: ``AnalysisOptions()`` (ours: clock alignment,
encoder-demodulated torque, anti-alias resampling, coherence weights) and
``AnalysisOptions(pipeline="paper")`` (Hilbert torque, no alignment, linear resampling, uniform
weights). The paper's slow 0.5 s profile is run too: its verdict must not be ``ok``.

Printed: every run (errors on K, J_m, J_l, C in %, whether the 95 % interval holds the truth,
clock offset / drift error, verdict), then a summary per scenario with the worst errors, the
fraction of intervals holding the truth, and the issue-4 criterion (|error| ≤ 1 % K, ≤ 2 % J on
the paper's plant; ≤ 2 % / 4 % on the scaled plants), then anything suspicious (an ``ok`` verdict
with the truth outside its interval or an error past the criterion).
"""

from __future__ import annotations

import argparse
import math
import multiprocessing as mp
import os
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from rich.console import Console
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn
from rich.table import Table

ROOT = Path(__file__).resolve().parent.parent
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

PARAMS = ("K_Nm_per_rad", "Jm_kgm2", "Jl_kgm2", "C_Nms_per_rad")
LABEL = {"K_Nm_per_rad": "K", "Jm_kgm2": "J_m", "Jl_kgm2": "J_l", "C_Nms_per_rad": "C"}


@dataclass(frozen=True)
class Scenario:
    """A plant (factors on the paper's K, J_m, J_l) and a profile; tolerances of issue 4 (%, K and J)."""

    name: str
    k: float = 1.0
    jm: float = 1.0
    jl: float = 1.0
    accel_time_s: float = 0.2
    tol_K: float = 1.0
    tol_J: float = 2.0
    must_not_be_ok: bool = False


SCENARIOS: tuple[Scenario, ...] = (
    Scenario("paper plant"),
    Scenario("K ×0.5", k=0.5, tol_K=2.0, tol_J=4.0),
    Scenario("K ×2", k=2.0, tol_K=2.0, tol_J=4.0),
    Scenario("J_m ×2, J_l ×0.5", jm=2.0, jl=0.5, tol_K=2.0, tol_J=4.0),
    Scenario("J_m ×0.5, J_l ×2", jm=0.5, jl=2.0, tol_K=2.0, tol_J=4.0),
    Scenario("K ×0.5, J_m ×2, J_l ×0.5", k=0.5, jm=2.0, jl=0.5, tol_K=2.0, tol_J=4.0),
    Scenario("K ×2, J ×0.5 (stiff)", k=2.0, jm=0.5, jl=0.5, tol_K=2.0, tol_J=4.0),
    Scenario("K ×0.5, J ×2 (soft)", k=0.5, jm=2.0, jl=2.0, tol_K=2.0, tol_J=4.0),
    Scenario("paper plant, 0.5 s profile", accel_time_s=0.5, must_not_be_ok=True),
)


@dataclass
class Outcome:
    """One pipeline on one recording."""

    err_pct: dict[str, float]
    in_ci: dict[str, bool]
    verdict: str
    reasons: tuple[str, ...]
    offset_err_us: float
    drift_err_ppm: float
    seconds: float


@dataclass
class Run:
    """One scenario × seed: the clock it had and both pipelines' outcomes."""

    scenario: str
    seed: int
    offset_ms: float
    drift_ppm: float
    ours: Outcome
    paper: Outcome
    notes: tuple[str, ...] = field(default_factory=tuple)


def clock_for(seed: int, scenario_index: int) -> tuple[float, float]:
    """DAQ offset (s) and drift (ppm) of a run: |offset| 10–60 ms, |drift| 20–60 ppm, random signs."""
    rng = np.random.default_rng([seed, scenario_index, 4])
    sign = rng.choice([-1.0, 1.0], size=2)
    return float(sign[0] * rng.uniform(0.010, 0.060)), float(sign[1] * rng.uniform(20.0, 60.0))


def _outcome(res, truth: dict, seconds: float, aligned: bool) -> Outcome:
    v = res.fit.values
    err = {n: 100.0 * (getattr(v, n) - truth[n]) / truth[n] for n in PARAMS}
    in_ci = {n: bool(res.fit.ci95[n][0] <= truth[n] <= res.fit.ci95[n][1]) for n in PARAMS}
    if aligned:
        off = 1e6 * (res.clock.offset_s - truth["daq_offset_s"])
        drift = res.clock.drift_ppm - truth["daq_drift_ppm"]
    else:  # the paper's chain does not align: its clock error is the whole offset and drift
        off, drift = -1e6 * truth["daq_offset_s"], -truth["daq_drift_ppm"]
    return Outcome(err, in_ci, res.quality.verdict, tuple(res.quality.reasons), float(off), float(drift), seconds)


def run_one(task: tuple[int, int]) -> Run:
    """Simulate one session and analyse it with both pipelines."""
    from analysis.pipeline import AnalysisOptions, analyze
    from drivers.config import SimSettings
    from tests.test_analysis_pipeline import sim_recording

    scenario_index, seed = task
    sc = SCENARIOS[scenario_index]
    base = SimSettings()
    offset_s, drift_ppm = clock_for(seed, scenario_index)
    rec, truth, nominal = sim_recording(
        accel_time_s=sc.accel_time_s, seed=seed, daq_offset_s=offset_s, daq_drift_ppm=drift_ppm,
        host_jitter_s=0.0002, current_noise_A=0.01,
        K_Nm_per_rad=base.K_Nm_per_rad * sc.k, Jm_kgm2=base.Jm_kgm2 * sc.jm, Jl_kgm2=base.Jl_kgm2 * sc.jl)
    t0 = time.perf_counter()
    ours = analyze(rec, AnalysisOptions(nominal=nominal))
    t1 = time.perf_counter()
    paper = analyze(rec, AnalysisOptions(nominal=nominal, pipeline="paper"))
    t2 = time.perf_counter()
    return Run(sc.name, seed, 1e3 * offset_s, drift_ppm, _outcome(ours, truth, t1 - t0, True),
               _outcome(paper, truth, t2 - t1, False), tuple(ours.notes))


# ---- printing ----------------------------------------------------------------------------------------
def _pct(x: float, tol: float | None = None) -> str:
    if not math.isfinite(x):
        return "—"
    s = f"{x:+.2f}"
    return f"[red]{s}[/red]" if tol is not None and abs(x) > tol else s


def _ci(o: Outcome) -> str:
    return "".join("✓" if o.in_ci[n] else "✗" for n in PARAMS)


def _verdict(v: str) -> str:
    return {"ok": "[green]ok[/green]", "poor": "[yellow]poor[/yellow]"}.get(v, f"[red]{v}[/red]")


def runs_table(runs: list[Run]) -> Table:
    t = Table(title="every run — errors in %, 95 % CI holds truth for K J_m J_l C (✓/✗), clock error",
              caption="red: past the issue-4 criterion of the scenario", show_lines=False)
    for col in ("scenario", "seed", "offset\nms", "drift\nppm"):
        t.add_column(col, justify="left" if col == "scenario" else "right")
    for who in ("ours", "paper"):
        for p in PARAMS:
            t.add_column(f"{who}\n{LABEL[p]} %", justify="right")
        t.add_column(f"{who}\nCI", justify="center")
        if who == "ours":
            t.add_column("Δoffset\nµs", justify="right")
            t.add_column("Δdrift\nppm", justify="right")
        t.add_column(f"{who}\nverdict")
    by_name = {s.name: s for s in SCENARIOS}
    for r in runs:
        sc = by_name[r.scenario]
        tol = {"K_Nm_per_rad": sc.tol_K, "Jm_kgm2": sc.tol_J, "Jl_kgm2": sc.tol_J, "C_Nms_per_rad": None}
        row = [r.scenario, str(r.seed), f"{r.offset_ms:+.1f}", f"{r.drift_ppm:+.1f}"]
        for who, o in (("ours", r.ours), ("paper", r.paper)):
            row += [_pct(o.err_pct[p], None if sc.must_not_be_ok else tol[p]) for p in PARAMS]
            row.append(_ci(o))
            if who == "ours":
                row += [f"{o.offset_err_us:+.1f}", f"{o.drift_err_ppm:+.2f}"]
            row.append(_verdict(o.verdict))
        t.add_row(*row)
    return t


@dataclass
class Summary:
    scenario: Scenario
    n: int
    worst: dict[str, dict[str, float]]  # who → param → max |error| %
    rms: dict[str, dict[str, float]]
    coverage: dict[str, dict[str, float]]  # who → param → fraction of runs with truth in CI
    verdicts: dict[str, dict[str, int]]
    worst_offset_us: float
    worst_drift_ppm: float
    meets: bool


def summarize(runs: list[Run]) -> list[Summary]:
    out = []
    for sc in SCENARIOS:
        rs = [r for r in runs if r.scenario == sc.name]
        if not rs:
            continue
        worst, rms, cov, verd = {}, {}, {}, {}
        for who in ("ours", "paper"):
            os_ = [getattr(r, who) for r in rs]
            worst[who] = {p: max(abs(o.err_pct[p]) for o in os_) for p in PARAMS}
            rms[who] = {p: float(np.sqrt(np.mean([o.err_pct[p] ** 2 for o in os_]))) for p in PARAMS}
            cov[who] = {p: float(np.mean([o.in_ci[p] for o in os_])) for p in PARAMS}
            verd[who] = {v: sum(o.verdict == v for o in os_) for v in ("ok", "poor", "failed")}
        if sc.must_not_be_ok:
            meets = verd["ours"]["ok"] == 0
        else:
            meets = (worst["ours"]["K_Nm_per_rad"] <= sc.tol_K and worst["ours"]["Jm_kgm2"] <= sc.tol_J
                     and worst["ours"]["Jl_kgm2"] <= sc.tol_J)
        out.append(Summary(sc, len(rs), worst, rms, cov, verd,
                           max(abs(r.ours.offset_err_us) for r in rs), max(abs(r.ours.drift_err_ppm) for r in rs),
                           meets))
    return out


def _verdicts(d: dict[str, int]) -> str:
    return " ".join(f"{v} {d[v]}" for v in ("ok", "poor", "failed") if d[v])


def summary_table(summ: list[Summary]) -> Table:
    t = Table(title="summary per scenario — worst |error| % over seeds (ours / paper), "
                    "fraction of runs whose 95 % CI holds the truth")
    for col in ("scenario", "seeds", "K %", "J_m %", "J_l %", "C %", "CI holds truth\nK, J_m, J_l, C",
                "clock worst\nµs / ppm", "verdicts ours", "verdicts paper", "criterion"):
        t.add_column(col, justify="left" if col in ("scenario", "verdicts ours", "verdicts paper") else "right")
    for s in summ:
        crit = (f"not ok: {'[green]yes[/green]' if s.meets else '[red]NO[/red]'}" if s.scenario.must_not_be_ok else
                f"≤{s.scenario.tol_K:g}/{s.scenario.tol_J:g} %: "
                f"{'[green]met[/green]' if s.meets else '[red]MISSED[/red]'}")
        t.add_row(s.scenario.name, str(s.n),
                  *(f"{s.worst['ours'][p]:.2f} / {s.worst['paper'][p]:.1f}" for p in PARAMS),
                  " ".join(f"{s.coverage['ours'][p]:.0%}" for p in PARAMS) + "\n"
                  + "[dim]paper " + " ".join(f"{s.coverage['paper'][p]:.0%}" for p in PARAMS) + "[/dim]",
                  f"{s.worst_offset_us:.1f} / {s.worst_drift_ppm:.2f}",
                  _verdicts(s.verdicts["ours"]), _verdicts(s.verdicts["paper"]), crit)
    return t


def coverage_overall(summ: list[Summary], who: str) -> dict[str, float]:
    """Fraction of all excited runs (not the 0.5 s profile) whose interval holds the truth."""
    ss = [s for s in summ if not s.scenario.must_not_be_ok]
    n = sum(s.n for s in ss)
    return {p: sum(s.coverage[who][p] * s.n for s in ss) / n for p in PARAMS} if n else {}


def suspicious(runs: list[Run]) -> list[str]:
    """Runs whose verdict is ok while the truth lies outside the interval or the error passes the criterion."""
    by_name = {s.name: s for s in SCENARIOS}
    out = []
    for r in runs:
        sc = by_name[r.scenario]
        for who, o in (("ours", r.ours), ("paper", r.paper)):
            if o.verdict != "ok":
                continue
            outside = [LABEL[p] for p in PARAMS if not o.in_ci[p]]
            tol = {"K_Nm_per_rad": sc.tol_K, "Jm_kgm2": sc.tol_J, "Jl_kgm2": sc.tol_J}
            past = [f"{LABEL[p]} {o.err_pct[p]:+.2f} %" for p in tol if abs(o.err_pct[p]) > tol[p]]
            if sc.must_not_be_ok:
                out.append(f"{r.scenario} seed {r.seed} ({who}): verdict ok on the 0.5 s profile")
            if outside:
                out.append(f"{r.scenario} seed {r.seed} ({who}): verdict ok but the truth of {', '.join(outside)} "
                           f"is outside the 95 % interval")
            if past and not sc.must_not_be_ok:
                out.append(f"{r.scenario} seed {r.seed} ({who}): verdict ok with {', '.join(past)} past the criterion")
    return out


def markdown(summ: list[Summary], runs: list[Run]) -> str:
    """The summary as a Markdown table (for README.md)."""
    lines = ["| scenario | seeds | K % ours / paper | J_m % ours / paper | J_l % ours / paper | C % ours / paper "
             "| CI holds truth K, J_m, J_l, C (ours) | (paper) | clock worst µs / ppm | verdicts ours | verdicts paper |",
             "|---|---|---|---|---|---|---|---|---|---|---|"]
    for s in summ:
        lines.append(f"| {s.scenario.name} | {s.n} | "
                     + " | ".join(f"{s.worst['ours'][p]:.2f} / {s.worst['paper'][p]:.1f}" for p in PARAMS)
                     + " | " + ", ".join(f"{s.coverage['ours'][p]:.0%}" for p in PARAMS)
                     + " | " + ", ".join(f"{s.coverage['paper'][p]:.0%}" for p in PARAMS)
                     + f" | {s.worst_offset_us:.1f} / {s.worst_drift_ppm:.2f} | {_verdicts(s.verdicts['ours'])} | "
                     + f"{_verdicts(s.verdicts['paper'])} |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=10, help="number of seeds, 0 … N−1 (default 10)")
    parser.add_argument("--seed-list", type=str, default=None, help="explicit seeds, e.g. 3,7,11 (overrides --seeds)")
    parser.add_argument("--scenarios", type=str, default=None,
                        help="comma-separated scenario numbers 1…%d (default all)" % len(SCENARIOS))
    parser.add_argument("--jobs", type=int, default=min(2, os.cpu_count() or 1), help="worker processes")
    parser.add_argument("--markdown", action="store_true", help="also print the summary as a Markdown table")
    parser.add_argument("--brief", action="store_true", help="summary only, not every run")
    args = parser.parse_args(argv)
    seeds = [int(s) for s in args.seed_list.split(",")] if args.seed_list else list(range(args.seeds))
    chosen = ([int(s) - 1 for s in args.scenarios.split(",")] if args.scenarios else list(range(len(SCENARIOS))))
    tasks = [(i, s) for i in chosen for s in seeds]
    console = Console(width=max(Console().width, 200)) if not sys.stdout.isatty() else Console()
    console.print("scenarios: " + "; ".join(f"{i + 1} {SCENARIOS[i].name}" for i in chosen))

    t0 = time.perf_counter()
    runs: list[Run] = []
    with Progress(TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn(),
                  console=console, transient=False) as progress:
        bar = progress.add_task(f"simulating + analysing ({args.jobs} processes)", total=len(tasks))
        if args.jobs > 1:
            with mp.get_context("fork").Pool(args.jobs) as pool:
                for r in pool.imap_unordered(run_one, tasks):
                    runs.append(r)
                    progress.advance(bar)
        else:
            for task in tasks:
                runs.append(run_one(task))
                progress.advance(bar)
    order = {name: i for i, name in enumerate(s.name for s in SCENARIOS)}
    runs.sort(key=lambda r: (order[r.scenario], r.seed))
    wall = time.perf_counter() - t0

    if not args.brief:
        console.print(runs_table(runs))
    summ = summarize(runs)
    console.print(summary_table(summ))
    for who in ("ours", "paper"):
        cov = coverage_overall(summ, who)
        if cov:
            console.print(f"95 % CI holds the truth ({who}, all excited runs): "
                          + ", ".join(f"{LABEL[p]} {cov[p]:.0%}" for p in PARAMS))
    t_ours = np.mean([r.ours.seconds for r in runs])
    t_paper = np.mean([r.paper.seconds for r in runs])
    console.print(f"{len(runs)} runs in {wall:.0f} s wall; analysis per 10 s session: ours {t_ours:.2f} s, "
                  f"paper {t_paper:.2f} s (wall, {args.jobs} processes sharing the cores)")
    warn = suspicious(runs)
    if warn:
        console.print("[bold yellow]suspicious:[/bold yellow]")
        for w in warn:
            console.print(f"  {w}", markup=False)
    else:
        console.print("no ok verdict with the truth outside its interval or past the criterion")
    if args.markdown:
        console.print(markdown(summ, runs), markup=False, highlight=False, soft_wrap=True)
    return 0 if all(s.meets for s in summ) else 1


if __name__ == "__main__":
    raise SystemExit(main())
