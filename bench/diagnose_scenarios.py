"""Does the bench-config diagnosis (analysis/diagnose.py) stay silent on correctly configured benches?

Records every scenario of :data:`bench.scenarios.SCENARIOS` (all configured correctly) for one seed and
prints the electrical-speed ratio (current's f_e against pole_pairs·|ω|, 1 on a correct bench) with its
standard error, and any fault the analysis would name. Exit code 1 if a fault is named.

    python bench/diagnose_scenarios.py [--seed 0]     # 48 scenarios, ~1 min on 2 loaded cores
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from acq.offline.analyze import recording_from_session  # noqa: E402
from acq.recording.reader import load  # noqa: E402
from analysis.diagnose import recording_fault  # noqa: E402
from analysis.speed_ratio import electrical_speed_ratio  # noqa: E402
from bench.scenarios import SCENARIOS, clock_for, record  # noqa: E402


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args(argv)
    start, named = time.perf_counter(), 0
    with tempfile.TemporaryDirectory() as folder:
        for i, sc in enumerate(SCENARIOS):
            offset_s, drift_ppm = clock_for(args.seed, i)
            path, _ = record(sc, args.seed, offset_s, drift_ppm, Path(folder) / str(i))
            rec = recording_from_session(load(path))
            r = electrical_speed_ratio(rec.current_a["i_a"], rec.rate_hz, rec.encoder_index, rec.position_counts,
                                       rec.period_s, rec.counts_per_rev, rec.pole_pairs)
            fault = recording_fault(rec)
            named += fault is not None
            ratio = f"{r.ratio:.4f} ± {r.spread:.4f}" if r is not None else "—"
            print(f"{i + 1:2d} {sc.name[:44]:44s} ratio {ratio}  {'FAULT: ' + fault if fault else 'ok'}", flush=True)
    print(f"{named} of {len(SCENARIOS)} scenarios named a fault, {time.perf_counter() - start:.0f} s")
    return 1 if named else 0


if __name__ == "__main__":
    sys.exit(main())
