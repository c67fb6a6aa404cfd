"""Accuracy of the identification on the scenario family, ours next to the paper's pipeline (prints figures).

    nice -n 10 python bench/accuracy.py [--seeds 5 | --seed-list 0,1,2] [--jobs 2] [--scenarios 1,7] [--markdown]
                                        [--set family | limits] [--fit amplitude | complex]

The scenarios are the table :data:`bench.scenarios.SCENARIOS` (issue 13): the paper's plant and scaled
plants (K and the inertias ×0.5–2 while the bench's *nominal* values stay the paper's), then load
friction, backlash, a third mass, trapezoid/S-curve profiles, speed loops, a heavy arm, DAQ rates with
and without anti-alias filter, PWM ripple, quantisation, mains hum, offset drift, per-phase gain errors,
encoder rates and resolutions, gaps, clock offsets to ±2 s and drifts to ±100 ppm, records of 3 and 60 s.
Each scenario states the outcome expected *before* running: ``ok`` within its tolerance, or ``not ok``
with a reason. Every run records a 10 s (unless the scenario is about length) simulated session through
the real recorder (``--fast``) with the seed's noise and, unless the scenario fixes the clock, a DAQ
offset of 10–60 ms and a drift of 20–60 ppm of random signs; the same session is analysed twice:
``request_for(session)`` (ours: clock alignment, encoder-demodulated or Park torque, anti-alias
resampling, coherence weights) and ``pipeline="paper"`` (Hilbert torque, no alignment, linear
resampling, uniform weights); ``--fit complex`` makes ours fit the complex FRF (``acq analyze --fit complex``) instead
of its amplitude. ``--set limits`` runs :data:`bench.scenarios.LIMITS` instead: combinations beyond the
family that measure where the misfit tests stop seeing a third mode.

Printed: every run (errors on K, J_m, J_l, C in %, whether the 95 % interval holds the truth, clock
offset / drift error, verdict), a summary per scenario (worst errors ours / paper, fraction of intervals
holding the truth, verdict counts, confident-wrong count, whether the expectation held), the interval
coverage over all excited runs, and loudly every **confident wrong** result: verdict ``ok`` with an error
beyond the scenario's tolerance or the truth outside an interval. Exit code 1 if there is any.
"""

from __future__ import annotations

import argparse
import math
import multiprocessing as mp
import os
import re
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

from bench.scenarios import (LABEL, PARAMS, SETS, Scenario, confident_wrong, errors_pct,  # noqa: E402
                             interval_holds, run_scenario)


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
    wrong: tuple[str, ...] = ()


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


def _outcome(sc: Scenario, res, truth: dict, seconds: float, aligned: bool) -> Outcome:
    err = errors_pct(res, truth)
    in_ci = interval_holds(res, truth)
    if aligned:
        off = 1e6 * (res.clock.offset_s - truth["daq_offset_s"])
        drift = res.clock.drift_ppm - truth["daq_drift_ppm"]
    else:  # the paper's chain does not align: its clock error is the whole offset and drift
        off, drift = -1e6 * truth["daq_offset_s"], -truth["daq_drift_ppm"]
    verdict = res.quality.verdict
    return Outcome(err, in_ci, verdict, tuple(res.quality.reasons), float(off), float(drift), seconds,
                   tuple(confident_wrong(sc, verdict, err, in_ci)))


@dataclass(frozen=True)
class Task:
    """One run to do: scenario ``index`` of the set ``set_name`` (:data:`bench.scenarios.SETS`), ``seed``, and the
    fit ours uses (``acq analyze --fit``)."""

    set_name: str
    index: int
    seed: int
    fit: str = "amplitude"


def run_one(task: Task) -> Run:
    """Record one scenario run and analyse it with both pipelines."""
    scenarios, clock_base = SETS[task.set_name]
    sc = scenarios[task.index]
    ours, paper, truth, (offset_s, drift_ppm), (t_ours, t_paper) = run_scenario(sc, task.seed, clock_base + task.index,
                                                                                fit=task.fit)
    return Run(sc.name, task.seed, 1e3 * offset_s, drift_ppm, _outcome(sc, ours, truth, t_ours, True),
               _outcome(sc, paper, truth, t_paper, False), tuple(ours.notes))


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


