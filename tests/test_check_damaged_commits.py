"""`acq check` of a file whose commit table (/flushes) or block table fails its checksum: nothing readable is lost.

A new user's trial: a killed recorder's file with one byte flipped in /flushes was "repaired" in place to 0 current
and 0 encoder samples (1 064 957 → 10 767 bytes, exit 0); one flipped in the block table's host stamps to 0 current
samples; a complete file with /flushes damaged passed as "checksums and counts verified". Real files of the real
recorder (a SIGKILLed one, a finished --fast one), damaged with one byte.
"""

from __future__ import annotations

import json
import os
import shutil
import signal
from pathlib import Path

import h5py
import numpy as np
import pytest

from acq.recording.reader import load
from tests.helpers import record_session_in_subprocess, run_cli
from tests.test_recorder import RATE_HZ, _start_recording, _wait_for_samples

DAMAGED_COMMITS = "the last commit lost with them: the samples stored are read"


@pytest.fixture(scope="module")
def killed(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A real-time recording SIGKILLed once 1 s of current is committed (status ``recording``)."""
    out = tmp_path_factory.mktemp("killed")
    proc = _start_recording(out, 60)
    path = _wait_for_samples(out, proc, RATE_HZ)
    os.kill(proc.pid, signal.SIGKILL)
    proc.communicate(timeout=30)
    return path


@pytest.fixture(scope="module")
def repaired_intact(killed: Path, tmp_path_factory: pytest.TempPathFactory) -> tuple[int, int]:
    """What `acq check` keeps of an undamaged copy of ``killed``: (current, encoder) samples."""
    copy = tmp_path_factory.mktemp("intact") / "intact.h5"
    shutil.copyfile(killed, copy)
    s = load(copy)
    assert s.status == "recording" and s.damage == ()
    from acq.recording.repair import repair
    r = repair(copy, "test")
    assert r.path == copy and r.status == "interrupted"
    return r.current.sample_count, r.encoder.index.size


def _flip(path: Path, name: str, chunk: int = 0) -> int:
    """XOR 0xFF one byte in the middle of chunk ``chunk`` of dataset ``name``; the dataset's stored rows."""
    with h5py.File(path, "r", swmr=True) as f:
        info = f[name].id.get_chunk_info(chunk)
        rows = f[name].shape[0]
    at = info.byte_offset + info.size // 2
    with path.open("r+b") as fh:
        fh.seek(at)
        byte = fh.read(1)
        fh.seek(at)
        fh.write(bytes([byte[0] ^ 0xFF]))
    with h5py.File(path, "r", swmr=True) as f, pytest.raises(OSError, match="filter returned failure"):
        f[name][...]  # the damage is real: HDF5 itself refuses the chunk
    return rows


def _stored(path: Path) -> tuple[int, int]:
    """Rows the datasets hold (the committed ones, and any a kill left uncommitted)."""
    with h5py.File(path, "r", swmr=True) as f:
        return f["current/i_a_A"].shape[0], f["encoder/index"].shape[0]


def test_a_killed_file_with_its_commit_table_unreadable_is_not_rewritten_and_its_samples_are_copied(
        killed: Path, repaired_intact: tuple[int, int], tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "k3f.h5"
    shutil.copyfile(killed, path)
    rows = _flip(path, "flushes")
    before = path.read_bytes()
    run = run_cli(capsys, "check", str(path))
    assert run.code == 1
    assert path.read_bytes() == before  # the original untouched (it was rewritten to 10 767 of 1 064 957 bytes)
    line = f"flushes: rows 0–{rows - 1} unreadable ({DAMAGED_COMMITS})"
    copy_path = tmp_path / "k3f.recovered.h5"
    out = run.out.replace("\n", "")
    assert f"{path}: {line}" in out
    assert (f"{path}: the recorder stopped without finishing the file, and the file is damaged: not rewritten (a "
            "rewrite would lose what cannot be read now)") in out
    copy = load(copy_path)
    assert (f"{path}: intact part copied into {copy_path}: {copy.current.sample_count} current and "
            f"{copy.encoder.index.size} encoder samples, status interrupted") in out
    assert run.err == f"acq: damaged: {path} ({line}) — not modified; its intact part is in {copy_path}\n"
    # the samples come from the datasets themselves: all the undamaged copy's repair keeps (and any the kill left
    # stored beyond the last commit)
    current, encoder = repaired_intact
    assert copy.status == "interrupted" and copy.damage == ()
    assert current >= RATE_HZ
    stored = _stored(path)
    assert current <= copy.current.sample_count <= stored[0] and encoder <= copy.encoder.index.size <= stored[1]
    if stored == (current, encoder):  # nothing stored uncommitted (the usual kill, between commits): exactly those
        assert (copy.current.sample_count, copy.encoder.index.size) == (current, encoder)
    np.testing.assert_array_equal(copy.current.sample_index(), np.arange(copy.current.sample_count))
    np.testing.assert_array_equal(np.diff(copy.encoder.index), 1)
    assert copy.meta.stop_reason.startswith(f"recovered from a damaged file ({line}): ")
    again = run_cli(capsys, "check", "--repair", str(path))  # --repair: the same, the original still untouched
    assert again.code == 1 and path.read_bytes() == before


def test_a_killed_file_with_its_block_host_stamps_unreadable_keeps_its_current_stamped_by_its_commits(
        killed: Path, repaired_intact: tuple[int, int], tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Block-table chunk 0 of host_ns holds every read of this short recording. Before: no current sample was kept
    ("current: samples 0–25 599 unreadable", the copy "0 current and 1120 encoder samples"), though each sample's place
    on the DAQ's own clock (count, first_index) was intact: a host stamp only relates that clock to the encoder's. Now
    every sample is kept, each read stamped by the commit that stored it (its /flushes row: true as "had arrived by
    then"), the session read with host_clock_shared false (no prior for the clock search), and acq check says so."""
    from acq.recording.reader import STAMPS_FROM_COMMITS

    path = tmp_path / "host.h5"
    shutil.copyfile(killed, path)
    blocks = _flip(path, "current/blocks/host_ns")
    before = path.read_bytes()
    current, encoder = repaired_intact
    with h5py.File(path, "r", swmr=True) as f:
        assert f["current/blocks/host_ns"].chunks[0] >= blocks  # one chunk: every block row is in it
        commits = f["flushes"][...]
    run = run_cli(capsys, "check", str(path))
    assert run.code == 1
    assert path.read_bytes() == before
    lines = (STAMPS_FROM_COMMITS, f"current/blocks/host_ns: rows 0–{blocks - 1} unreadable")
    out = run.out.replace("\n", "")
    assert all(f"{path}: {line}" in out for line in lines)
    copy_path = tmp_path / "host.recovered.h5"
    assert f"{path}: intact part copied into {copy_path}: {current} current and {encoder} encoder samples" in out
    assert run.err == f"acq: damaged: {path} ({'; '.join(lines)}) — not modified; its intact part is in {copy_path}\n"
    intact, copy = load(killed), load(copy_path)
    assert (copy.current.sample_count, copy.encoder.index.size, copy.damage) == (current, encoder, ())
    np.testing.assert_array_equal(copy.current.phases_a["i_a"], intact.current.phases_a["i_a"][:current])
    np.testing.assert_array_equal(copy.current.block_first_index, intact.current.block_first_index[:blocks])
    committing = np.searchsorted(commits["current_blocks"], np.arange(blocks), side="right")  # each read's commit
    np.testing.assert_array_equal(copy.current.block_host_ns, commits["host_ns"][committing])
    assert np.all(copy.current.block_host_ns >= intact.current.block_host_ns[:blocks])  # arrived before its commit
    assert (copy.meta.host_clock_shared, load(path).meta.host_clock_shared) == (False, False)
    with h5py.File(copy_path, "r") as f:  # as any HDF5 reader reads the copy
        assert (f["current/i_a_A"].shape[0], bool(f.attrs["host_clock_shared"])) == (current, False)


@pytest.fixture(scope="module")
def complete(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return record_session_in_subprocess(tmp_path_factory.mktemp("complete"), 2.0)


def test_a_complete_file_with_its_commit_table_unreadable_is_damaged_not_verified(
        complete: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The footer's counts still say what was committed: every sample is kept, the table's damage named, exit 1."""
    path = tmp_path / "cf.h5"
    shutil.copyfile(complete, path)
    intact = load(complete)
    rows = _flip(path, "flushes")
    before = path.read_bytes()
    line = f"flushes: {'row 0' if rows == 1 else f'rows 0–{rows - 1}'} unreadable"
    run = run_cli(capsys, "check", str(path))
    assert run.code == 1
    assert f"{path}: {line}\n" in run.out and "checksums and counts verified" not in run.out
    assert run.err == (f"acq: damaged: {path} ({line}) — the intact part holds {2 * RATE_HZ} current and 2000 encoder "
                       f"samples (acq analyze --partial uses it; acq check --repair copies it into "
                       f"{tmp_path / 'cf.recovered.h5'})\n")
    repaired = run_cli(capsys, "check", "--repair", str(path))
    assert repaired.code == 1 and path.read_bytes() == before
    copy = load(tmp_path / "cf.recovered.h5")
    assert (copy.current.sample_count, copy.encoder.index.size) == (2 * RATE_HZ, 2000) and copy.damage == ()
    np.testing.assert_array_equal(copy.current.phases_a["i_a"], intact.current.phases_a["i_a"])
    np.testing.assert_array_equal(copy.encoder.position_counts, intact.encoder.position_counts)


@pytest.fixture(scope="module")
def partial_chunks(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """2.2 s: about 22 reads of 2 560 samples (block-table chunks of 256 rows) and 2 200 encoder rows (chunks of
    500), so the last chunk of each holds rows never written."""
    return record_session_in_subprocess(tmp_path_factory.mktemp("partial"), 2.2)


def test_without_its_commits_a_file_extended_over_unwritten_rows_keeps_only_stamped_rows(
        partial_chunks: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """As a kill can leave it: the datasets extended over rows of their last chunk, already on disk, that were never
    written there (zeros that pass the checksum), no footer, /flushes unreadable. Rows with a host stamp of 0 are not
    read as samples (before: 300 encoder rows of zeros, cycle 0 at host time 0, kept; 8 reads of 0 samples)."""
    path = tmp_path / "extended.h5"
    shutil.copyfile(partial_chunks, path)
    intact = load(partial_chunks)
    blocks, encoder = intact.current.block_count.size, intact.encoder.index.size
    assert blocks < 256 and encoder % 500 and intact.current.sample_count == blocks * 2560
    extended = encoder + 500 - encoder % 500  # the last chunk's end
    with h5py.File(path, "r+") as f:
        for name in ("current_samples", "encoder_samples"):
            f.attrs.modify(name, np.int64(-1))  # the footer never written
        f.attrs.modify("status", "recording")
        for name in ("count", "first_index", "host_ns"):
            f[f"current/blocks/{name}"].resize((blocks + 8,))
        for name in f["encoder"]:
            f[f"encoder/{name}"].resize((extended,))
    with h5py.File(path, "r") as f:
        assert not f["encoder/host_ns"][encoder:].any()
        assert f["encoder/host_ns"].id.get_num_chunks() == extended // 500  # the zeros lie in a chunk on disk
    rows = _flip(path, "flushes")
    s = load(path)
    assert s.damage == (f"flushes: {'row 0' if rows == 1 else f'rows 0–{rows - 1}'} unreadable ({DAMAGED_COMMITS})",)
    assert (s.current.block_count.size, s.current.sample_count, s.encoder.index.size) == (blocks, blocks * 2560,
                                                                                          encoder)
    np.testing.assert_array_equal(s.encoder.host_ns, intact.encoder.host_ns)
    np.testing.assert_array_equal(s.current.block_host_ns, intact.current.block_host_ns)
    run = run_cli(capsys, "check", str(path))
    assert run.code == 1
    copy = load(tmp_path / "extended.recovered.h5")
    assert (copy.current.sample_count, copy.encoder.index.size) == (blocks * 2560, encoder)


def test_a_copy_whose_current_host_stamps_were_all_lost_is_analysed_from_the_data_alone(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The copy acq check makes of a 10 s recording whose every current host stamp is lost (each chunk of
    current/blocks/host_ns flipped) holds every current sample (before: none, and its analysis failed) and identifies
    the joint, its clocks related from the data alone (the stamps its reads got from their commits are no prior)."""
    path = record_session_in_subprocess(tmp_path / "rec", 10.0)
    with h5py.File(path, "r") as f:
        chunks = f["current/blocks/host_ns"].id.get_num_chunks()
    for chunk in range(chunks):
        _flip(path, "current/blocks/host_ns", chunk)
    run = run_cli(capsys, "check", "--repair", str(path))
    copy = path.with_name(f"{path.stem}.recovered.h5")
    assert run.code == 1 and run.err.endswith(f"its intact part is in {copy}\n"), run.err
    assert load(copy).current.sample_count == 10 * RATE_HZ
    analysed = run_cli(capsys, "analyze", str(copy), "--json", "--no-report")
    assert analysed.code == 0, analysed.err
    doc = json.loads(analysed.out)
    truth = doc["simulated_truth"]
    assert doc["quality"]["verdict"] == "ok"
    assert doc["K_Nm_per_rad"] == pytest.approx(truth["K_Nm_per_rad"], rel=0.01)
    assert doc["clock"]["offset_s"] == pytest.approx(truth["offset_s"], abs=50e-6)
    assert "note: clock: the streams' time stamps are not on one host clock; aligned from the data alone" in \
        doc["quality"]["reasons"]
