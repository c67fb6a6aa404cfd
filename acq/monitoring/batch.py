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
import glob
import multiprocessing
import os
import select
import signal
import threading
import time
import warnings
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import Executor, Future, ProcessPoolExecutor, as_completed
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from acq.environment import pin_blas_threads
from acq.install import install_hint
from acq.monitoring.catalogue import Catalogue, Outcome
from acq.offline.analyze import SessionResult, analyze_session, filed_request, output_paths, sha256_of
from acq.process_signals import signals_deferred
from acq.recording.paths import GLOB_CHARS, is_batch, require_session_file
from acq.recording.reader import load, read_status
from acq.recording.session import Session
from acq.recording.storage import remove_temp_files
from acqcore.errors import AcqError, ConfigError
from analysis import AnalysisRequest

CATALOGUE_NAME = "catalogue.sqlite"

#: Draws a written result's report PNG and returns the result (with a note if the picture failed), e.g.
#: :func:`acq.ui.report_png.draw_report`; a module-level function, so it reaches the workers by name.
DrawReport = Callable[[SessionResult], SessionResult]

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


def find_sessions(spec: Path | str) -> tuple[list[Path], Path]:
    """The session files (``*.h5``) of a folder or glob, sorted, and the folder they were sought in.

    The folder is where the catalogue goes by default: the folder itself, or a glob's deepest
    folder without wildcards.
    """
    spec = Path(spec)
    if spec.is_dir():
        paths, base = spec.glob("*.h5"), spec
    else:
        paths = (Path(p) for p in glob.glob(str(spec), recursive=True))
        base = Path(*_prefix(spec.parts))
    sessions = sorted(p for p in paths if p.suffix == ".h5" and p.is_file())
    if not sessions:
        raise ConfigError(f"{spec}: no session files (*.h5) found")
    return sessions, base


def find_all_sessions(specs: Sequence[Path | str]) -> tuple[list[Path], Path | None]:
    """The session files of several command-line arguments — session files, folders, globs (also as the shell
    expanded ``par/*.h5``) — each once, sorted; and the folder the catalogue goes in by default: the one all were
    sought in (as a glob's deepest folder without wildcards), None when they lie in different folders (their common
    folder could be /: the review)."""
    found: dict[Path, Path] = {}
    bases: list[Path] = []
    for spec in map(Path, specs):
        if is_batch(spec):
            paths, base = find_sessions(spec)
        else:
            require_session_file(spec)
            paths, base = [spec], spec.parent
        bases.append(base)
        for p in paths:
            found.setdefault(p.resolve(), p)
    if any(b.resolve() != bases[0].resolve() for b in bases):
        return sorted(found.values()), None
    return sorted(found.values()), bases[0]


def _prefix(parts: Sequence[str]) -> Iterator[str]:
    """The path parts before the first one with a wildcard ('.' when the first has one)."""
    if not parts or GLOB_CHARS & set(parts[0]):
        yield "."
        return
    for part in parts:
        if GLOB_CHARS & set(part):
            return
        yield part


def record_outcome(done: SessionResult, catalogue_path: Path | str | None, seconds: float) -> Path | str:
    """Put one session's analysis (done outside a batch) into its catalogue; return the catalogue's path.

    The catalogue is ``catalogue_path`` or ``catalogue.sqlite`` in the folder of the result (the session's, or
    ``--result-dir``), so a later ``acq analyze FOLDER`` finds the session current and ``acq trend`` sees it at once.
    """
    path = catalogue_path or done.json_path.parent / CATALOGUE_NAME
    with Catalogue(path) as catalogue:
        catalogue.record(succeeded(str(done.session.path), done, seconds))
    return path


def succeeded(path: str, done: SessionResult, seconds: float) -> Outcome:
    """The catalogue's record of a successful analysis of the session at ``path``, filed under the request it
    answered (an option that named the default left to it: :meth:`analysis.AnalysisRequest.as_default_where_it_is`)."""
    return Outcome(path, done.json_dict["session"]["sha256"], done.request.key(), session_meta(done.session),
                   done.json_dict, None, seconds)


