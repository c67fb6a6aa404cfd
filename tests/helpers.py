"""Small helpers shared by tests: run the CLI in-process and capture its exit code and output; record a session."""

from __future__ import annotations

import contextlib
import os
import subprocess
import sys
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest

from acq.ui.cli import main


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


PROFILES = Path(__file__).resolve().parents[1] / "configs" / "profiles"


def seeded_profile(folder: Path, dither_seed: int = 0, name: str = "triangle_0.2s") -> Path:
    """The shipped profile ``name`` with a fixed ``dither_seed``, written to ``folder`` (``--profile`` takes the path).

    The shipped profiles dither the speed per cycle with a seed acq draws per recording, so a test that records them
    and asserts on identified numbers would run another motion every time; from this one it repeats exactly."""
    path = folder / f"{name}_seed{dither_seed}.toml"
    path.write_text((PROFILES / f"{name}.toml").read_text() + f"dither_seed = {dither_seed}\n")
    return path


def record_session_in_subprocess(out: Path, duration_s: float) -> Path:
    """``acq record --profile triangle_0.2s --fast`` (dither seed 0) of ``duration_s`` into ``out`` in a child process
    (nothing of the recording stays in the test process); the one session file it wrote."""
    out.mkdir(parents=True, exist_ok=True)
    profile = seeded_profile(out.parent)
    proc = subprocess.run([sys.executable, "-m", "acq", "record", "--profile", str(profile), "--fast", "--duration",
                           f"{duration_s:g}", "--no-analyze", "--out", str(out)], capture_output=True, text=True,
                          timeout=120)
    assert proc.returncode == 0, proc.stderr
    (path,) = out.glob("*.h5")
    return path


@contextlib.contextmanager
def read_only_view(folder: Path) -> Iterator[Path]:
    """``folder`` seen through a read-only bind mount (``<folder>.ro``): every write there fails with a real EROFS
    (as root chmod does not stop a write). Skips the test where this process may not mount."""
    view = folder.with_name(folder.name + ".ro")
    view.mkdir()
    mounted = subprocess.run(["mount", "-o", "bind,ro", str(folder), str(view)], capture_output=True, text=True)
    if mounted.returncode != 0:
        pytest.skip(f"needs a read-only bind mount (root): {mounted.stderr.strip()}")
    try:
        yield view
    finally:
        subprocess.run(["umount", "-l", str(view)], check=False)


@contextlib.contextmanager
def tiny_read_only_folder(folder: Path) -> Iterator[tuple[Path, str]]:
    """A folder this process may not write into, and the cause acq should name: as root a read-only tmpfs of 1 MiB
    mounted on ``folder`` (its few free bytes once read "disk full"; chmod does not stop root) — "read-only file
    system"; otherwise ``folder`` made read-only with chmod — "permission denied". Skips where root may not mount."""
    folder.mkdir()
    if os.geteuid() != 0:
        folder.chmod(0o555)
        try:
            yield folder, "permission denied"
        finally:
            folder.chmod(0o755)
        return
    mounted = subprocess.run(["mount", "-t", "tmpfs", "-o", "ro,size=1m", "tmpfs", str(folder)], capture_output=True,
                             text=True)
    if mounted.returncode != 0:
        pytest.skip(f"needs a read-only tmpfs mount as root: {mounted.stderr.strip()}")
    try:
        yield folder, "read-only file system"
    finally:
        subprocess.run(["umount", "-l", str(folder)], check=False)
