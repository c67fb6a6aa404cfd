"""Fault campaign: run acq into full disks, damaged files, hostile names, absurd values, concurrent writers and
signals, and print one row per case (prints figures; not a test — tests/test_faults.py runs the fast part).

    python bench/faults.py [--only SUBSTRING] [--quick]

Every case runs the real ``acq`` command in a subprocess. A case is **handled** when the exit code is the one
expected, stderr holds no traceback and no warning, a failure says so in exactly one ``acq:`` line, and the
case's own check holds (samples reported = samples stored and readable, no zeros, no temp file, catalogue rows =
result files, bounded time). Disk-full cases need a tmpfs (root: ``mount -t tmpfs``); without one they are
reported as skipped.
"""

from __future__ import annotations

import argparse
import contextlib
import os
import re
import shutil
import signal
import sqlite3
import subprocess
import sys
import tempfile
import time
import uuid
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path

import h5py
import numpy as np
from rich.console import Console
from rich.table import Table

from acq.config import DEFAULT_BENCH, resolve_profile_path
from acq.recording.reader import load
from acq.recording.session import Session

RATE_HZ = 25600
_PROGRESS = re.compile(r"━|^\s*(recording|analysing|identifying)\b")


@dataclass(frozen=True)
class Run:
    code: int
    out: str
    err: str
    seconds: float

    @property
    def lines(self) -> list[str]:
        """stderr lines that are not the progress bar."""
        return [ln for ln in self.err.splitlines() if ln.strip() and not _PROGRESS.search(ln)]


@dataclass(frozen=True)
class Row:
    case: str
    code: int | None
    stderr_lines: int | None
    kept: str
    stored: str
    verdict: str
    note: str = ""


def acq(*args: str, timeout: float = 120, env: dict[str, str] | None = None) -> Run:
    """Run ``python -m acq ARGS``; a hang past ``timeout`` is exit code -1."""
    start = time.monotonic()
    try:
        p = subprocess.run([sys.executable, "-m", "acq", *args], capture_output=True, text=True, timeout=timeout,
                           env=env)
    except subprocess.TimeoutExpired as e:
        return Run(-1, str(e.stdout or ""), f"timed out after {timeout:g} s", time.monotonic() - start)
    return Run(p.returncode, p.stdout, p.stderr, time.monotonic() - start)


def clean(run: Run, codes: tuple[int, ...]) -> str | None:
    """Why ``run`` is not a clean exit with one of ``codes`` (None when it is)."""
    if run.code not in codes:
        return f"exit {run.code}, expected {codes}: {run.err.strip().splitlines()[-1:] if run.err else ''}"
    if "Traceback" in run.err or "Warning" in run.err:
        return "traceback or warning on stderr"
    if run.code != 0:
        acq_lines = [ln for ln in run.lines if ln.startswith("acq:")]
        if len(acq_lines) != 1:
            return f"{len(acq_lines)} acq: lines on stderr"
    return None


def row(case: str, run: Run | None, problem: str | None, kept: object = "", stored: object = "",
        note: str = "") -> Row:
    return Row(case, None if run is None else run.code, None if run is None else len(run.lines), str(kept),
               str(stored), "handled" if problem is None else "bad", problem or note)


def temp_files(folder: Path) -> list[str]:
    return [p.name for p in folder.rglob(".*") if p.is_file()]


# ------------------------------------------------------------------------------------------ fixtures


class Lab:
    """A scratch folder with a recorded session to spoil."""

    def __init__(self, root: Path) -> None:
        self.root = root
        self.base = root / "base"
        run = acq("record", "--profile", "triangle_0.2s", "--fast", "--duration", "10", "--no-analyze",
                  "--out", str(self.base))
        assert run.code == 0, run.err
        (self.session,) = self.base.glob("*.h5")
        self.n = 0

    def folder(self) -> Path:
        self.n += 1
        path = self.root / f"case{self.n}"
        path.mkdir()
        return path

    def copy(self, folder: Path | None = None, name: str = "s.h5") -> Path:
        """A copy of the session with its own session id (its own hash)."""
        dst = (folder or self.folder()) / name
        shutil.copyfile(self.session, dst)
        with h5py.File(dst, "r+") as f:
            f.attrs["session_id"] = str(uuid.uuid4())
        return dst