def runs_table(runs: list[Run], scenarios: tuple[Scenario, ...]) -> Table:
    t = Table(title="every run — errors in %, 95 % CI holds truth for K J_m J_l C (✓/✗), clock error",
              caption="red: past the scenario's tolerance; ok WRONG: a confident wrong result", show_lines=False)
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
    by_name = {s.name: s for s in scenarios}
    for r in runs:
        sc = by_name[r.scenario]
        tol = {"K_Nm_per_rad": sc.tol_K, "Jm_kgm2": sc.tol_J, "Jl_kgm2": sc.tol_J, "C_Nms_per_rad": None}
        row = [r.scenario, str(r.seed), f"{r.offset_ms:+.1f}", f"{r.drift_ppm:+.1f}"]
        for who, o in (("ours", r.ours), ("paper", r.paper)):
            row += [_pct(o.err_pct[p], None if sc.must_not_be_ok else tol[p]) for p in PARAMS]
            row.append(_ci(o))
            if who == "ours":
                row += [f"{o.offset_err_us:+.1f}", f"{o.drift_err_ppm:+.2f}"]
            row.append("[bold red]ok WRONG[/bold red]" if o.wrong else _verdict(o.verdict))
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
    wrong: dict[str, int]  # who → confident-wrong runs
    as_expected: int  # runs of ours whose outcome is the expected one (ok within tolerance / not ok)
    reasons: tuple[str, ...]  # distinct reasons ours gave when it declined

    @property
    def meets(self) -> bool:
        """The issue-13 criterion for ours: no confident wrong result."""
        return self.wrong["ours"] == 0


def summarize(runs: list[Run], scenarios: tuple[Scenario, ...]) -> list[Summary]:
    out = []
    for sc in scenarios:
        rs = [r for r in runs if r.scenario == sc.name]
        if not rs:
            continue
        worst, rms, cov, verd, wrong = {}, {}, {}, {}, {}
        for who in ("ours", "paper"):
            os_ = [getattr(r, who) for r in rs]
            worst[who] = {p: max(abs(o.err_pct[p]) for o in os_) for p in PARAMS}
            rms[who] = {p: float(np.sqrt(np.mean([o.err_pct[p] ** 2 for o in os_]))) for p in PARAMS}
            cov[who] = {p: float(np.mean([o.in_ci[p] for o in os_])) for p in PARAMS}
            verd[who] = {v: sum(o.verdict == v for o in os_) for v in ("ok", "poor", "failed")}
            wrong[who] = sum(bool(o.wrong) for o in os_)
        expected = sum((r.ours.verdict == "ok" and not r.ours.wrong) if sc.expect == "ok" else r.ours.verdict != "ok"
                       for r in rs)
        first = {re.sub(r"[0-9.]+", "#", r.ours.reasons[0]): r.ours.reasons[0]  # one per kind, numbers aside
                 for r in rs if r.ours.verdict != "ok" and r.ours.reasons}
        reasons = tuple(first.values())
        out.append(Summary(sc, len(rs), worst, rms, cov, verd,
                           max(abs(r.ours.offset_err_us) for r in rs), max(abs(r.ours.drift_err_ppm) for r in rs),
                           wrong, expected, reasons))
    return out


def _verdicts(d: dict[str, int]) -> str:
    return " ".join(f"{v} {d[v]}" for v in ("ok", "poor", "failed") if d[v])


