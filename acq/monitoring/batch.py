"""Batch re-analysis: every session of a folder or glob, in parallel, into the catalogue.

One runner, two back ends with the same :class:`concurrent.futures.Executor` face: a local process
pool (default) or a Dask distributed cluster (``--scheduler ADDRESS``), whose workers read the
session files by the absolute paths given here — the files must be reachable at the same path on
every worker (a shared mount). The parent only hashes the files (and reads the sessions not found
current, for the request each is filed under), hands paths to the workers and writes the catalogue,
one transaction per session as results come in.

A session is skipped when the catalogue already holds a successful analysis of the same file
(SHA-256) under the request its result is filed under (:func:`acq.offline.analyze.filed_request`: the
options as asked, one that names what the default does on that session left to the default); a failed
one is tried again. A session that fails is recorded with its error, under the same request, and the
batch goes on.
"""

from __future__ import annotations

import contextlib
import os
import signal
import threading
import time
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import Executor, Future, ProcessPoolExecutor, as_completed
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from acq.monitoring.analysis_pool import analysis_executor
from acq.monitoring.catalogue import Catalogue, Outcome
from acq.monitoring.session_outcome import DrawReport, analyze_one
from acq.offline.analyze import filed_request, output_paths, sha256_of
from acq.process_signals import signals_deferred
from acq.recording.reader import load, read_status
from acq.recording.storage import remove_temp_files
from acqcore.errors import AcqError
from analysis import AnalysisRequest

#: Told how far a batch is: (sessions done, sessions to analyse, of them failed); first called with (0, n, 0).
OnProgress = Callable[[int, int, int], None]


@dataclass(frozen=True)
class BatchReport:
    """What a batch did: the outcomes of the sessions analysed, the sessions skipped as current."""

    outcomes: list[Outcome]
    skipped: list[Path]
    seconds: float
    not_ready: list[Path] = field(default_factory=list)  # status recording: skipped (unless the request is partial)
    interrupted: bool = False  # Ctrl-C: queued analyses cancelled; every outcome received is in the catalogue

    @property
    def failed(self) -> list[Outcome]:
        """Outcomes with an error."""
        return [o for o in self.outcomes if o.error is not None]




#: Seconds a Ctrl-C'd batch gives running workers to finish before they are killed (what they wrote without a
#: catalogue row is then removed); with the bookkeeping after it, a batch stops within 2 s.
STOP_GRACE_S = 0.5


def run_batch(paths: Sequence[Path], catalogue: Catalogue, request: AnalysisRequest, *, jobs: int | None = None,
              scheduler: str | None = None, draw_report: DrawReport | None = None,
              on_progress: OnProgress | None = None, result_dir: Path | None = None) -> BatchReport:
    """Analyse the sessions not yet current in ``catalogue``, recording each outcome as it arrives.

    Parameters
    ----------
    paths : sequence of Path
        Session files.
    catalogue : Catalogue
        Where the outcomes go (and what decides which sessions are current).
    request : AnalysisRequest
        What is asked. Without ``request.partial``, sessions still ``recording`` are skipped
        (:attr:`BatchReport.not_ready`).
    jobs : int, optional
        Worker processes of the local pool (default: the CPU count); ignored with ``scheduler``.
    scheduler : str, optional
        Address of a Dask distributed scheduler to run on instead of the local pool.
    draw_report : callable, optional
        Draws each session's report PNG in its worker (None: no reports).
    on_progress : callable, optional
        Told (done, to analyse, failed) when the analyses start and as each outcome is recorded.
    result_dir : Path, optional
        Where the results and reports go (None: beside each session).

    Ctrl-C (the workers ignore it) cancels the queued analyses, stops the running ones (a result file a stopped
    worker wrote without its catalogue row is removed), records every outcome received and returns with
    ``interrupted`` set; a Ctrl-C while the files are hashed or read, before any analysis, raises KeyboardInterrupt.
    """
    start = time.perf_counter()
    started_at = time.time()
    hashes = {p: sha256_of(p) for p in paths}
    not_ready = [] if request.partial else [p for p in paths if _status(p) == "recording"]
    filed = _not_current([p for p in paths if p not in not_ready], hashes, catalogue, request)
    todo = list(filed)
    outcomes: list[Outcome] = []
    interrupted = False
    try:
        if todo:
            with analysis_executor(jobs or os.cpu_count() or 1, scheduler) as executor:
                futures: dict[Future[Outcome], Path] = {}
                try:
                    with signals_deferred():  # a submit starts a worker: one cut short would outlive the pool
                        for p in todo:
                            futures[executor.submit(analyze_one, str(p.resolve()), hashes[p], filed[p],
                                                    draw_report, result_dir=result_dir)] = p
                    tell = on_progress or (lambda done, total, failed: None)
                    tell(0, len(todo), 0)
                    for future in as_completed(futures):
                        outcome = _outcome(future, futures[future], hashes, filed)
                        catalogue.record(outcome)
                        outcomes.append(outcome)
                        tell(len(outcomes), len(todo), sum(o.error is not None for o in outcomes))
                except KeyboardInterrupt:
                    with _signals_ignored():
                        _stop_workers(executor, futures, outcomes, catalogue, hashes, filed, started_at,
                                      result_dir)
                    raise
    except KeyboardInterrupt:  # the pool is shut down and every outcome received is recorded
        interrupted = True
    return BatchReport(outcomes, [p for p in paths if p not in todo and p not in not_ready],
                       time.perf_counter() - start, not_ready, interrupted)


