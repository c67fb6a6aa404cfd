"""``acq analyze FOLDER|GLOB``: the batch of :mod:`acq.monitoring.batch` with its table or JSON."""

from __future__ import annotations

import json
from pathlib import Path

from rich.console import Console

from acq.monitoring.batch import CATALOGUE_NAME, find_sessions, report_json, run_batch
from acq.monitoring.catalogue import Catalogue
from acq.ui.display import batch_table
from analysis import AnalysisRequest


def analyze_many(spec: Path, request: AnalysisRequest, *, jobs: int | None, catalogue_path: Path | str | None,
                 scheduler: str | None, report: bool, as_json: bool, out: Console) -> int:
    """``acq analyze FOLDER|GLOB``: the batch, its table (or JSON) on ``out``; 1 when a session failed, else 0."""
    paths, base = find_sessions(spec)
    with Catalogue(catalogue_path or base / CATALOGUE_NAME) as catalogue:
        done = run_batch(paths, catalogue, request, jobs=jobs, scheduler=scheduler, report=report)
    if as_json:
        out.print_json(json.dumps(report_json(done)))
    else:
        out.print(batch_table(done))
        out.print(f"catalogue: {catalogue.path}")
    return 1 if done.failed else 0