def summary_table(summ: list[Summary], scenarios: tuple[Scenario, ...]) -> Table:
    t = Table(title="summary per scenario — worst |error| % over seeds (ours / paper), "
                    "fraction of runs whose 95 % CI holds the truth, confident wrong (ok beyond tolerance or "
                    "truth outside the interval)")
    for col in ("#", "scenario", "expected", "seeds", "K %", "J_m %", "J_l %", "C %", "CI holds truth\nK, J_m, J_l, C",
                "clock worst\nµs / ppm", "verdicts ours", "verdicts paper", "confident\nwrong", "as\nexpected"):
        left = col in ("scenario", "expected", "verdicts ours", "verdicts paper")
        t.add_column(col, justify="left" if left else "right")
    index = {sc.name: i + 1 for i, sc in enumerate(scenarios)}
    for s in summ:
        sc = s.scenario
        expected = f"ok ≤{sc.tol_K:g}/{sc.tol_J:g} %" if sc.expect == "ok" else f"not ok: {sc.reason}"
        wrong = f"[red]{s.wrong['ours']}[/red]" if s.wrong["ours"] else "[green]0[/green]"
        t.add_row(str(index[sc.name]), sc.name, expected, str(s.n),
                  *(f"{s.worst['ours'][p]:.2f} / {s.worst['paper'][p]:.1f}" for p in PARAMS),
                  " ".join(f"{s.coverage['ours'][p]:.0%}" for p in PARAMS) + "\n"
                  + "[dim]paper " + " ".join(f"{s.coverage['paper'][p]:.0%}" for p in PARAMS) + "[/dim]",
                  f"{s.worst_offset_us:.1f} / {s.worst_drift_ppm:.2f}",
                  _verdicts(s.verdicts["ours"]), _verdicts(s.verdicts["paper"]),
                  f"{wrong}\n[dim]paper {s.wrong['paper']}[/dim]", f"{s.as_expected}/{s.n}")
    return t


def coverage_overall(summ: list[Summary], who: str) -> dict[str, float]:
    """Fraction of the runs of every scenario expected ``ok`` (excited) whose interval holds the truth."""
    ss = [s for s in summ if s.scenario.expect == "ok"]
    n = sum(s.n for s in ss)
    return {p: sum(s.coverage[who][p] * s.n for s in ss) / n for p in PARAMS} if n else {}


def confident_wrong_lines(runs: list[Run], who: str = "ours") -> list[str]:
    """Every run whose verdict is ok while an error is past the tolerance or the truth is outside an interval."""
    return [f"{r.scenario} seed {r.seed}: " + "; ".join(getattr(r, who).wrong) for r in runs if getattr(r, who).wrong]