@contextlib.contextmanager
def tmpfs(folder: Path, size: str) -> Iterator[bool]:
    """Mount a ``size`` tmpfs at ``folder``; yields False when that is not possible here."""
    folder.mkdir(parents=True, exist_ok=True)
    ok = subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", str(folder)],
                        capture_output=True).returncode == 0
    try:
        yield ok
    finally:
        if ok:
            subprocess.run(["umount", "-l", str(folder)], check=False)


def fill(folder: Path, leave_bytes: int) -> None:
    """Fill the file system of ``folder`` up to ``leave_bytes`` free."""
    st = os.statvfs(folder)
    free = st.f_bavail * st.f_frsize
    with (folder / "filler").open("wb") as f:
        with contextlib.suppress(OSError):
            f.write(b"\0" * max(0, free - leave_bytes))


def counts_in(run: Run) -> tuple[int, int] | None:
    m = re.search(r"(\d+) current (?:and|samples, )\s*(\d+) encoder", run.err.replace("\n", " "))
    return (int(m.group(1)), int(m.group(2))) if m else None


def stored_ok(path: Path) -> tuple[int, str | None]:
    """Intact current samples of ``path`` and why they are not consistent (None when they are)."""
    s = load(path)
    n = s.current.sample_count
    if s.damage:
        return n, f"damaged: {s.damage}"
    if n and np.any(s.current.phases_a["i_a"] == 0.0):
        return n, "zeros stored"
    if not np.array_equal(s.current.sample_index(), np.arange(n)):
        return n, "sample index not contiguous"
    return n, None


# ------------------------------------------------------------------------------------------ cases


def disk_full_record(lab: Lab, size: str, inside_hdf5: bool = False) -> Row:
    case = f"disk full while recording ({size} tmpfs{', ENOSPC inside HDF5' if inside_hdf5 else ''})"
    out = lab.folder() / "disk"
    with tmpfs(out, size) as ok:
        if not ok:
            return Row(case, None, None, "", "", "skipped", "no tmpfs here")
        args = ["record", "--profile", "triangle_0.5s", "--fast", "--duration", "120", "--no-analyze", "--out",
                str(out)]
        if inside_hdf5:  # the free-space guard off: the error reaches HDF5 mid-flush
            code = ("import sys, acq.recording.writer as s; s.RESERVE_BYTES = -(1 << 40); from acq.ui.cli import main; "
                    "main(sys.argv[1:])")
            p = subprocess.run([sys.executable, "-c", code, *args], capture_output=True, text=True, timeout=120)
            run = Run(p.returncode, p.stdout, p.stderr, 0.0)
        else:
            run = acq(*args)
        problem = clean(run, (1,))
        files = list(out.glob("*.h5"))
        reported = counts_in(run)
        if problem is None and (len(files) != 1 or reported is None):
            problem = f"files {files}, reported {reported}"
        if problem is not None:
            return row(case, run, problem)
        stored, why = stored_ok(files[0])
        problem = why or (None if reported[0] == stored else "reported ≠ stored")
        problem = problem or ("temp files left" if temp_files(out) else None)
        return row(case, run, problem, reported[0], stored)


