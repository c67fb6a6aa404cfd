"""A --fast recording's threads kept on one CPU (acq.recording.one_cpu), and given their CPUs back after."""

from __future__ import annotations

import os
import threading
from pathlib import Path

import pytest

from acq.recording.one_cpu import current_cpu, on_one_cpu

pytestmark = pytest.mark.skipif(not hasattr(os, "sched_setaffinity") or len(os.sched_getaffinity(0)) < 2,
                                reason="needs a platform that pins threads, and two CPUs to pin to one of")


def test_the_caller_and_the_threads_it_starts_inside_stay_on_its_cpu_then_get_their_cpus_back() -> None:
    allowed = os.sched_getaffinity(0)
    seen: list[set[int]] = []
    with on_one_cpu():
        inside = os.sched_getaffinity(0)
        started = threading.Thread(target=lambda: seen.append(os.sched_getaffinity(0)))
        started.start()
        started.join()
    assert len(inside) == 1 and inside <= allowed
    assert seen == [inside]
    assert os.sched_getaffinity(0) == allowed
    with on_one_cpu(enabled=False):
        assert os.sched_getaffinity(0) == allowed


def test_current_cpu_is_one_the_thread_may_run_on() -> None:
    with on_one_cpu():
        assert {current_cpu()} == os.sched_getaffinity(0)


def test_a_fast_recording_on_one_cpu_runs_its_readers_there_and_stores_everything(tmp_path: Path) -> None:
    from acq.config import load_bench, load_profile
    from acq.recording.recorder import Recorder
    from drivers.registry import open_bench

    allowed = os.sched_getaffinity(0)
    cpus: dict[str, set[int]] = {}

    def look(kind: str, item: object) -> None:  # in the recording thread, while the readers run
        cpus.setdefault("recording", os.sched_getaffinity(0))
        for t in threading.enumerate():
            if t.name.startswith("acq-") and t.name.endswith("-reader") and t.native_id is not None:
                try:
                    cpus.setdefault(t.name, os.sched_getaffinity(t.native_id))
                except OSError:  # that reader has ended meanwhile
                    pass

    bench = load_bench()
    current, drive = open_bench(bench, fast=True)
    result = Recorder(bench, load_profile("triangle_0.2s"), current, drive, tmp_path, 1.0, listeners=[look],
                      one_cpu=True).run()
    assert result.status == "complete"
    assert result.current_samples == round(bench.daq.rate_hz)
    assert set(cpus) == {"recording", "acq-current-reader", "acq-encoder-reader"}
    assert len(cpus["recording"]) == 1 and all(c == cpus["recording"] for c in cpus.values())
    assert os.sched_getaffinity(0) == allowed