def session_meta(session: Session) -> dict[str, Any]:
    """What the catalogue keeps of a session's root attributes."""
    meta = session.meta
    return {"session_id": meta.session_id, "joint": meta.joint, "created_utc": meta.created_utc,
            "start_monotonic_ns": meta.host_ns_at_start or 0, "status": meta.status, "tags": meta.tags}


@contextmanager
def quiet_numerics() -> Iterator[None]:
    """No numpy floating-point warning (divide by zero, invalid value, overflow) reaches the person: the analysis
    reports unusable data through its errors and verdict, and a warning line before them only confuses."""
    with np.errstate(all="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        yield


def analyze_one(path: str, sha256: str, request: AnalysisRequest, draw_report: DrawReport | None = None, *,
                write: bool = True, result_dir: Path | None = None) -> Outcome:
    """Analyse one session (runs in a worker process or on a Dask worker); never raises.

    Parameters
    ----------
    path : str
        Absolute path of the session file, as the worker sees it.
    sha256 : str
        The file's hash when the batch looked at it (kept when the analysis fails).
    request : AnalysisRequest
        What is asked, as filed for this session (:func:`acq.offline.analyze.filed_request`): its key files the
        outcome in the catalogue, a failure too.
    draw_report : callable, optional
        Draws ``<session>.report.png`` once the result is written (None: no report).
    write : bool, optional
        Write ``<session>.result.json`` (False: the caller writes the document it makes of the outcome).
    result_dir : Path, optional
        Where the result and report go (None: beside the session).
    """
    start = time.perf_counter()
    try:
        with quiet_numerics():
            done = analyze_session(path, request, write=write, report=draw_report is not None, result_dir=result_dir)
    except Exception as e:  # noqa: BLE001 — a batch records any session's failure and goes on
        error = str(e) if isinstance(e, AcqError) else f"{path}: {type(e).__name__}: {e}"
        return Outcome(path, sha256, request.key(), _meta_if_readable(path), None, error,
                       time.perf_counter() - start)
    if draw_report is not None:
        done = draw_report(done)  # the result is written; a picture that fails is a note on it, not a failure
    return succeeded(path, done, time.perf_counter() - start)


def _meta_if_readable(path: str) -> dict[str, Any]:
    try:
        return session_meta(load(path))
    except (AcqError, OSError, KeyError, ValueError):
        return {}


def _start_forkserver_without_cwd() -> None:
    """Start the forkserver as ``python -P`` would (PYTHONSAFEPATH): it runs ``python -c``, which puts the current
    folder first on sys.path, so a folder named ``acq``, ``analysis`` or ``drivers`` where the user stands would be
    imported by every worker in place of ours (they then die: BrokenProcessPool). The server and its workers keep
    the variable (they run no program of the user's); acq's own process has it only while the server starts, so
    the commands it runs later (``--on-alarm``) see the user's environment.

    The server (and the resource tracker it starts) begin with SIGINT ignored, which they and every worker forked
    from them keep: a Ctrl-C at the terminal reaches the whole process group, and only acq's own process stops the
    workers (a worker or the server's preload stopped mid-import printed tracebacks, Qt a fatal error)."""
    from multiprocessing import forkserver, resource_tracker

    before = os.environ.get("PYTHONSAFEPATH")
    os.environ["PYTHONSAFEPATH"] = "1"
    try:
        # the resource tracker first, outside the window: its start blocks and then unblocks SIGINT itself, which
        # inside the window left SIGINT unblocked while ignored — a Ctrl-C then was lost (the batch ran to its end,
        # 3 of 8 runs of test_ctrl_c_at_the_terminal_stops_a_batch_in_one_line[catalogue opened]); it ignores SIGINT
        # on its own (CPython's resource_tracker.main)
        resource_tracker.ensure_running()
        with _sigint_ignored_by_children():
            forkserver.ensure_running()
    finally:
        if before is None:
            del os.environ["PYTHONSAFEPATH"]
        else:
            os.environ["PYTHONSAFEPATH"] = before


@contextmanager
def _sigint_ignored_by_children() -> Iterator[None]:
    """Processes started inside the block begin with SIGINT ignored (the disposition survives exec; Python then
    installs no KeyboardInterrupt handler). A Ctrl-C meanwhile is held (blocked) and reaches this process after it."""
    if threading.current_thread() is not threading.main_thread():
        yield  # signal handlers can only change in the main thread (acq starts its pools there)
        return
    signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)
        signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})


