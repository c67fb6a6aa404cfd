"""The acq process's start-up settings (acq/entry.py): the allocator keeps freed memory in a one-shot acq process
only, for that process only, and never against a setting of the user's."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).parents[1]

#: Prints whether a 1 MiB malloc is mmapped (glibc's IS_MMAPPED bit of the chunk's size field) before and after
#: keep_freed_memory(), what it returned, and the MALLOC_ variables a child process started afterwards sees.
PROBE = """
import ctypes, os, subprocess, sys
libc = ctypes.CDLL(None)
libc.malloc.restype = ctypes.c_void_p
libc.free.argtypes = [ctypes.c_void_p]
def mmapped():
    p = libc.malloc(1 << 20)
    flag = ctypes.c_size_t.from_address(p - ctypes.sizeof(ctypes.c_size_t)).value & 2
    libc.free(p)
    return bool(flag)
before = mmapped()
from acq.entry import keep_freed_memory
kept = keep_freed_memory()
child = subprocess.run([sys.executable, "-c", "import os; print(sorted(k for k in os.environ if k.startswith('MALLOC_')))"],
                       capture_output=True, text=True).stdout.strip()
print(before, kept, mmapped(), child)
"""


def _probe(**env_vars: str) -> list[str]:
    env = {k: v for k, v in os.environ.items() if not k.startswith("MALLOC_") and k != "GLIBC_TUNABLES"}
    env.update(env_vars, PYTHONPATH=str(ROOT))
    proc = subprocess.run([sys.executable, "-c", PROBE], env=env, capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0, proc.stderr
    return proc.stdout.strip().split(maxsplit=3)


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc's malloc")
def test_keep_freed_memory_sets_this_process_alone() -> None:
    """A 1 MiB array comes from the heap afterwards (it was mmapped); a child process gets no MALLOC_ variable
    (they were exported, so every worker and --on-alarm command kept freed memory too)."""
    assert _probe() == ["True", "True", "False", "[]"]


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc's malloc")
@pytest.mark.parametrize("setting", [{"GLIBC_TUNABLES": "glibc.malloc.mmap_threshold=65536"},
                                     {"MALLOC_TRIM_THRESHOLD_": "1048576"}])
def test_keep_freed_memory_leaves_a_users_malloc_setting_alone(setting: dict[str, str]) -> None:
    """With the user's 64 KiB mmap threshold a 1 MiB array stays mmapped (mallopt overrode it: from the heap)."""
    before, kept, after, _child = _probe(**setting)
    assert (before, kept, after) == ("True", "False", "True")


@pytest.mark.parametrize(("command", "kept"), [("analyze", True), ("record", True), ("monitor", False),
                                                ("import", False)])
def test_only_one_shot_commands_keep_freed_memory(command: str, kept: bool) -> None:
    """acq monitor runs for hours: it keeps glibc's defaults (idle, it held its peak memory)."""
    # said as it is called: acq leaves without the interpreter's teardown (no atexit), as a Ctrl-C does
    script = ("import sys; import acq.entry as entry; "
              "entry.keep_freed_memory = lambda: print('kept', flush=True) or True; "
              f"sys.argv = ['acq', {command!r}, '--help']; entry.main()")
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    proc = subprocess.run([sys.executable, "-c", script], env=env, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert f"Usage: acq {command}" in proc.stdout
    assert proc.stdout.splitlines().count("kept") == int(kept)