def disk_full_output(lab: Lab, what: str) -> Row:
    case = f"disk full writing {what}"
    folder = lab.folder()
    disk = folder / "disk"
    with tmpfs(disk, "20m") as ok:
        if not ok:
            return Row(case, None, None, "", "", "skipped", "no tmpfs here")
        if what == "result JSON":
            session = lab.copy(disk)
            fill(disk, 1024)
            run, target = acq("analyze", str(session), "--no-report",
                              "--catalogue", str(folder / "c.sqlite")), "s.result.json"
        elif what == "report PNG":
            session = lab.copy(disk)
            fill(disk, 8 * 1024)
            run, target = acq("analyze", str(session), "--catalogue", str(folder / "c.sqlite")), "s.report.png"
        elif what == "catalogue":
            session = lab.copy(folder)
            fill(disk, 0)
            run, target = acq("analyze", str(session), "--no-report", "--catalogue", str(disk / "c.sqlite")), \
                "c.sqlite"
        elif what == "CSV export":
            session = lab.copy(folder)
            fill(disk, 4096)
            run, target = acq("export", str(session), "--csv", str(disk / "csv")), "csv"
        else:  # import
            csv = folder / "csv"
            assert acq("export", str(lab.session), "--csv", str(csv)).code == 0
            fill(disk, 64 * 1024)
            cur, enc = sorted(csv.glob("*current.csv"))[0], sorted(csv.glob("*encoder.csv"))[0]
            run, target = acq("import", "--current", str(cur), "--encoder", str(enc), "--bench", str(DEFAULT_BENCH),
                              "--profile", "triangle_0.2s", "-o", str(disk / "imp.h5")), "imp.h5"
        problem = clean(run, (1,))
        if problem is None and target not in run.err:
            problem = f"the error does not name {target}: {run.lines}"
        if problem is None and temp_files(disk):
            problem = f"temp files left: {temp_files(disk)}"
        if problem is None and what in ("result JSON", "report PNG", "catalogue") and \
                list(session.parent.glob("*.result.json")):
            problem = "a result file without its catalogue row"
        return row(case, run, problem)


def vanished_folder(lab: Lab) -> Row:
    case = "session folder deleted while recording"
    out = lab.folder() / "out"
    p = subprocess.Popen([sys.executable, "-m", "acq", "record", "--profile", "triangle_0.2s", "--duration", "30",
                          "--no-analyze", "--out", str(out)], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                         text=True)
    deadline = time.monotonic() + 30
    while not list(out.glob("*.h5")) and time.monotonic() < deadline:
        time.sleep(0.1)
    time.sleep(1.0)
    shutil.rmtree(out)
    try:
        o, e = p.communicate(timeout=30)
    except subprocess.TimeoutExpired:
        p.kill()
        return row(case, None, "did not stop within 30 s")
    run = Run(p.returncode, o, e, 0.0)
    problem = clean(run, (1,)) or (None if "session file vanished" in run.err else f"{run.lines}")
    return row(case, run, problem)


