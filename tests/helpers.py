"""Small helpers shared by tests: run the CLI in-process and capture its exit code and output."""

from __future__ import annotations

from dataclasses import dataclass

import pytest

from acq.cli import main


@dataclass(frozen=True)
class CliRun:
    code: int
    out: str
    err: str


def run_cli(capsys: pytest.CaptureFixture[str], *args: str) -> CliRun:
    """Run ``acq ARGS`` in this process; return exit code, stdout and stderr."""
    capsys.readouterr()
    with pytest.raises(SystemExit) as exc:
        main(list(args))
    captured = capsys.readouterr()
    return CliRun(int(exc.value.code or 0), captured.out, captured.err)
