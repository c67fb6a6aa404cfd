"""The acq process's start-up settings (acq/entry.py): the allocator keeps freed memory, for it and its children."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).parents[1]


def test_keep_freed_memory_sets_the_environment_for_children_and_keeps_what_the_user_set() -> None:
    """Unset variables get acq's values; one the user set stays; a child process started afterwards sees both."""
    script = ("import os, subprocess, sys; from acq.entry import keep_freed_memory; keep_freed_memory(); "
              "print(subprocess.run([sys.executable, '-c', 'import os; print(os.environ[\"MALLOC_MMAP_THRESHOLD_\"], "
              "os.environ[\"MALLOC_TRIM_THRESHOLD_\"])'], capture_output=True, text=True).stdout.strip())")
    env = {k: v for k, v in os.environ.items() if not k.startswith("MALLOC_")}
    env["MALLOC_TRIM_THRESHOLD_"] = "1048576"
    env["PYTHONPATH"] = str(ROOT)
    proc = subprocess.run([sys.executable, "-c", script], env=env, capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.split() == [str(32 << 20), "1048576"]
