"""A finished session file cut short (a partial copy, a truncated download): the samples whose chunks lie wholly
before the cut are kept, the loss is stated, nothing after the cut is invented; ``acq check --repair`` copies them
into a new session beside it. A file of an older acq (its root attributes past the cut) stays refused in one line."""

from __future__ import annotations

import hashlib
import json
import shutil
from pathlib import Path

import h5py
import numpy as np
import pytest

from acq.config import load_bench, load_profile
from acq.recording.reader import load
from acq.recording.recorder import Recorder
from acq.recording.session import Session
from drivers.registry import open_bench
from tests.helpers import ReadsFile, footer_strings_past, rewritten_as_older_acq, rewritten_in_real_time, run_cli

RATE_HZ = 25600
ENCODER_HZ = 1000


@pytest.fixture(scope="module")
def recorded(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A 10 s session of the simulated bench recorded by the real recorder (--fast), written again committed every
    0.5 s of data as a real-time recording commits (:func:`rewritten_in_real_time`): a --fast recording
    commits at 2 MiB or at the 0.5 s clock, whichever the machine's load lets come first, so where its chunks,
    chunk indexes and footer strings lie would differ from run to run."""
    bench = load_bench()
    current, drive = open_bench(bench, fast=True)
    folder = tmp_path_factory.mktemp("rec")
    result = Recorder(bench, load_profile("triangle_0.2s"), current, drive, folder, 10.0).run()
    path = rewritten_in_real_time(result.path, folder / "session.h5")
    with h5py.File(path, "r") as f:
        assert f["flushes"].shape[0] == 21  # 20 commits and the one SessionWriter.finish makes
    return path


@pytest.fixture(scope="module")
def intact(recorded: Path) -> Session:
    return load(recorded)


def _rows_before(path: Path, cut: int) -> dict[str, int]:
    """Rows of each dataset of ``path`` up to its first chunk that does not lie wholly before byte ``cut``, or whose
    place HDF5 finds only past it (its chunk-index entry: measured as the furthest byte HDF5 reads to find the chunk,
    and every chunk before it)."""
    fh = ReadsFile(path)
    rows: dict[str, int] = {}
    with h5py.File(fh, "r", rdcc_nbytes=0) as f:
        names: list[str] = []
        f.visititems(lambda name, obj: names.append(name) if isinstance(obj, h5py.Dataset) else None)
        for name in names:
            fh.end, ds, rows[name] = 0, f[name], 0
            for start in range(0, ds.shape[0], ds.chunks[0]):
                info = ds.id.get_chunk_info_by_coord((start,))
                if max(fh.end, info.byte_offset + info.size) > cut:
                    break
                rows[name] = min(start + ds.chunks[0], ds.shape[0])
    return rows


def _kept_before(path: Path, cut: int) -> tuple[int, int]:
    """(current, encoder) samples of the intact file ``path`` a copy cut at byte ``cut`` holds whole: a current
    sample needs its chunk in every phase and its DAQ read's row in each block-table column; an encoder sample its
    chunk in every column."""
    rows = _rows_before(path, cut)
    with h5py.File(path, "r") as f:
        phases = min(rows[f"current/{name}"] for name in f["current"] if name.endswith("_A"))
        reads = min(rows[f"current/blocks/{name}"] for name in ("count", "first_index", "host_ns"))
        ends = np.cumsum(f["current/blocks/count"][:reads])
        encoder = min(rows[f"encoder/{name}"] for name in f["encoder"])
    current = int(ends[ends <= phases][-1]) if np.any(ends <= phases) else 0
    return current, encoder


def _cut_copy(src: Path, dst: Path, percent: int) -> tuple[int, int]:
    """Copy ``src`` to ``dst`` cut to ``percent`` % of its bytes; (bytes kept, bytes of the whole)."""
    shutil.copyfile(src, dst)
    size = dst.stat().st_size
    with dst.open("r+b") as fh:
        fh.truncate(size * percent // 100)
    return size * percent // 100, size


def _bytes(n: int) -> str:
    return f"{n:,}".replace(",", " ")


def _assert_prefix_of(s: Session, intact: Session, current: int, encoder: int) -> None:
    """``s`` holds exactly the first ``current`` / ``encoder`` samples of ``intact``, value for value."""
    assert (s.current.sample_count, s.encoder.index.size) == (current, encoder)
    for ch, values in s.current.phases_a.items():
        assert np.array_equal(values, intact.current.phases_a[ch][:current])
    reads = s.current.block_count.size
    assert int(s.current.block_count.sum()) == current
    for name in ("block_first_index", "block_count", "block_host_ns"):
        assert np.array_equal(getattr(s.current, name), getattr(intact.current, name)[:reads])
    for name in ("position_counts", "index", "host_ns", "drive_time_s", "velocity_demand_counts_per_s"):
        assert np.array_equal(getattr(s.encoder, name), getattr(intact.encoder, name)[:encoder])


@pytest.mark.parametrize("percent", [10, 30, 50, 90])
def test_a_cut_copy_keeps_the_samples_before_the_cut_and_says_what_is_lost(
        recorded: Path, intact: Session, tmp_path: Path, percent: int, capsys: pytest.CaptureFixture[str]) -> None:
    """Before: every cut was refused whole, 'not a readable HDF5 session file (file cut: …, root attributes lost)'."""
    path = tmp_path / "cut.h5"
    cut, size = _cut_copy(recorded, path, percent)
    current, encoder = _kept_before(recorded, cut)
    assert current < 10 * RATE_HZ and encoder < 10 * ENCODER_HZ
    if percent >= 30:  # what the test is about: a real part of both streams kept
        assert current >= (percent - 20) / 100 * 10 * RATE_HZ and encoder >= (percent - 20) / 100 * 10 * ENCODER_HZ
    s = load(path)
    _assert_prefix_of(s, intact, current, encoder)
    assert footer_strings_past(recorded, cut) == []  # written in place, before the data (they were at the file's end)
    assert s.damage[0] == f"file cut: {_bytes(cut)} of {_bytes(size)} bytes"
    assert (s.status, s.meta.stop_reason) == (intact.status, intact.meta.stop_reason)
    assert intact.status == "complete" and intact.meta.stop_reason.startswith("recorded")
    assert s.damage[1:] == (f"current: samples {_bytes(current)}–{_bytes(10 * RATE_HZ - 1)} unreadable",
                            f"encoder: samples {_bytes(encoder)}–{_bytes(10 * ENCODER_HZ - 1)} unreadable")
    run = run_cli(capsys, "check", str(path))
    assert run.code == 1
    assert "".join(f"{path}: {line}\n" for line in s.damage) in run.out
    assert run.err == (f"acq: damaged: {path} ({'; '.join(s.damage)}) — the intact part holds {current} current and "
                       f"{encoder} encoder samples (acq analyze --partial uses it; acq check --repair copies it into "
                       f"{tmp_path / 'cut.recovered.h5'})\n")


@pytest.mark.parametrize("percent", [30, 90])
def test_check_repair_copies_the_samples_before_the_cut_into_a_new_session_and_leaves_the_cut_file_alone(
        recorded: Path, intact: Session, tmp_path: Path, percent: int, capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "cut.h5"
    cut, size = _cut_copy(recorded, path, percent)
    before = hashlib.sha256(path.read_bytes()).hexdigest()
    current, encoder = _kept_before(recorded, cut)
    run = run_cli(capsys, "check", "--repair", str(path))
    assert run.code == 1  # the copy is written, and the loss is an error still
    copy_path = tmp_path / "cut.recovered.h5"
    assert run.err == (f"acq: damaged: {path} ({'; '.join(load(path).damage)}) — not modified; its intact part is "
                       f"in {copy_path}\n")
    copy = load(copy_path)
    was = load(path).meta
    reason = (f"recovered from a file cut at {_bytes(cut)} of {_bytes(size)} bytes: {current / RATE_HZ:.1f} s of "
              f"current, {encoder / ENCODER_HZ:.1f} s of encoder kept (was complete"
              + (f": {was.stop_reason})" if was.stop_reason else ")"))
    assert run.out.endswith(f"{path}: intact part copied into {copy_path}: {current} current and {encoder} encoder "
                            f"samples, status interrupted, stop reason: {reason}\n")
    assert copy.damage == () and copy.status == "interrupted" and copy.meta.stop_reason == reason
    assert copy.meta.session_id == intact.meta.session_id
    _assert_prefix_of(copy, intact, current, encoder)
    assert hashlib.sha256(path.read_bytes()).hexdigest() == before  # the cut file is not written
    again = run_cli(capsys, "check", str(copy_path))
    assert again.code == 0 and "nothing to repair" in again.out


def test_a_cut_copy_is_analysed_with_partial_only(recorded: Path, tmp_path: Path,
                                                 capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "cut.h5"
    _cut_copy(recorded, path, 90)
    refused = run_cli(capsys, "analyze", str(path), "--no-report")
    assert refused.code == 2
    assert refused.err.startswith(f"acq: error: {path}: damaged (file cut: ")
    assert refused.err.endswith(" — run acq check, or use --partial to analyse the intact part\n")
    run = run_cli(capsys, "analyze", str(path), "--partial", "--no-report", "--json")
    assert run.code in (0, 1), run.err
    assert json.loads(run.out)["partial"] is True


def _older_footer(path: Path) -> None:
    """Rewrite ``path``'s footer as acq wrote it before the counts were created with the file: the counts added
    as new attributes and every footer attribute assigned (HDF5 then rewrites the dense-attribute index at the end)."""
    with h5py.File(path, "r+", libver=("v110", "latest")) as f:
        counts = {name: f.attrs[name] for name in ("current_samples", "encoder_samples")}
        for name in counts:
            del f.attrs[name]
        for name in ("status", "stop_reason", "stopped_utc"):
            f.attrs[name] = f.attrs[name]
        f.attrs.update(counts)


@pytest.mark.parametrize("percent", [50, 90])
def test_a_cut_copy_of_an_older_file_is_refused_in_one_line(recorded: Path, tmp_path: Path, percent: int,
                                                            capsys: pytest.CaptureFixture[str]) -> None:
    older = tmp_path / "older.h5"
    shutil.copyfile(recorded, older)
    _older_footer(older)
    assert load(older).damage == ()
    path = tmp_path / "cut.h5"
    cut, size = _cut_copy(older, path, percent)
    for command in ("check", "info"):
        run = run_cli(capsys, command, str(path))
        assert run.code == 2
        assert run.err == (f"acq: error: {path}: not a readable HDF5 session file (file cut: {_bytes(cut)} of "
                           f"{_bytes(size)} bytes, root attributes lost)\n")


def test_a_cut_copy_whose_status_is_lost_keeps_the_samples_the_footer_counts(
        recorded: Path, intact: Session, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The committed counts are the footer's numbers, stored in place: a cut that loses the status string loses no
    sample. acq now writes its footer strings in place (fixed length); an older acq wrote variable-length strings, and
    the test moves those to the file's end: a value larger than the free room of HDF5's string heap (≈ 4 KiB,
    measured) goes into a new heap there, as a footer string of another writer may. Before: refused, 'damaged, cannot
    be read (file cut: …)'."""
    moved = rewritten_as_older_acq(recorded, tmp_path / "moved.h5")
    with h5py.File(moved, "r+", libver=("v110", "latest")) as f:
        f.attrs.modify("status", "complete" + " " * 5000)
    path = tmp_path / "cut.h5"
    cut, size = _cut_copy(moved, path, 90)
    assert footer_strings_past(moved, cut) == ["status", "stop_reason", "stopped_utc"]
    current, encoder = _kept_before(moved, cut)
    assert current >= 0.7 * 10 * RATE_HZ and encoder >= 0.7 * 10 * ENCODER_HZ
    s = load(path)
    assert s.status == ""
    _assert_prefix_of(s, intact, current, encoder)
    assert s.damage == (f"file cut: {_bytes(cut)} of {_bytes(size)} bytes, status and stop_reason and stopped_utc lost",
                        f"current: samples {_bytes(current)}–{_bytes(10 * RATE_HZ - 1)} unreadable",
                        f"encoder: samples {_bytes(encoder)}–{_bytes(10 * ENCODER_HZ - 1)} unreadable")
    run = run_cli(capsys, "check", "--repair", str(path))
    assert run.code == 1 and run.err.startswith(f"acq: damaged: {path} (")
    copy = load(tmp_path / "cut.recovered.h5")
    assert copy.damage == () and copy.status == "interrupted"
    _assert_prefix_of(copy, intact, current, encoder)


def test_a_cut_copy_of_a_recovered_copy_keeps_its_attributes_and_the_samples_before_the_cut(
        recorded: Path, intact: Session, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The recovered copy is created as the writer creates a file (every attribute, group and dataset before the
    data, the counts overwritten in place) and written in slices of both streams, so a cut copy of it is read as one
    of a recording is. Before: refused, 'not a readable HDF5 session file (file cut: …, root attributes lost)'."""
    path = tmp_path / "cut.h5"
    _cut_copy(recorded, path, 90)
    assert run_cli(capsys, "check", "--repair", str(path)).code == 1
    recovered = tmp_path / "cut.recovered.h5"
    copy = load(recovered)
    again = tmp_path / "again.h5"
    cut, size = _cut_copy(recovered, again, 90)
    current, encoder = _kept_before(recovered, cut)
    total_current, total_encoder = copy.current.sample_count, copy.encoder.index.size
    assert total_current > current >= 0.85 * total_current and total_encoder > encoder >= 0.85 * total_encoder
    s = load(again)
    assert s.status == "interrupted" and s.meta.stop_reason == copy.meta.stop_reason
    _assert_prefix_of(s, intact, current, encoder)
    assert s.damage == (f"file cut: {_bytes(cut)} of {_bytes(size)} bytes",
                        f"current: samples {_bytes(current)}–{_bytes(total_current - 1)} unreadable",
                        f"encoder: samples {_bytes(encoder)}–{_bytes(total_encoder - 1)} unreadable")
