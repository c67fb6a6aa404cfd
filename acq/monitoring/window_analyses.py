"""The windows a monitor (:mod:`acq.monitoring.monitor`) hands to analysis worker processes
(:func:`acq.monitoring.analysis_pool.analysis_executor`), by key, and their outcomes as they finish; a new pool when
a worker died."""

from __future__ import annotations

from collections.abc import Iterator
from concurrent.futures import Future
from concurrent.futures.process import BrokenProcessPool
from contextlib import ExitStack
from pathlib import Path

from acq.monitoring.analysis_pool import analysis_executor
from acq.monitoring.catalogue import Outcome
from acq.monitoring.window_judge import analyse_window
from acq.offline.analyze import sha256_of
from analysis import AnalysisRequest


class WindowAnalyses:
    """Analyses under way in a pool of ``jobs`` workers entered into ``pools`` (the run's: a new pool is entered
    when a worker died, the old one's ended with the run)."""

    def __init__(self, pools: ExitStack, jobs: int) -> None:
        self._pools, self._jobs = pools, jobs
        self._pool = pools.enter_context(analysis_executor(jobs, None))
        self._pending: dict[Future[Outcome], str] = {}

    def __len__(self) -> int:
        """Windows submitted whose outcome was not yet taken (:meth:`finished`)."""
        return len(self._pending)

    def submit(self, key: str, path: Path, request: AnalysisRequest) -> None:
        """Hand the window ``key`` (its file ``path``) to a worker."""
        job = (analyse_window, str(path.resolve()), sha256_of(path), request)
        try:
            future = self._pool.submit(*job)
        except BrokenProcessPool:  # a worker died (killed, out of memory) — its window's future may not say so yet:
            # this window and the next go to a new pool (the old one's futures are collected as unfinished)
            self._pool = self._pools.enter_context(analysis_executor(self._jobs, None))
            future = self._pool.submit(*job)
        self._pending[future] = key

    def finished(self, at_most: int | None) -> Iterator[tuple[str, Outcome | Exception]]:
        """The finished analyses, as (key, outcome — or the exception of a worker that died: analyse_window never
        raises); first waits until at most ``at_most`` are left (None: does not wait)."""
        while self._pending:
            done = [f for f in self._pending if f.done()]
            if not done and at_most is not None and len(self._pending) > at_most:
                next(iter(self._pending)).exception()  # wait for the oldest
                continue
            if not done:
                break
            for future in done:
                key = self._pending.pop(future)
                try:
                    outcome = future.result()
                except Exception as e:  # noqa: BLE001 - the worker itself died
                    yield key, e
                    continue
                yield key, outcome
