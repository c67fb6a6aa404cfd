"""The fast part of the fault campaign (bench/faults.py): damaged files, hostile input — every case handled."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "bench"))
import faults  # noqa: E402 - bench/ is not a package

FAST = ("cut50", "flip data", "flip meta", "zeroed region", "bad bench_json", "name 'x/../../../escaped'")


@pytest.fixture(scope="module")
def lab(tmp_path_factory: pytest.TempPathFactory) -> faults.Lab:
    return faults.Lab(tmp_path_factory.mktemp("faults"))


@pytest.mark.parametrize("name", FAST)
def test_fault_case_is_handled(lab: faults.Lab, name: str) -> None:
    (run,) = [run for case, run in faults.cases(lab, quick=True) if case == name]
    result = run()
    assert result.verdict == "handled", result
    assert result.code in (1, 2) and result.stderr_lines == 1
