"""Windows recorded and judged for confident wrong results, and their count table (shared by bench/friction_robot.py
and bench/effects_robot.py).

A window is recorded through the real recorder from the simulated drivers (``--fast``) and analysed by
``acq analyze``'s own path (:func:`acq.offline.analyze.analyze_session`); it is *confidently wrong* when its verdict is
``ok`` and the simulator's truth of K, J_m, J_l or C lies outside the 95 % interval.
"""

from __future__ import annotations

import sys
import tempfile
from collections import Counter
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from rich.table import Table

ROOT = Path(__file__).resolve().parent.parent
if str(ROOT) not in sys.path:  # this checkout's packages
    sys.path.insert(0, str(ROOT))

from acq.config import load_bench  # noqa: E402
from acq.offline.analyze import analyze_session  # noqa: E402
from acq.recording.recorder import Recorder  # noqa: E402
from drivers.registry import open_bench  # noqa: E402

ROBOT = ROOT / "configs" / "benches" / "sim_robot.toml"
WINDOW_S = 10.0  # the monitor's window
PARAMS = ("K_Nm_per_rad", "Jm_kgm2", "Jl_kgm2", "C_Nms_per_rad")
VERDICTS = ("ok", "poor", "failed", "not excited", "error")
COLUMNS = ("windows", "ok", "poor", "failed", "not excited", "errors", "ok & wrong", *(p.split("_")[0] for p in PARAMS))


def judged(record: Callable[[Path], Path], key: dict[str, Any]) -> dict[str, Any]:
    """``key`` with the verdict of the session ``record(folder)`` writes and the parameters whose interval misses the
    truth (``outside``; ``values``: value, interval and truth of each), or the error's text as the verdict."""
    try:
        with tempfile.TemporaryDirectory() as folder:
            doc = analyze_session(record(Path(folder)), write=False).json_dict
    except Exception as e:  # noqa: BLE001 — a window the analysis refuses is counted, not fatal
        return {**key, "verdict": f"error: {e}", "outside": [], "values": {}}
    ci, truth = doc.get("ci95") or {}, doc.get("simulated_truth") or {}
    outside = [p for p in PARAMS if p in ci and None not in ci[p] and not ci[p][0] <= truth[p] <= ci[p][1]]
    values = {p: (doc.get(p), *ci[p], truth.get(p)) for p in outside}
    return {**key, "verdict": doc["quality"]["verdict"], "outside": outside, "values": values}


def robot_window(seed: int, elapsed_s: float, sim: dict[str, Any], key: dict[str, Any]) -> dict[str, Any]:
    """Record and judge one window of configs/benches/sim_robot.toml as the monitor records it (``WINDOW_S``, the
    bench's one phase, the robot's own program at ``elapsed_s`` of ``seed``) with the ``[sim]`` values ``sim``."""
    bench = load_bench(ROBOT)
    bench = bench.model_copy(update={"sim": bench.sim.model_copy(update={"elapsed_s": elapsed_s, "seed": seed, **sim})})

    def record(folder: Path) -> Path:
        current, drive = open_bench(bench, fast=True)
        return Recorder(bench, None, current, drive, folder, WINDOW_S).run().path

    return judged(record, {"seed": seed, "elapsed_s": elapsed_s, **key})


def is_wrong(row: dict[str, Any]) -> bool:
    """Whether a judged window is confidently wrong (ok, the truth outside an interval)."""
    return row["verdict"] == "ok" and bool(row["outside"])


def count_cells(rows: Sequence[dict[str, Any]]) -> list[str]:
    """The :data:`COLUMNS` cells of some judged windows: how many, per verdict, confidently wrong, and per parameter."""
    verdicts = Counter("error" if r["verdict"].startswith("error") else r["verdict"] for r in rows)
    wrong = [r for r in rows if is_wrong(r)]
    per = Counter(p for r in wrong for p in r["outside"])
    return [str(len(rows)), *(str(verdicts[v]) for v in VERDICTS), str(len(wrong)), *(str(per[p]) for p in PARAMS)]


def count_table(title: str, first: Sequence[str], groups: Sequence[tuple[Sequence[str], Sequence[dict[str, Any]]]]
                ) -> Table:
    """A table of :func:`count_cells` per group; ``first`` names the columns that label a group."""
    table = Table(title=title)
    for col in (*first, *COLUMNS):
        table.add_column(col, justify="right")
    for labels, rows in groups:
        table.add_row(*labels, *count_cells(rows))
    return table


def wrong_line(row: dict[str, Any]) -> str:
    """Each missed parameter of a judged window: value [interval] truth."""
    return "; ".join(f"{p} {v[0]:.6g} [{v[1]:.6g}, {v[2]:.6g}] truth {v[3]:.6g}" for p, v in row["values"].items())