def end_with_process(pid: int) -> None:
    """Worker initializer: the worker ends when process ``pid`` (acq, which made the pool) ends, by kill -9 too.

    A worker otherwise waits for work forever once acq is killed (it holds both ends of its task pipe: no EOF), and
    through it the forkserver and the resource tracker live on, re-parented to PID 1 (≈ 270 MB per killed monitor).
    ``prctl(PR_SET_PDEATHSIG)`` cannot do this: a worker's parent is the forkserver, which lives as long as a worker
    holds its end of the server's "alive" pipe. So a daemon thread waits on a pidfd of acq's process (readable when it
    has ended; no polling, no pid reuse once open) and ends the worker; the forkserver then sees EOF on its pipe and
    exits, and the resource tracker exits when the last of its clients' pipes closes (measured: all three gone < 1 s
    after kill -9 of acq). Without pidfds (not Linux ≥ 5.3) the thread checks the pid once a second.
    """
    try:
        pidfd: int | None = os.pidfd_open(pid)
    except ProcessLookupError:  # acq ended before this worker started
        os._exit(1)
    except (AttributeError, OSError):  # no pidfd_open here
        pidfd = None
    threading.Thread(target=_exit_when_ended, args=(pid, pidfd), name="acq-end-with-parent", daemon=True).start()


def _exit_when_ended(pid: int, pidfd: int | None) -> None:
    if pidfd is not None:
        select.select([pidfd], [], [])
    else:
        while _running(pid):
            time.sleep(1.0)
    os._exit(1)  # acq is gone: nobody waits for this worker's result


def _running(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except (ProcessLookupError, PermissionError):  # gone, or its pid is another user's process now
        return False
    return True


@contextmanager
def analysis_executor(jobs: int, scheduler: str | None) -> Iterator[Executor]:
    """Workers for analyses: a process pool of ``jobs`` (one BLAS thread each), or a Dask cluster's executor at
    ``scheduler`` (tcp://host:port); used by the batch and by ``acq monitor``."""
    if scheduler is None:
        # forkserver: workers fork from a clean single-threaded server that has imported acq once (a plain fork
        # of this process inherits the locks its threads — recorder, progress, BLAS — may hold, and can hang);
        # one BLAS thread per worker, as Dask's workers have, so N jobs do not fight over the cores
        pin_blas_threads()
        context = multiprocessing.get_context("forkserver")
        context.set_forkserver_preload(["acq.monitoring.batch"])
        _start_forkserver_without_cwd()
        pool = ProcessPoolExecutor(max_workers=jobs, mp_context=context, initializer=end_with_process,
                                   initargs=(os.getpid(),))
        try:
            yield pool
        except BaseException:
            pool.shutdown(wait=True, cancel_futures=True)  # the caller stopped the workers: quick, frees the pool's locks
            raise
        pool.shutdown(wait=True)
        return
    try:
        from distributed import Client
    except ImportError:
        raise ConfigError(f"--scheduler needs Dask distributed: {install_hint('cluster')}") from None
    try:
        client = Client(scheduler, timeout="10s")
    except OSError as e:
        raise ConfigError(f"--scheduler {scheduler}: cannot reach the Dask scheduler ({e})") from None
    with client:
        yield client.get_executor(pure=False)


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
