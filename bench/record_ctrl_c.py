"""Ctrl-C at a random moment of ``acq record``: what the person sees. Prints one row per distinct stderr (progress bar
left out, paths and counts masked) with how many of the N runs printed it, and the exit codes.

    python bench/record_ctrl_c.py [--runs 40] [--duration 5] [--seed 1] [--analyze] [--from-file]

Each run starts ``acq record --profile triangle_0.2s --duration D`` (real time, the simulated bench; ``--no-analyze``
unless ``--analyze``) in a child process and sends it one SIGINT at a time drawn uniformly from 0 to the run's expected
length (start-up, D s of recording, the file's finish: :data:`TAIL_S`), so start-up, recording and the end are all
hit; with ``--from-file`` the time counts from the moment the session file appears (on a loaded machine the start-up
takes most of the draws otherwise), so the recording, its end and the identification are hit. The seed fixes the
times, not the machine's load.
"""

from __future__ import annotations

import argparse
import collections
import random
import re
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from rich.console import Console
from rich.table import Table

#: Seconds past the recording's own length in which a SIGINT still lands on a running acq: its start-up (imports,
#: devices: ≈ 2 s on 2 loaded cores) and the finish (footer, summary read back): measured by hand, load ≈ 3.
TAIL_S = 4.0
_PROGRESS = re.compile(r"━|^\s*(recording|analysing|identifying)\b")
_MASKS = ((re.compile(r"[^\s(]+\.h5"), "<session>"), (re.compile(r"\d+(\.\d+)?"), "N"))


def masked_lines(err: str) -> tuple[str, ...]:
    """stderr as the person reads it: the progress bar's redraws left out, paths and numbers masked."""
    lines = [ln for ln in err.replace("\r", "\n").splitlines() if ln.strip() and not _PROGRESS.search(ln)]
    for pattern, mask in _MASKS:
        lines = [pattern.sub(mask, ln) for ln in lines]
    return tuple(lines)


def files_left(folder: Path) -> str:
    """What the run left in ``folder``: each session file's status (``/`` attribute), or "no file"."""
    import h5py

    statuses = []
    for path in sorted(folder.glob("*.h5")):
        try:
            with h5py.File(path, "r") as f:
                statuses.append(str(f.attrs.get("status", "no status")))
        except OSError as e:
            statuses.append(f"unreadable ({e})")
    return ", ".join(statuses) or "no file"


def one_run(folder: Path, duration_s: float, delay_s: float, analyze: bool,
            from_file: bool) -> tuple[int, str, tuple[str, ...]]:
    """One ``acq record`` sent SIGINT ``delay_s`` after its start (``from_file``: after its session file appeared);
    (exit code, the file left, masked stderr lines)."""
    argv = [sys.executable, "-m", "acq", "record", "--profile", "triangle_0.2s", "--duration", f"{duration_s:g}",
            "--out", str(folder)] + ([] if analyze else ["--no-analyze"])
    proc = subprocess.Popen(argv, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    while from_file and proc.poll() is None and not any(folder.glob("*.h5")):
        time.sleep(0.01)
    time.sleep(delay_s)
    if proc.poll() is None:
        proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=120)
    return proc.returncode, files_left(folder), masked_lines(err)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--runs", type=int, default=40)
    parser.add_argument("--duration", type=float, default=5.0)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--analyze", action="store_true", help="identify after recording (default --no-analyze)")
    parser.add_argument("--from-file", action="store_true", help="count the SIGINT's time from the session file's "
                                                                 "appearance, not from the start")
    args = parser.parse_args()
    rng = random.Random(args.seed)
    # a child inherits an ignored SIGINT (this script started with & by a shell without job control): acq would then
    # ignore it outside the recording itself; a handled one is the default again in the child
    signal.signal(signal.SIGINT, signal.default_int_handler)
    seen: collections.Counter[tuple[int, str, tuple[str, ...]]] = collections.Counter()
    delays: dict[tuple[int, str, tuple[str, ...]], list[float]] = collections.defaultdict(list)
    with tempfile.TemporaryDirectory(prefix="acq-ctrl-c-") as tmp:
        for i in range(args.runs):
            delay = rng.uniform(0.0, args.duration + TAIL_S)
            key = one_run(Path(tmp) / f"r{i}", args.duration, delay, args.analyze, args.from_file)
            seen[key] += 1
            delays[key].append(delay)
    since = "of the session file" if args.from_file else "of the start"
    table = Table(title=f"acq record --duration {args.duration:g}: SIGINT at a random moment {since}, {args.runs} runs")
    for column in ("runs", "exit", "file left", "stderr lines", "SIGINT after s", "stderr (paths, numbers masked)"):
        table.add_column(column)
    for (code, left, lines), n in seen.most_common():
        ds = delays[(code, left, lines)]
        table.add_row(str(n), str(code), left, str(len(lines)), f"{min(ds):.1f}–{max(ds):.1f}", "\n".join(lines))
    Console(width=200).print(table)
    one = sum(n for (_, _, lines), n in seen.items() if len(lines) == 1)
    print(f"one line: {one}/{args.runs}; other: {args.runs - one}/{args.runs}")


if __name__ == "__main__":
    main()