def cut_file(lab: Lab, percent: int) -> Row:
    case = f"file cut to {percent} %: check, check --repair, analyze"
    path = lab.folder() / "s.h5"
    shutil.copyfile(lab.session, path)  # not Lab.copy: the session_id it writes afterwards can lie past the cut
    size = path.stat().st_size
    with path.open("r+b") as f:
        f.truncate(size * percent // 100)
    detect_s = detection_seconds(path)
    check = acq("check", str(path), timeout=60)
    problem = clean(check, (1,)) or (None if detect_s <= 5 else f"detection took {detect_s:.1f} s")
    if problem is None and f"{path}: file cut: " not in check.out:
        problem = "the cut not reported"
    kept = stored = ""
    if problem is None:
        cut, whole = load(path), load(lab.session)
        kept = f"{cut.current.sample_count} / {cut.encoder.index.size}"
        stored = f"{whole.current.sample_count} / {whole.encoder.index.size}"
        problem = invented(cut, whole)
        if problem is None and (cut.current.sample_count or cut.encoder.index.size):
            problem = recovered_copy(path, cut, whole)
    analyze = acq("analyze", str(path), "--no-report", timeout=60)
    problem = problem or clean(analyze, (2,))
    return row(case, check, problem, kept, stored,
               note=f"detected in {detect_s:.2f} s (acq check {check.seconds:.1f} s wall)")


def invented(part: Session, whole: Session) -> str | None:
    """What ``part`` holds that is not the start of ``whole`` (None when every sample it holds is)."""
    n, m = part.current.sample_count, part.encoder.index.size
    same = all(np.array_equal(v, whole.current.phases_a[ch][:n]) for ch, v in part.current.phases_a.items())
    same = same and np.array_equal(part.encoder.position_counts, whole.encoder.position_counts[:m])
    return None if same else "samples kept that the intact file does not hold there"


def recovered_copy(path: Path, cut: Session, whole: Session) -> str | None:
    """Why ``acq check --repair`` of the cut ``path`` did not write its intact part beside it (None when it did)."""
    run = acq("check", "--repair", str(path), timeout=60)
    target = path.with_name(f"{path.stem}.recovered{path.suffix}")
    problem = clean(run, (1,))  # damage found (and its intact part copied): exit 1, as fsck's "errors corrected"
    if problem is None:
        copy = load(target)
        if copy.damage or copy.status != "interrupted" or "recovered from a file cut at" not in copy.meta.stop_reason:
            problem = f"recovered copy: damage {copy.damage}, status {copy.status}, reason {copy.meta.stop_reason!r}"
        elif (copy.current.sample_count, copy.encoder.index.size) != (cut.current.sample_count,
                                                                        cut.encoder.index.size):
            problem = "recovered copy holds other counts than the cut file's intact part"
        else:
            problem = invented(copy, whole)
    return problem or (None if not temp_files(path.parent) else f"temp files left: {temp_files(path.parent)}")


def detection_seconds(path: Path) -> float:
    """Seconds :func:`acq.recording.reader.load` takes to read ``path`` or refuse it (the interpreter's start-up, several
    seconds on a loaded 2-core machine, is not part of it)."""
    start = time.monotonic()
    with contextlib.suppress(Exception):
        load(path)
    return time.monotonic() - start


def flipped_byte(lab: Lab, where: str) -> Row:
    case = f"flipped byte in {where}"
    path = lab.copy()
    with h5py.File(path, "r") as f:
        if where == "current data chunk":
            info = f["current/i_a_A"].id.get_chunk_info(20)
            offset, first = info.byte_offset + 64, int(info.chunk_offset[0])
        else:  # the root object header region, just past the superblock
            offset, first = 60, None
    with path.open("r+b") as fh:
        fh.seek(offset)
        b = fh.read(1)
        fh.seek(offset)
        fh.write(bytes([b[0] ^ 0xFF]))
    check = acq("check", str(path), timeout=60)
    problem = clean(check, (1, 2) if first is None else (1,))
    if problem is None and first is not None:
        span = f"current: samples {first:,}–".replace(",", " ")
        problem = None if span in check.out.replace("\n", "") else f"span {span} not reported"
    analyze = acq("analyze", str(path), "--no-report", timeout=60)
    problem = problem or clean(analyze, (2,))
    return row(case, check, problem, note=f"check {check.seconds:.1f} s")


def zeroed(lab: Lab, where: str) -> Row:
    """Bytes replaced by zeros, as storage that lost them leaves them (a cut pre-allocated download, blocks a file
    system zero-fills after a crash): a chunk's samples and checksum (Fletcher32 of zeros is 0: it passes), a
    4 KiB-aligned region of 64 KiB around the middle of the file, whatever lies there, or the file's second half (a cut
    copy pre-allocated to full size). Handled: ``acq check`` names a span "zeroed on disk" or the zeroed end (exit 1),
    every sample kept is the intact file's, none is a row of the zeroed bytes."""
    case = f"zeroed {where}: check, analyze, analyze --partial"
    path = lab.folder() / "s.h5"
    shutil.copyfile(lab.session, path)  # not Lab.copy: the session_id it writes lies at the end, in the zeroed half
    with h5py.File(path, "r") as f:
        size = path.stat().st_size
        if where == "region":
            span = (size // 2 // 4096 * 4096, size // 2 // 4096 * 4096 + (64 << 10))
        elif where == "second half":
            span = (size // 2, size)
        else:
            info = f[where].id.get_chunk_info(8)
            span = (info.byte_offset, info.byte_offset + info.size)
    with path.open("r+b") as fh:
        fh.seek(span[0])
        fh.write(bytes(span[1] - span[0]))
    check = acq("check", str(path), timeout=60)
    named = " zeroed on disk\n" in check.out or f"{path}: file zeroed from byte " in check.out
    problem = clean(check, (1,)) or (None if named else "no span named zeroed on disk")
    kept = stored = ""
    if problem is None:
        part, whole = load(path), load(lab.session)
        kept = f"{part.current.sample_count} / {part.encoder.index.size}"
        stored = f"{whole.current.sample_count} / {whole.encoder.index.size}"
        same = all(np.array_equal(v, whole.current.phases_a[ch][part.current.sample_index()])
                   for ch, v in part.current.phases_a.items())
        same = same and np.array_equal(part.encoder.position_counts,
                                       whole.encoder.position_counts[np.isin(whole.encoder.index, part.encoder.index)])
        problem = None if same else "samples kept that the intact file does not hold there"
    problem = problem or clean(acq("analyze", str(path), "--no-report", timeout=60), (2,))
    partial = acq("analyze", str(path), "--no-report", "--partial", timeout=120)
    problem = problem or clean(partial, (0, 1))
    return row(case, check, problem, kept, stored, note=f"check {check.seconds:.1f} s")


def malformed(lab: Lab, what: str, spoil: Callable[[h5py.File], None]) -> Row:
    path = lab.copy()
    with h5py.File(path, "r+") as f:
        spoil(f)
    worst: Row | None = None
    for command in ("info", "check", "analyze"):
        run = acq(command, str(path), timeout=60)
        problem = clean(run, (2,)) or (None if str(path) in run.err else "file not named")
        worst = row(f"{what}: info/check/analyze", run, problem)
        if problem:
            return worst
    assert worst is not None
    return worst


def hostile_name(lab: Lab, joint: str) -> Row:
    out = lab.folder() / "out"
    run = acq("record", "--profile", "triangle_0.2s", "--fast", "--duration", "0.5", "--no-analyze", "--joint", joint,
              "--out", str(out))
    escaped = [p for p in lab.root.rglob("*escaped*")]
    problem = clean(run, (2,)) or ("wrote outside --out" if escaped else None) or \
        ("a session was written" if out.exists() and any(out.iterdir()) else None)
    return row(f"joint name {joint!r}", run, problem)


def absurd(lab: Lab, what: str, args: list[str], bench_edit: tuple[str, str] | None = None,
           profile_edit: tuple[str, str] | None = None) -> Row:
    folder = lab.folder()
    extra: list[str] = []
    if bench_edit:
        bench = folder / "b.toml"
        bench.write_text(DEFAULT_BENCH.read_text().replace(*bench_edit))
        extra += ["--bench", str(bench)]
    profile = "triangle_0.2s"
    if profile_edit:
        p = folder / "p.toml"
        p.write_text(resolve_profile_path("triangle_0.2s").read_text().replace(*profile_edit))
        profile = str(p)
    run = acq("record", "--profile", profile, "--fast", "--no-analyze", "--out", str(folder / "out"), *args, *extra)
    problem = clean(run, (2,)) or ("a session was written" if (folder / "out").exists() else None)
    return row(what, run, problem)


def csv_beyond_bound(lab: Lab) -> Row:
    folder = lab.folder()
    csv = folder / "csv"
    assert acq("export", str(lab.session), "--csv", str(csv)).code == 0
    cur, enc = sorted(csv.glob("*current.csv"))[0], sorted(csv.glob("*encoder.csv"))[0]
    lines = cur.read_text().splitlines()
    cells = lines[99].split(",")
    cells[1] = "1e300"
    lines[99] = ",".join(cells)
    cur.write_text("\n".join(lines) + "\n")
    run = acq("import", "--current", str(cur), "--encoder", str(enc), "--bench", str(DEFAULT_BENCH), "--profile",
              "triangle_0.2s", "-o", str(folder / "imp.h5"))
    problem = clean(run, (2,)) or (None if "line 100, column" in run.err else "line/column not named")
    return row("CSV value 1e300 at import", run, problem)


def narrow_band(lab: Lab) -> Row:
    run = acq("analyze", str(lab.copy()), "--band", "200,210", "--no-report")
    return row("--band 200,210 (divide-by-zero warning before)", run, clean(run, (2,)))


def concurrent_recorders(lab: Lab) -> Row:
    out = lab.folder()
    cmd = [sys.executable, "-m", "acq", "record", "--profile", "triangle_0.2s", "--fast", "--duration", "2",
           "--no-analyze", "--out", str(out)]
    procs = [subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True) for _ in range(3)]
    runs = [Run(p.wait(timeout=120), "", p.stderr.read() if p.stderr else "", 0.0) for p in procs]
    files = sorted(out.glob("*.h5"))
    problem = next((clean(r, (0,)) for r in runs if clean(r, (0,))), None)
    counts = [load(f).current.sample_count for f in files]
    if problem is None and (len(files) != 3 or min(counts) < 2 * RATE_HZ):
        problem = f"{len(files)} files, counts {counts}"
    return row("3 recorders into one folder at once", runs[0], problem, "3 × ≥ 51200", sum(counts))


def concurrent_analyses(lab: Lab) -> Row:
    path = lab.copy()
    cmd = [sys.executable, "-m", "acq", "analyze", str(path), "--no-report"]
    procs = [subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True) for _ in range(2)]
    runs = [Run(p.wait(timeout=180), "", p.stderr.read() if p.stderr else "", 0.0) for p in procs]
    problem = next((clean(r, (0,)) for r in runs if clean(r, (0,))), None)
    with sqlite3.connect(path.parent / "catalogue.sqlite") as db:
        rows = db.execute("SELECT count(*) FROM analyses").fetchone()[0]
    problem = problem or (None if rows == 1 else f"{rows} catalogue rows") or \
        (f"temp files {temp_files(path.parent)}" if temp_files(path.parent) else None)
    return row("2 analyses of one session at once", runs[0], problem)


def signal_record(lab: Lab, sig: signal.Signals) -> Row:
    case = f"{sig.name} during record"
    out = lab.folder()
    p = subprocess.Popen([sys.executable, "-m", "acq", "record", "--profile", "triangle_0.2s", "--duration", "30",
                          "--no-analyze", "--out", str(out)], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                         text=True)
    deadline = time.monotonic() + 30
    while time.monotonic() < deadline:
        files = list(out.glob("*.h5"))
        if files:
            with contextlib.suppress(Exception):
                if load(files[0]).current.sample_count >= 2 * RATE_HZ:
                    break
        time.sleep(0.2)
    p.send_signal(sig)
    o, e = p.communicate(timeout=30)
    run = Run(p.returncode, o, e, 0.0)
    (path,) = out.glob("*.h5")
    if sig == signal.SIGKILL:
        before, why = stored_ok(path)
        check = acq("check", str(path))
        after, why2 = stored_ok(path)
        problem = why or why2 or clean(check, (0,)) or (None if after == before else "repair changed the counts")
        return row(case + " (then acq check)", check, problem, "—", after)
    problem = clean(run, (130,))
    reported = counts_in(run)
    stored, why = stored_ok(path)
    problem = problem or why or (None if reported and reported[0] == stored else f"reported {reported}")
    problem = problem or (None if load(path).status == "interrupted" else f"status {load(path).status}")
    return row(case, run, problem, reported[0] if reported else "", stored)


def signal_analyze(lab: Lab, sig: signal.Signals) -> Row:
    path = lab.copy()
    p = subprocess.Popen([sys.executable, "-m", "acq", "analyze", str(path)], stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, text=True)
    time.sleep(5.0)  # start-up and loading: the analysis is under way (or, on a loaded machine, the imports)
    p.send_signal(sig)
    o, e = p.communicate(timeout=30)
    run = Run(p.returncode, o, e, 0.0)
    results = sorted(q.name for q in path.parent.glob("*.result.json"))
    # 130 from acq; -SIG when the signal came during the interpreter's imports, before acq could catch it: the
    # process ends quietly by that signal (a shell shows 128 + SIG), nothing written yet
    quiet_death = run.code == -sig and "Traceback" not in run.err
    problem = None if run.code == 0 or quiet_death else clean(run, (130,))
    rows = 0
    if (path.parent / "catalogue.sqlite").exists():
        with sqlite3.connect(path.parent / "catalogue.sqlite") as db:
            rows = db.execute("SELECT count(*) FROM analyses").fetchone()[0]
    if sig != signal.SIGKILL and bool(results) != bool(rows):
        problem = problem or f"{len(results)} result files, {rows} rows"
    problem = problem or (f"temp files {temp_files(path.parent)}" if sig != signal.SIGKILL and
                          temp_files(path.parent) else None)
    return row(f"{sig.name} during analyze", run, problem, note=f"exit after {'finish' if run.code == 0 else 'signal'}")


def signal_batch(lab: Lab, sig: signal.Signals, sessions: int = 6) -> Row:
    folder = lab.folder()
    for i in range(sessions):
        lab.copy(folder, f"s{i}.h5")
    p = subprocess.Popen([sys.executable, "-m", "acq", "analyze", str(folder), "--jobs", "2", "--no-report"],
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 180
    while not list(folder.glob("*.result.json")) and time.monotonic() < deadline:
        time.sleep(0.05)
    sent = time.monotonic()
    p.send_signal(sig)
    if sig == signal.SIGKILL:  # the orphaned workers keep the pipes open until they end: do not read them
        p.wait(timeout=60)
        run = Run(p.returncode, "", "", time.monotonic() - sent)
        time.sleep(5.0)  # the orphans see the pool's pipe closed and end after their current analysis
    else:
        o, e = p.communicate(timeout=60)
        run = Run(p.returncode, o, e, time.monotonic() - sent)
    stop_s = run.seconds

    def consistency() -> tuple[list[str], list[str]]:
        with sqlite3.connect(folder / "catalogue.sqlite") as db:
            ok = sorted(Path(r[0]).name for r in db.execute(
                "SELECT s.path FROM sessions s JOIN analyses a USING (session_key) WHERE a.error IS NULL"))
        return ok, sorted(q.name.replace(".result.json", ".h5") for q in folder.glob("*.result.json"))

    if sig == signal.SIGKILL:  # nothing can tidy up after SIGKILL: the next batch must make it consistent
        again = acq("analyze", str(folder), "--jobs", "2", "--no-report", timeout=300)
        rows, results = consistency()
        problem = clean(again, (0,)) or (None if rows == results and len(rows) == sessions else
                                          f"rows {rows} vs results {results}")
        return row("SIGKILL during batch (then batch again)", again, problem, len(results), len(rows))
    rows, results = consistency()
    problem = clean(run, (130,)) or (None if stop_s <= 2.0 else f"stopped after {stop_s:.2f} s")
    problem = problem or (None if rows == results else f"rows {rows} vs results {results}")
    problem = problem or (f"temp files {temp_files(folder)}" if temp_files(folder) else None)
    return row(f"{sig.name} during batch of {sessions}", run, problem, len(results), len(rows),
               note=f"stopped in {stop_s:.2f} s")


def recording_session_in_batch(lab: Lab) -> Row:
    folder = lab.folder()
    lab.copy(folder, "a.h5")
    live = lab.copy(folder, "b.h5")
    with h5py.File(live, "r+") as f:
        f.attrs["status"] = "recording"
    run = acq("analyze", str(folder), "--no-report", "--jobs", "1", "--json", timeout=300)
    problem = clean(run, (0,)) or (None if '"skipped: status recording"' in run.out else "not skipped")
    single = acq("analyze", str(live), "--no-report")
    problem = problem or clean(single, (2,))
    return row("session still recording: batch skips, analyze refuses", run, problem)


# ------------------------------------------------------------------------------------------ campaign


def cases(lab: Lab, quick: bool) -> list[tuple[str, Callable[[], Row]]]:
    """(name, run) of every case; ``quick`` keeps the ones that take no recording or signal (the pytest part)."""
    fast: list[tuple[str, Callable[[], Row]]] = [
        *[(f"cut{p}", lambda p=p: cut_file(lab, p)) for p in (10, 30, 50, 90)],
        ("flip data", lambda: flipped_byte(lab, "current data chunk")),
        ("flip meta", lambda: flipped_byte(lab, "metadata")),
        *[(f"zeroed {w}", lambda w=w: zeroed(lab, w)) for w in ("current/i_a_A", "encoder/index", "region",
                                                                          "second half")],
        ("no encoder", lambda: malformed(lab, "no /encoder group", lambda f: f.__delitem__("encoder"))),
        ("no blocks", lambda: malformed(lab, "no /current/blocks", lambda f: f.__delitem__("current/blocks"))),
        ("bad bench_json", lambda: malformed(lab, "corrupt bench_json",
                                             lambda f: f.attrs.__setitem__("bench_json", "{not json"))),
        ("bad tags", lambda: malformed(lab, "corrupt tags_json", lambda f: f.attrs.__setitem__("tags_json", "[["))),
        ("bad rate attr", lambda: malformed(lab, "no /current rate_hz",
                                            lambda f: f["current"].attrs.__delitem__("rate_hz"))),
        *[(f"name {j!r}", lambda j=j: hostile_name(lab, j))
          for j in ("x/../../../escaped", "a/b", "../../x", "/etc/passwd", "a\tb", "", ".x", "j" * 65, "a\u200fb")],
        ("duration nan", lambda: absurd(lab, "--duration nan", ["--duration", "nan"])),
        ("duration inf", lambda: absurd(lab, "--duration inf", ["--duration", "inf"])),
        ("duration 1e9", lambda: absurd(lab, "--duration 1e9", ["--duration", "1e9"])),
        ("rate", lambda: absurd(lab, "rate_hz = 1e12", [], bench_edit=("rate_hz = 25600", "rate_hz = 1e12"))),
        ("drift", lambda: absurd(lab, "daq_drift_ppm = 1e6", [], bench_edit=("daq_drift_ppm = 40.0",
                                                                              "daq_drift_ppm = 1e6"))),
        ("speed", lambda: absurd(lab, "top_speed_rpm = 1e9", [], profile_edit=("top_speed_rpm = ",
                                                                                "top_speed_rpm = 1e9 # "))),
        ("csv", lambda: csv_beyond_bound(lab)),
        ("band", lambda: narrow_band(lab)),
    ]
    if quick:
        return fast
    slow: list[tuple[str, Callable[[], Row]]] = [
        *[(f"full {s}", lambda s=s: disk_full_record(lab, s)) for s in ("3m", "6m", "12m", "24m")],
        ("full hdf5", lambda: disk_full_record(lab, "4m", inside_hdf5=True)),
        *[(f"full {w}", lambda w=w: disk_full_output(lab, w))
          for w in ("result JSON", "report PNG", "catalogue", "CSV export", "import")],
        ("vanished", lambda: vanished_folder(lab)),
        ("recorders", lambda: concurrent_recorders(lab)),
        ("analyses", lambda: concurrent_analyses(lab)),
        ("recording in batch", lambda: recording_session_in_batch(lab)),
        *[(f"record {s.name}", lambda s=s: signal_record(lab, s))
          for s in (signal.SIGINT, signal.SIGTERM, signal.SIGKILL)],
        *[(f"analyze {s.name}", lambda s=s: signal_analyze(lab, s))
          for s in (signal.SIGINT, signal.SIGTERM, signal.SIGKILL)],
        *[(f"batch {s.name}", lambda s=s: signal_batch(lab, s))
          for s in (signal.SIGINT, signal.SIGTERM, signal.SIGKILL)],
    ]
    return fast + slow


def run_campaign(quick: bool = False, only: str | None = None) -> list[Row]:
    with tempfile.TemporaryDirectory(prefix="acq-faults-") as tmp:
        lab = Lab(Path(tmp))
        rows = []
        for name, run in cases(lab, quick):
            if only and only not in name:
                continue
            try:
                rows.append(run())
            except Exception as e:  # noqa: BLE001 - a crash of the case itself is a bad case, not the end
                rows.append(Row(name, None, None, "", "", "bad", f"case crashed: {type(e).__name__}: {e}"))
        return rows


def table(rows: list[Row]) -> Table:
    t = Table(title="acq fault campaign")
    for column in ("case", "exit", "stderr lines", "samples kept", "samples stored", "verdict", "note"):
        t.add_column(column)
    for r in rows:
        t.add_row(r.case, "—" if r.code is None else str(r.code), "—" if r.stderr_lines is None else str(r.stderr_lines),
                  r.kept, r.stored, f"[green]{r.verdict}" if r.verdict == "handled" else f"[red]{r.verdict}", r.note)
    handled = sum(r.verdict == "handled" for r in rows)
    t.caption = f"{handled} of {len(rows)} cases handled ({sum(r.verdict == 'skipped' for r in rows)} skipped)"
    return t


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="only the cases without recording or signals")
    parser.add_argument("--only", default=None, help="only cases whose name contains this")
    args = parser.parse_args()
    start = time.monotonic()
    rows = run_campaign(args.quick, args.only)
    console = Console(width=200)
    console.print(table(rows))
    console.print(f"{time.monotonic() - start:.0f} s")
    sys.exit(0 if all(r.verdict != "bad" for r in rows) else 1)


if __name__ == "__main__":
    main()
