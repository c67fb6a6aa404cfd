"""Small helpers shared by tests: run the CLI in-process and capture its exit code and output; record a session."""

from __future__ import annotations

import contextlib
import io
import os
import shutil
import subprocess
import sys
from collections.abc import Iterator
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any

import h5py
import numpy as np
import pytest

import acq.recording.writer
from acq.recording import layout
from acq.recording.layout import FOOTER_TEXT
from acq.recording.reader import load
from acq.recording.writer import SessionWriter
from acq.ui.cli import main
from drivers.base import CurrentSourceInfo, DriveInfo, EncoderBlock


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


def record_session_in_subprocess(out: Path, duration_s: float, channels: tuple[str, ...] = ("i_a",)) -> Path:
    """``acq record --profile triangle_0.2s --fast`` (dither seed 0) of ``duration_s`` into ``out`` in a child process
    (nothing of the recording stays in the test process), on the default simulated bench with the DAQ's ``channels``;
    the one session file it wrote."""
    out.mkdir(parents=True, exist_ok=True)
    profile = seeded_profile(out.parent)
    bench = (Path(__file__).parents[1] / "configs/benches/sim.toml").read_text()
    assert 'channels = ["i_a"]' in bench
    bench_path = out.parent / "bench.toml"
    bench_path.write_text(bench.replace('channels = ["i_a"]', f"channels = {list(channels)!r}".replace("'", '"')))
    proc = subprocess.run([sys.executable, "-m", "acq", "record", "--profile", str(profile), "--bench",
                           str(bench_path), "--fast", "--duration", f"{duration_s:g}", "--no-analyze", "--out",
                           str(out)], capture_output=True, text=True, timeout=120)
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
def tmpfs(folder: Path, options: str) -> Iterator[str | None]:
    """A tmpfs mounted on ``folder`` with ``options`` (``size=6m``, ``ro,size=1m``) for the block, unmounted after
    (lazily: a test's open file must not keep it); yields None when mounted, else why not (not root, no mount(8), the
    mount refused) — the caller skips or falls back."""
    if os.geteuid() != 0 or shutil.which("mount") is None:
        yield "needs root and mount(8)"
        return
    mounted = subprocess.run(["mount", "-t", "tmpfs", "-o", options, "tmpfs", str(folder)], capture_output=True,
                             text=True)
    if mounted.returncode != 0:
        yield mounted.stderr.strip()
        return
    try:
        yield None
    finally:
        subprocess.run(["umount", "-l", str(folder)], check=False)


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
    with tmpfs(folder, "ro,size=1m") as refused:
        if refused is not None:
            pytest.skip(f"needs a read-only tmpfs mount as root: {refused}")
        yield folder, "read-only file system"


#: A real-time recording commits every 0.5 s of wall time (acq.recording.recorder.FLUSH_INTERVAL_S), i.e. every 0.5 s
#: of data; a --fast one commits whenever its load lets the 0.5 s or the 2 MiB come first.
COMMIT_EVERY_S = 0.5


