"""The opt-in hardware suite: ``ACQ_HW_BENCH=path/to/bench.toml pytest tests/hardware``.

Without the variable every test here is skipped with the reason (plain ``pytest`` stays hardware-free).
With it, the suite runs ``acq selftest``'s checks, the recorder and an identification against the devices
that bench names — real ones, or our simulated peers (``configs/benches/sim_canopen.toml``,
``sim_serial.toml``) to prove the suite itself. The drive MOVES: a slow triangle, then the bench's profile.
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from pathlib import Path

import pytest

from acq.commissioning.selftest import run_selftest
from acq.commissioning.selftest_checks import Check
from acq.config import load_bench, load_profile
from drivers.config import Bench

ENV = "ACQ_HW_BENCH"
PROFILE_ENV = "ACQ_HW_PROFILE"  # the identification's profile (default triangle_0.2s)
HERE = Path(__file__).parent


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    if os.environ.get(ENV):
        return
    skip = pytest.mark.skip(reason=f"hardware suite: set {ENV}=path/to/bench.toml to run it against that bench")
    for item in items:
        if HERE in Path(item.path).parents:
            item.add_marker(skip)


@pytest.fixture(scope="session")
def hw_bench() -> Bench:
    """The bench under test (a config error fails here, in one line)."""
    return load_bench(os.environ[ENV])


@pytest.fixture(scope="session")
def selftest_checks(hw_bench: Bench, tmp_path_factory: pytest.TempPathFactory) -> dict[str, Check]:
    """One ``acq selftest`` run on the bench (real time), its checks by name."""
    profile = load_profile(os.environ.get(PROFILE_ENV, "triangle_0.2s"))
    checks = list(run_selftest(hw_bench, profile, tmp_path_factory.mktemp("selftest")))
    return {c.name: c for c in checks}


@pytest.fixture(scope="session")
def hw_session_dir(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Path]:
    yield tmp_path_factory.mktemp("sessions")