def _not_current(paths: Sequence[Path], hashes: dict[Path, str], catalogue: Catalogue,
                 request: AnalysisRequest) -> dict[Path, AnalysisRequest]:
    """The sessions of ``paths`` to analyse, in order, each with the request its result and failure are filed under
    (:func:`_filed_request`): those whose file (``hashes``) the catalogue holds no successful analysis of under that
    request's key.

    A session found under the key of ``request`` as asked is not read: a result is filed under it only when the
    session leaves ``request`` as it is, and the same file always does. Any other is read once here for the request
    it is filed under: 5 ms for a 10 s ``--fast`` session (2.5 MB, hashed in 1.5 ms), 15 ms for 60 s (15 MB, 9 ms);
    a re-run of 40 current 60 s sessions took 2.7–3.1 s with ``--band 10,400`` (each read), 1.6–1.9 s without.
    """
    current: dict[str, set[str]] = {}

    def is_current(path: Path, filed: AnalysisRequest) -> bool:
        key = filed.key()
        if key not in current:
            current[key] = catalogue.current(key)
        return hashes[path] in current[key]

    todo: dict[Path, AnalysisRequest] = {}
    for p in paths:
        if is_current(p, request):
            continue
        filed = _filed_request(p, request)
        if filed == request or not is_current(p, filed):
            todo[p] = filed
    return todo


def _filed_request(path: Path, request: AnalysisRequest) -> AnalysisRequest:
    """:func:`acq.offline.analyze.filed_request` of the session at ``path``; ``request`` as asked when the file cannot
    be read that far (then its analysis fails as it did here, and is filed as asked, where the next batch looks).
    A request that names none of the default's options is filed as asked without reading the session (33 ms for
    60 s)."""
    if not request.names_options_of_the_default():
        return request
    try:
        return filed_request(load(path), request)
    except (AcqError, OSError, KeyError, ValueError):
        return request


def _status(path: Path) -> str:
    try:
        return read_status(path)
    except AcqError:
        return ""  # unreadable: the analysis reports why


@contextmanager
def _signals_ignored() -> Iterator[None]:
    """While a stopped batch tidies up (≤ 2 s), a second Ctrl-C does not cut it short."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)


def _stop_workers(executor: Executor, futures: dict[Future[Outcome], Path], outcomes: list[Outcome],
                  catalogue: Catalogue, hashes: dict[Path, str], filed: dict[Path, AnalysisRequest],
                  started_at: float, result_dir: Path | None) -> None:
    """Cancel what is queued, give what runs :data:`STOP_GRACE_S` to finish, kill the rest, record what finished;
    no result file (nor a temp file) is left without its catalogue row (``filed``: each session's request as its
    worker was given it, which names the files it writes)."""
    pool = executor if isinstance(executor, ProcessPoolExecutor) else None
    # the local pool's worker processes (Dask: none), as objects: a worker that finished and was reaped is not
    # signalled (its pid may be another process's by then); multiprocessing's kill checks that it was not
    processes = list((getattr(executor, "_processes", None) or {}).values())
    # what a local pool's shutdown(wait=True) would join and close, kept: shutdown(wait=False) lets go of them
    manager, results = getattr(pool, "_executor_manager_thread", None), getattr(pool, "_result_queue", None)
    if pool is None:
        for future in futures:
            future.cancel()
    else:
        # the queued analyses are cancelled by the pool itself (its shutdown, in its own thread), before the grace
        # below would let the workers take them up (then nothing queued was cancelled: all ran); a future cancelled
        # from here instead makes that thread fail on it when the workers are killed (Python 3.11: InvalidStateError)
        pool.shutdown(wait=False, cancel_futures=True)
    recorded = {o.path for o in outcomes}
    deadline = time.monotonic() + STOP_GRACE_S
    for future, path in futures.items():
        if future.cancelled():
            continue
        try:
            outcome = future.result(timeout=max(0.0, deadline - time.monotonic()))
        except BaseException:  # noqa: BLE001 - interrupted or still running: no outcome
            continue
        if outcome.path not in recorded:
            catalogue.record(outcome)
            outcomes.append(outcome)
            recorded.add(outcome.path)
    for process in processes:
        if process.exitcode is None:
            with contextlib.suppress(OSError, ValueError):
                process.kill()
    if manager is not None:  # the killed workers reaped: none writes after this
        manager.join()
    if results is not None:
        results.close()
    for path in futures.values():  # a worker killed after writing its result but before the row: remove it
        if str(path.resolve()) in recorded:
            continue
        for output in output_paths(path, filed[path], result_dir):
            remove_temp_files(output)
            with contextlib.suppress(OSError):
                if output.stat().st_mtime >= started_at:
                    output.unlink()


def _outcome(future: Future[Outcome], path: Path, hashes: dict[Path, str],
             filed: dict[Path, AnalysisRequest]) -> Outcome:
    """The worker's outcome, or a failure (filed as the worker was asked) when the worker itself died (pool broken,
    cluster lost)."""
    try:
        return future.result()
    except Exception as e:  # noqa: BLE001 — the worker never raises; this is the worker or cluster dying
        return Outcome(str(path.resolve()), hashes[path], filed[path].key(), {}, None,
                       f"{path}: worker failed: {type(e).__name__}: {e}", 0.0)


def report_json(report: BatchReport) -> list[dict[str, Any]]:
    """The ``--json`` list: per session its path, what happened, K, verdict and error."""
    done = [{"path": o.path, "outcome": "failed" if o.error else "analysed",
             "K_Nm_per_rad": None if o.doc is None else o.doc.get("K_Nm_per_rad"),  # none when not excited
             "verdict": None if o.doc is None else o.doc["quality"]["verdict"], "error": o.error}
            for o in report.outcomes]
    return (done + [{"path": str(p.resolve()), "outcome": "skipped"} for p in report.skipped]
            + [{"path": str(p.resolve()), "outcome": "skipped: status recording"} for p in report.not_ready])