def rewritten_in_real_time(src: Path, dst: Path, commit_every_s: float = COMMIT_EVERY_S) -> Path:
    """``src`` (a finished recording) written again into ``dst`` by the real :class:`SessionWriter`, committed every
    ``commit_every_s`` s of data (by default as a real-time recording commits): the DAQ reads ending in each span of
    samples, the encoder rows of each span of drive cycles and the events before the commit's last read. A --fast recording
    commits where the machine's load puts the 0.5 s clock, and so places its chunks, chunk indexes and footer strings
    differently in every run; this file's layout is the same in every run (the samples are: dither seed 0)."""
    s = load(src)
    c, e, meta = s.current, s.encoder, s.meta
    assert s.damage == () and meta.host_ns_at_start is not None
    w = SessionWriter(dst, bench=s.bench, profile=s.profile,
                      current_info=CurrentSourceInfo(c.rate_hz, tuple(c.phases_a), c.device),
                      drive_info=DriveInfo(e.period_s, e.counts_per_rev, e.transport, e.timestamp_kind, e.device),
                      host_ns_at_start=meta.host_ns_at_start, operator=meta.operator, tags=meta.tags,
                      origin=meta.origin, host_clock_shared=meta.host_clock_shared, session_id=meta.session_id,
                      created_utc=meta.created_utc)
    read_end = np.cumsum(c.block_count)
    cycle_s = (e.index - e.index[0]) * e.period_s
    commits = int(np.ceil(round(max(read_end[-1] / c.rate_hz, cycle_s[-1] + e.period_s) / commit_every_s, 6)))
    reads = np.searchsorted(read_end, np.arange(commits + 1) * commit_every_s * c.rate_hz, side="right")
    rows = np.searchsorted(cycle_s, np.arange(commits + 1) * commit_every_s - e.period_s / 2, side="left")
    reads[-1], rows[-1] = read_end.size, e.index.size
    events = iter(sorted(s.events, key=lambda ev: ev.host_ns))
    pending_event = next(events, None)
    for k in range(commits):
        r = slice(reads[k], reads[k + 1])
        sample = [int(read_end[i - 1]) if i else 0 for i in (r.start, r.stop)]
        if r.stop > r.start:
            w.append_current_blocks([v[sample[0]:sample[1]] for v in c.phases_a.values()], c.block_first_index[r],
                                    c.block_count[r], c.block_host_ns[r])
        if rows[k + 1] > rows[k]:
            columns = {f.name: getattr(e, f.name) for f in fields(EncoderBlock)}
            w.append_encoder(EncoderBlock(**{name: None if values is None else values[rows[k]:rows[k + 1]]
                                             for name, values in columns.items()}))
        last_ns = c.block_host_ns[r.stop - 1] if r.stop else 0
        while pending_event is not None and (pending_event.host_ns <= last_ns or k == commits - 1):
            w.add_event(pending_event)
            pending_event = next(events, None)
        w.flush()
    w.finish(meta.status, meta.stop_reason)  # type: ignore[arg-type]
    return dst


def rewritten_as_older_acq(src: Path, dst: Path) -> Path:
    """``src`` written again (:func:`rewritten_in_real_time`) as acq wrote files before its footer strings were
    fixed-length: variable-length strings, created with the file and modified by the footer (a variable-length
    string's new value goes into HDF5's string heap, which may lie at the file's end)."""
    def older_unwritten() -> dict[str, Any]:
        return {**layout.footer_unwritten(), "stopped_utc": "", "status": "recording", "stop_reason": ""}

    def older_footer(f: h5py.File, status: str, stop_reason: str, filled_optional: set[str], *_: Any) -> None:
        for name in layout.OPTIONAL_ENCODER:
            if name in f["encoder"] and name not in filled_optional:
                del f["encoder"][name]
        f.attrs.modify("current_samples", np.int64(f["current/blocks/count"][...].sum()))
        f.attrs.modify("encoder_samples", np.int64(f["encoder/index"].shape[0]))
        for name, text in (("stop_reason", stop_reason), ("stopped_utc", layout.utc_now_iso()), ("status", status)):
            f.attrs.modify(name, text)

    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(acq.recording.writer, "footer_unwritten", older_unwritten)
        patch.setattr(acq.recording.writer, "write_footer", older_footer)
        return rewritten_in_real_time(src, dst)


class ReadsFile(io.FileIO):
    """A file opened for reading that remembers the furthest byte HDF5 read from it (``end``)."""

    def __init__(self, path: Path) -> None:
        super().__init__(path, "r")
        self.end = 0

    def readinto(self, buffer: Any) -> int | None:
        start = self.tell()
        self.end = max(self.end, start + len(buffer))
        return super().readinto(buffer)


def footer_strings_past(path: Path, cut: int) -> list[str]:
    """The footer's strings (:data:`FOOTER_TEXT`, in the file's attribute order) of the intact file ``path`` that HDF5
    reads from at or past byte ``cut``: a copy cut there loses them. Where HDF5 puts them depends on the file's
    history (a freed block reused, or the file's end), so it is measured: the furthest byte read to read each, in a
    file opened anew for each."""
    with h5py.File(path, "r") as f:
        names = [name for name in f.attrs if name in FOOTER_TEXT]
    past = []
    for name in names:
        with ReadsFile(path) as fh, h5py.File(fh, "r") as f:
            fh.end = 0
            f.attrs[name]
            if fh.end > cut:
                past.append(name)
    return past
