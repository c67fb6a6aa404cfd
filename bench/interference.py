"""Accuracy, interval coverage and verdicts under one-phase interference (prints figures; not a test).

    python bench/interference.py [--seeds 10] [--jobs 2] [--cases 1,2]

Each run is a 10 s simulated session of the paper's plant (0.2 s triangle, 1 kHz encoder, DAQ clock
offset 10–60 ms and drift 20–60 ppm as in bench/accuracy.py) with interference added to i_a after
recording (:func:`tests.interference.with_interference`): mains hum with 3rd and 5th harmonics and a
random-walk sensor offset, or tones at 2–4 kHz on a 10 kS/s current (a drive's PWM ripple folded by
a DAQ without anti-alias filter). Printed per case: worst |error| of K, J_m, J_l, the fraction of
runs whose 95 % interval holds the truth, the median relative half-width, the verdicts, and every
``ok`` whose error passes K 2 % / J 4 % or whose interval misses the truth.
"""

from __future__ import annotations

import argparse
import multiprocessing as mp
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

PARAMS = ("K_Nm_per_rad", "Jm_kgm2", "Jl_kgm2")
CASES: tuple[tuple[str, float | None, dict], ...] = (
    ("none, 25.6 kS/s", None, {}),
    ("hum 20 mA 50 Hz + drift 40 mA", None, dict(hum_A=0.020, drift_A=0.040)),
    ("hum 20 mA 60 Hz + drift 40 mA", None, dict(hum_A=0.020, mains_hz=60.0, drift_A=0.040)),
    ("none, 10 kS/s", 10000.0, {}),
    ("2 tones 25 mA 2–4 kHz, 10 kS/s", 10000.0, dict(tones_A=0.025, n_tones=2)),
    ("tones + hum + drift, 10 kS/s", 10000.0, dict(tones_A=0.025, n_tones=2, hum_A=0.020, drift_A=0.040)),
)


def run_one(task: tuple[int, int]) -> tuple[int, int, list[float], list[bool], list[float], str, tuple[str, ...]]:
    from analysis import AnalysisRequest, analyze
    from bench.scenarios import clock_for
    from tests.interference import with_interference
    from tests.test_analysis_pipeline import sim_recording

    case, seed = task
    _, rate, kw = CASES[case]
    offset_s, drift_ppm = clock_for(seed, 0)
    rec, truth, nominal = sim_recording(seed=seed, daq_offset_s=offset_s, daq_drift_ppm=drift_ppm,
                                        host_jitter_s=0.0002, current_noise_A=0.01, daq_rate_hz=rate)
    if kw:
        rec = with_interference(rec, seed, **kw)
    res = analyze(rec, AnalysisRequest(nominal=nominal))
    err = [100.0 * (getattr(res.fit.values, n) / truth[n] - 1.0) for n in PARAMS]
    inside = [bool(res.fit.ci95[n][0] <= truth[n] <= res.fit.ci95[n][1]) for n in PARAMS]
    half = [100.0 * res.quality.ci_rel_halfwidth.get(n, np.nan) for n in PARAMS]
    return case, seed, err, inside, half, res.quality.verdict, (*res.quality.reasons, *res.notes)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=10)
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--cases", type=str, default=None, help="comma-separated case numbers 1…%d" % len(CASES))
    args = parser.parse_args(argv)
    chosen = [int(c) - 1 for c in args.cases.split(",")] if args.cases else list(range(len(CASES)))
    tasks = [(c, s) for c in chosen for s in range(args.seeds)]
    with mp.get_context("fork").Pool(args.jobs) as pool:
        runs = sorted(pool.map(run_one, tasks))
    bad = []
    print(f"{'case':36s} {'worst |err| % K J_m J_l':>24s} {'CI holds truth':>16s} {'median ±% (95 %)':>18s}  verdicts")
    for c in chosen:
        rs = [r for r in runs if r[0] == c]
        err = np.abs([r[2] for r in rs])
        cov = np.mean([r[3] for r in rs], axis=0)
        half = np.median([r[4] for r in rs], axis=0)
        verdicts = {v: sum(r[5] == v for r in rs) for v in ("ok", "poor", "failed")}
        print(f"{CASES[c][0]:36s} {' '.join(f'{x:6.2f}' for x in err.max(axis=0)):>24s} "
              f"{' '.join(f'{x:4.0%}' for x in cov):>16s} {' '.join(f'{x:5.2f}' for x in half):>18s}  "
              + " ".join(f"{v} {n}" for v, n in verdicts.items() if n))
        for r in rs:
            if r[5] == "ok" and (abs(r[2][0]) > 2.0 or max(abs(r[2][1]), abs(r[2][2])) > 4.0 or not all(r[3])):
                bad.append(f"{CASES[c][0]} seed {r[1]}: ok with errors {np.round(r[2], 2).tolist()} %, "
                           f"truth in CI {r[3]}")
    for r in runs:
        if r[5] != "ok":
            print(f"  {CASES[r[0]][0]} seed {r[1]}: {r[5]} — {r[6][0] if r[6] else ''}")
    print("notes of seed 0: " + " | ".join(f"{CASES[r[0]][0]}: {[n for n in r[6] if 'current' in n]}"
                                            for r in runs if r[1] == 0))
    print("\n".join(bad) if bad else "no ok verdict past K 2 % / J 4 % or with the truth outside its interval")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
