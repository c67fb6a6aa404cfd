"""Worker processes for analyses: a local forkserver pool or a Dask cluster (:func:`analysis_executor`), for the batch
(:mod:`acq.monitoring.batch`) and ``acq monitor``; its workers ignore Ctrl-C and SIGTERM (acq's own process stops
them) and end when acq's process ends."""

from __future__ import annotations

import multiprocessing
import os
import select
import signal
import threading
import time
from collections.abc import Iterator
from concurrent.futures import Executor, ProcessPoolExecutor
from contextlib import contextmanager

from acq.environment import pin_blas_threads
from acq.install import install_hint
from acq.process_signals import STOP_SIGNALS
from acqcore.errors import ConfigError


def _start_forkserver_without_cwd() -> None:
    """Start the forkserver as ``python -P`` would (PYTHONSAFEPATH): it runs ``python -c``, which puts the current
    folder first on sys.path, so a folder named ``acq``, ``analysis`` or ``drivers`` where the user stands would be
    imported by every worker in place of ours (they then die: BrokenProcessPool). The server and its workers keep
    the variable (they run no program of the user's); acq's own process has it only while the server starts, so
    the commands it runs later (``--on-alarm``) see the user's environment.

    The server (and the resource tracker it starts) begin with SIGINT, SIGTERM and SIGHUP ignored, which they and every
    worker forked from them keep: a Ctrl-C at the terminal reaches the whole process group, and so does the SIGTERM of
    ``timeout -s TERM`` (it signals its group), and only acq's own process stops the workers (a worker or the server's
    preload stopped mid-import printed tracebacks, Qt a fatal error; a worker killed by SIGTERM broke the pool, the
    window it analysed was filed "worker failed: BrokenProcessPool" — the trial)."""
    from multiprocessing import forkserver, resource_tracker

    before = os.environ.get("PYTHONSAFEPATH")
    os.environ["PYTHONSAFEPATH"] = "1"
    try:
        # the resource tracker first, outside the window: its start blocks and then unblocks SIGINT itself, which
        # inside the window left SIGINT unblocked while ignored — a Ctrl-C then was lost (the batch ran to its end,
        # 3 of 8 runs of test_ctrl_c_at_the_terminal_stops_a_batch_in_one_line[catalogue opened]); it ignores SIGINT
        # on its own (CPython's resource_tracker.main) — and SIGTERM, not SIGHUP: a closed terminal killed it (the
        # review: "resource tracker … alive: False"), so it starts with SIGHUP blocked, which it keeps (it unblocks
        # only SIGINT and SIGTERM); blocked, not ignored, here: a SIGHUP meanwhile reaches acq once it is unblocked
        # (pthread_sigmask is the calling thread's, whichever thread: the tracker is spawned from it)
        mask = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGHUP})
        try:
            resource_tracker.ensure_running()
        finally:
            signal.pthread_sigmask(signal.SIG_SETMASK, mask)
        with _signals_ignored_by_children():
            forkserver.ensure_running()
    finally:
        if before is None:
            del os.environ["PYTHONSAFEPATH"]
        else:
            os.environ["PYTHONSAFEPATH"] = before


@contextmanager
def _signals_ignored_by_children() -> Iterator[None]:
    """Processes started inside the block begin with the stop signals (SIGINT, SIGTERM, SIGHUP) ignored (the
    disposition survives exec; Python then installs no KeyboardInterrupt handler). Such a signal meanwhile is held
    (blocked) and reaches this process after it."""
    if threading.current_thread() is not threading.main_thread():
        yield  # signal handlers can only change in the main thread (acq starts its pools there)
        return
    signal.pthread_sigmask(signal.SIG_BLOCK, STOP_SIGNALS)
    previous = {s: signal.signal(s, signal.SIG_IGN) for s in STOP_SIGNALS}
    try:
        yield
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler)
        signal.pthread_sigmask(signal.SIG_UNBLOCK, STOP_SIGNALS)


def end_with_process(pid: int) -> None:
    """Worker initializer: the worker ends when process ``pid`` (acq, which made the pool) ends, by kill -9 too.

    A worker otherwise waits for work forever once acq is killed (it holds both ends of its task pipe: no EOF), and
    through it the forkserver and the resource tracker live on, re-parented to PID 1 (≈ 270 MB per killed monitor).
    ``prctl(PR_SET_PDEATHSIG)`` cannot do this: a worker's parent is the forkserver, which lives as long as a worker
    holds its end of the server's "alive" pipe. So a daemon thread waits on a pidfd of acq's process (readable when it
    has ended; no polling, no pid reuse once open) and ends the worker; the forkserver then sees EOF on its pipe and
    exits, and the resource tracker exits when the last of its clients' pipes closes (measured: all three gone < 1 s
    after kill -9 of acq). Without pidfds (not Linux ≥ 5.3) the thread checks the pid once a second.

    The worker ignores the stop signals, which a terminal or a service manager sends a whole process group (again: a forkserver started by another program need not): acq's process
    handles them and shuts the pool down once the analyses under way are filed.
    """
    for s in STOP_SIGNALS:
        signal.signal(s, signal.SIG_IGN)
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
        # one BLAS thread per worker, as Dask's workers have, so N jobs do not fight over the cores; the server
        # preloads the module of the workers' analysis (analyze_one: acq's analysis, numpy, scipy)
        pin_blas_threads()
        context = multiprocessing.get_context("forkserver")
        context.set_forkserver_preload(["acq.monitoring.session_outcome"])
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