def markdown(summ: list[Summary]) -> str:
    """The summary as a Markdown table (for README.md)."""
    lines = ["| scenario | expected | seeds | K % ours / paper | J_m % ours / paper | J_l % ours / paper "
             "| CI holds truth K, J_m, J_l (ours) | verdicts ours | confident wrong ours / paper "
             "| what acq says when it declines |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for s in summ:
        sc = s.scenario
        expected = f"ok ±{sc.tol_K:g}/±{sc.tol_J:g} %" if sc.expect == "ok" else f"not ok ({sc.reason})"
        lines.append(f"| {sc.name} | {expected} | {s.n} | "
                     + " | ".join(f"{s.worst['ours'][p]:.2f} / {s.worst['paper'][p]:.1f}" for p in PARAMS[:3])
                     + " | " + ", ".join(f"{s.coverage['ours'][p]:.0%}" for p in PARAMS[:3])
                     + f" | {_verdicts(s.verdicts['ours'])} | {s.wrong['ours']} / {s.wrong['paper']} | "
                     + "; ".join(r.replace("|", "/") for r in s.reasons) + " |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=5, help="number of seeds, 0 … N−1 (default 5)")
    parser.add_argument("--seed-list", type=str, default=None, help="explicit seeds, e.g. 3,7,11 (overrides --seeds)")
    parser.add_argument("--scenarios", type=str, default=None,
                        help="comma-separated scenario numbers of the set, from 1 (default all)")
    parser.add_argument("--jobs", type=int, default=min(2, os.cpu_count() or 1), help="worker processes")
    parser.add_argument("--markdown", action="store_true", help="also print the summary as a Markdown table")
    parser.add_argument("--brief", action="store_true", help="summary only, not every run")
    parser.add_argument("--set", choices=tuple(SETS), default="family",
                        help="the scenario family (default) or the combinations beyond it (limits)")
    parser.add_argument("--fit", choices=("amplitude", "complex"), default="amplitude",
                        help="the fit ours uses, as acq analyze --fit (the paper's chain always fits the amplitude)")
    args = parser.parse_args(argv)
    scenarios = SETS[args.set][0]
    seeds = [int(s) for s in args.seed_list.split(",")] if args.seed_list else list(range(args.seeds))
    chosen = ([int(s) - 1 for s in args.scenarios.split(",")] if args.scenarios else list(range(len(scenarios))))
    tasks = [Task(args.set, i, s, args.fit) for i in chosen for s in seeds]
    tasks.sort(key=lambda t: -scenarios[t.index].duration_s)  # the longest first: the pool ends together
    console = Console(width=max(Console().width, 200)) if not sys.stdout.isatty() else Console()
    console.print(f"set {args.set}, ours fits the {args.fit}; scenarios: "
                  + "; ".join(f"{i + 1} {scenarios[i].name}" for i in chosen))

    t0 = time.perf_counter()
    runs: list[Run] = []
    with Progress(TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn(),
                  console=console, transient=False) as progress:
        bar = progress.add_task(f"recording + analysing ({args.jobs} processes)", total=len(tasks))
        if args.jobs > 1:
            with mp.get_context("fork").Pool(args.jobs) as pool:
                for r in pool.imap_unordered(run_one, tasks):
                    runs.append(r)
                    progress.advance(bar)
        else:
            for task in tasks:
                runs.append(run_one(task))
                progress.advance(bar)
    order = {name: i for i, name in enumerate(s.name for s in scenarios)}
    runs.sort(key=lambda r: (order[r.scenario], r.seed))
    wall = time.perf_counter() - t0

    if not args.brief:
        console.print(runs_table(runs, scenarios))
    summ = summarize(runs, scenarios)
    console.print(summary_table(summ, scenarios))
    for who in ("ours", "paper"):
        cov = coverage_overall(summ, who)
        if cov:
            console.print(f"95 % CI holds the truth ({who}, runs of the scenarios expected ok): "
                          + ", ".join(f"{LABEL[p]} {cov[p]:.0%}" for p in PARAMS))
    t_ours = np.mean([r.ours.seconds for r in runs])
    t_paper = np.mean([r.paper.seconds for r in runs])
    n_ok = sum(r.ours.verdict == "ok" for r in runs)
    console.print(f"{len(runs)} runs in {wall:.0f} s wall; analysis per session: ours {t_ours:.2f} s, "
                  f"paper {t_paper:.2f} s (wall, {args.jobs} processes sharing the cores); ours: {n_ok} ok, "
                  f"{sum(s.as_expected for s in summ)}/{len(runs)} as expected")
    wrong = confident_wrong_lines(runs)
    beyond = [r for r in runs if any("tol" in w for w in r.ours.wrong)]
    console.print(f"ok beyond the scenario's tolerance (ours; issue 13's criterion: none): {len(beyond)}; ok with the truth "
                  f"outside a 95 % interval while within tolerance: {len(wrong) - len(beyond)} "
                  f"(a calibrated interval misses ~5 % of runs; the coverage is above)")
    if wrong:
        console.print(f"[bold red]CONFIDENT WRONG (ours): {len(wrong)} of {n_ok} ok verdicts[/bold red]")
        for w in wrong:
            console.print(f"  {w}", markup=False)
    else:
        console.print("[green]no confident wrong result (ours): no ok verdict beyond its tolerance or with the truth "
                      "outside its interval[/green]")
    console.print(f"confident wrong (paper's chain): {len(confident_wrong_lines(runs, 'paper'))}")
    if args.markdown:
        console.print(markdown(summ), markup=False, highlight=False, soft_wrap=True)
    return 0 if all(s.meets for s in summ) else 1


if __name__ == "__main__":
    raise SystemExit(main())
