"""A damaged chunk in the middle of a stream costs that chunk only: the rows after it are kept, the loss is a gap."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import h5py
import numpy as np
import pytest

from acq.recording.holes import Column, current_rows
from acq.recording.reader import load
from acq.recording.session import Session
from tests.helpers import record_session_in_subprocess, run_cli

RATE_HZ = 25600
SECONDS = 52  # 520 DAQ reads: three chunks of the block table (256 rows each), the middle one whole
TOTAL = SECONDS * RATE_HZ


@pytest.fixture(scope="module")
def recorded(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A --fast simulated session of the three phases, written by the real recorder in a child process."""
    return record_session_in_subprocess(tmp_path_factory.mktemp("rec3") / "out", SECONDS, ("i_a", "i_b", "i_c"))


@pytest.fixture(scope="module")
def intact(recorded: Path) -> Session:
    s = load(recorded)
    assert s.damage == () and s.current.sample_count == TOTAL and s.encoder.index.size == SECONDS * 1000
    return s


def _damaged(recorded: Path, tmp_path: Path, *chunks: tuple[str, int]) -> Path:
    """A copy of ``recorded`` with one bit flipped inside each (dataset, chunk number) of ``chunks``."""
    path = tmp_path / "damaged.h5"
    shutil.copyfile(recorded, path)
    for name, number in chunks:
        with h5py.File(path, "r") as f:
            info = f[name].id.get_chunk_info_by_coord((number * f[name].chunks[0],))
        with path.open("r+b") as fh:
            fh.seek(info.byte_offset + 100)
            byte = fh.read(1)
            fh.seek(info.byte_offset + 100)
            fh.write(bytes([byte[0] ^ 0x40]))
    return path


def _assert_current_kept_as_in(s: Session, intact: Session, lost: list[tuple[int, int]]) -> None:
    """Every current sample but those of ``lost`` kept, in every phase, with its DAQ index; the block table true."""
    keep = np.ones(TOTAL, dtype=bool)
    for a, b in lost:
        keep[a:b] = False
    index = s.current.sample_index()
    assert np.array_equal(index, np.flatnonzero(keep))  # the recorder had no gap: DAQ index = row
    for phase in ("i_a", "i_b", "i_c"):
        assert np.array_equal(s.current.phases_a[phase], intact.current.phases_a[phase][keep])
    assert s.current.block_count.sum() == keep.sum()
    ends = s.current.block_first_index + s.current.block_count  # every block of the intact table, or a piece of it
    row = np.searchsorted(intact.current.block_first_index, s.current.block_first_index, side="right") - 1
    assert np.all(ends <= intact.current.block_first_index[row] + intact.current.block_count[row])
    assert np.array_equal(s.current.block_host_ns, intact.current.block_host_ns[row])


def test_a_middle_chunk_of_one_phase_costs_that_chunk_in_every_phase(recorded: Path, intact: Session,
                                                                     tmp_path: Path) -> None:
    s = load(_damaged(recorded, tmp_path, ("current/i_b_A", 100)))
    assert s.damage == ("current: samples 256 000–258 559 unreadable",)
    assert s.current.sample_count == 256000 + (TOTAL - 258560) == TOTAL - 2560
    _assert_current_kept_as_in(s, intact, [(256000, 258560)])
    assert s.encoder.index.size == SECONDS * 1000


def test_two_holes_are_two_spans_and_everything_between_and_after_is_kept(recorded: Path, intact: Session,
                                                                          tmp_path: Path) -> None:
    s = load(_damaged(recorded, tmp_path, ("current/i_a_A", 100), ("current/i_c_A", 300)))
    assert s.damage == ("current: samples 256 000–258 559 unreadable",
                        "current: samples 768 000–770 559 unreadable")
    assert s.current.sample_count == TOTAL - 2 * 2560
    _assert_current_kept_as_in(s, intact, [(256000, 258560), (768000, 770560)])


@pytest.mark.parametrize("column", ["count", "first_index"])
def test_a_middle_chunk_of_the_block_table_costs_its_reads_only(recorded: Path, intact: Session, tmp_path: Path,
                                                               column: str, capsys: pytest.CaptureFixture[str]
                                                               ) -> None:
    """Block-table rows 256–511 lost: their reads' samples (655 360–1 310 719) cannot be placed; the 8 reads after
    them can (from the committed total when the counts are what was lost)."""
    path = _damaged(recorded, tmp_path, (f"current/blocks/{column}", 1))
    s = load(path)
    span = f"current/blocks/{column}: rows 256–511 unreadable; current: samples 655 360–1 310 719 unreadable"
    assert s.damage == tuple(span.split("; "))  # the dataset's rows, and the samples they placed
    assert s.current.sample_count == TOTAL - 256 * 2560 == 655360 + 20480
    _assert_current_kept_as_in(s, intact, [(655360, 1310720)])
    run = run_cli(capsys, "check", str(path))
    assert run.code == 1
    assert "".join(f"{path}: {line}\n" for line in s.damage) in run.out
    assert run.err == (f"acq: damaged: {path} ({span}) — the intact part holds 675840 current and 52000 encoder "
                       "samples, 20480 and 52000 of them after the first damaged span (acq analyze --partial uses "
                       f"it; acq check --repair copies it into {tmp_path / 'damaged.recovered.h5'})\n")


def test_reads_whose_host_stamps_are_lost_join_the_next_read_and_keep_their_samples(
        recorded: Path, intact: Session, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Block-table host stamps 256–511 lost, their counts and DAQ indices read: the 256 reads join read 512 into one
    block stamped when read 512 returned (its samples had all arrived then; the stamp stays paired with the block's
    last sample). Before: samples 655 360–1 310 719 lost (675 840 of 1 331 200 kept)."""
    path = _damaged(recorded, tmp_path, ("current/blocks/host_ns", 1))
    s = load(path)
    assert s.damage == ("current/blocks/host_ns: rows 256–511 unreadable",)
    assert s.current.sample_count == TOTAL
    np.testing.assert_array_equal(s.current.sample_index(), np.arange(TOTAL))
    for phase in ("i_a", "i_b", "i_c"):
        np.testing.assert_array_equal(s.current.phases_a[phase], intact.current.phases_a[phase])
    assert s.current.block_count.size == intact.current.block_count.size - 256
    joined = 256  # the block that starts at read 256 and ends with read 512
    assert (s.current.block_first_index[joined], s.current.block_count[joined]) == (256 * 2560, 257 * 2560)
    assert s.current.block_host_ns[joined] == intact.current.block_host_ns[512]
    keep = np.ones(intact.current.block_count.size, dtype=bool)
    keep[256:512] = False
    np.testing.assert_array_equal(s.current.block_host_ns, intact.current.block_host_ns[keep])
    run = run_cli(capsys, "check", str(path))
    assert run.code == 1
    assert run.err == (f"acq: damaged: {path} (current/blocks/host_ns: rows 256–511 unreadable) — the intact part "
                       f"holds {TOTAL} current and 52000 encoder samples (acq analyze --partial uses it; acq check "
                       f"--repair copies it into {tmp_path / 'damaged.recovered.h5'})\n")


def test_a_middle_chunk_of_the_encoder_position_costs_those_rows_in_every_column(recorded: Path, intact: Session,
                                                                                  tmp_path: Path) -> None:
    s = load(_damaged(recorded, tmp_path, ("encoder/position_counts", 30), ("encoder/host_ns", 31)))
    assert s.damage == ("encoder: samples 15 000–15 999 unreadable",)  # adjacent holes of two columns: one span
    keep = np.ones(SECONDS * 1000, dtype=bool)
    keep[15000:16000] = False
    assert s.encoder.index.size == SECONDS * 1000 - 1000
    assert np.array_equal(s.encoder.index, intact.encoder.index[keep])  # a jump in the drive cycle: a gap
    for name in ("position_counts", "host_ns", "drive_time_s"):
        assert np.array_equal(getattr(s.encoder, name), getattr(intact.encoder, name)[keep]), name
    assert s.current.sample_count == TOTAL


def test_a_never_written_tail_still_ends_the_intact_part_after_a_hole(recorded: Path, tmp_path: Path) -> None:
    """A hole, then rows counted but never written (their chunks would read as zeros): the hole is one span, the tail
    another, as before."""
    copy = tmp_path / "tail.h5"
    shutil.copyfile(recorded, copy)
    with h5py.File(copy, "r+") as f:
        for phase in ("i_a", "i_b", "i_c"):
            f[f"current/{phase}_A"].resize((TOTAL + 2 * 2560,))
        f.attrs["current_samples"] = np.int64(TOTAL + 2 * 2560)
    s = load(_damaged(copy, tmp_path, ("current/i_a_A", 100)))
    assert s.damage == ("current: samples 256 000–258 559 unreadable",
                        "current: samples 1 331 200–1 336 319 unreadable")
    assert s.current.sample_count == TOTAL - 2560
    assert not np.any(s.current.phases_a["i_a"] == 0.0)


def test_split_reads_keep_exact_indices_and_their_arrival() -> None:
    """Reads of 1 000 samples, a hole of the phases' chunk (2 560) inside reads 2–4: read 2 and read 4 are cut to
    their intact pieces, each with its exact first index and count and the read's arrival (see
    :func:`acq.recording.holes.current_rows` for why the stamp is kept)."""
    n = np.full(8, 1000, dtype=np.int64)
    first = np.arange(8, dtype=np.int64) * 1000 + np.r_[0, 0, 0, 0, 500, 500, 500, 500]  # a recorder gap before read 4
    host = np.arange(8, dtype=np.int64) * 10 + 7
    phase = Column(np.zeros(8000), None, ((2560, 5120),))
    rows = current_rows(Column(n, None), Column(first, None), Column(host, None), [phase, Column(np.zeros(8000), None)],
                        8000)
    assert rows.sample_keep.sum() == 8000 - 2560
    assert rows.first_index.tolist() == [0, 1000, 2000, 5620, 6500, 7500]
    assert rows.count.tolist() == [1000, 1000, 560, 880, 1000, 1000]
    assert rows.host_ns.tolist() == [7, 17, 27, 57, 67, 77]


@pytest.fixture(scope="module")
def with_gaps(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """10 s on the simulated bench whose drive never delivers 2 frames every 60 cycles: 150 gap events (three chunks
    of /events) and an encoder stream with 150 gaps of its own."""
    folder = tmp_path_factory.mktemp("gaps")
    bench = (Path(__file__).parents[1] / "configs/benches/sim.toml").read_text()
    drops = ", ".join(f"[{60 * k + 30}, 2]" for k in range(150))
    (folder / "drops.toml").write_text(bench.replace("current_noise_A = 0.01",
                                                     f"current_noise_A = 0.01\ndrop_encoder_frames = [{drops}]"))
    proc = subprocess.run([sys.executable, "-m", "acq", "record", "--profile", "triangle_0.2s", "--bench",
                           str(folder / "drops.toml"), "--fast", "--duration", "10", "--no-analyze", "--out",
                           str(folder / "out")], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    (path,) = (folder / "out").glob("*.h5")
    return path


def test_a_middle_chunk_of_events_and_of_an_encoder_with_gaps_costs_those_rows(with_gaps: Path,
                                                                                tmp_path: Path) -> None:
    intact = load(with_gaps)
    assert len(intact.events) == 150 and intact.encoder.index.size == 10000 - 300
    s = load(_damaged(with_gaps, tmp_path, ("events", 1), ("encoder/index", 5)))
    assert s.damage == ("encoder: samples 2 500–2 999 unreadable", "events: samples 64–127 lost")
    assert s.events == intact.events[:64] + intact.events[128:]
    keep = np.ones(intact.encoder.index.size, dtype=bool)
    keep[2500:3000] = False
    assert np.array_equal(s.encoder.index, intact.encoder.index[keep])  # the recorder's gaps and the hole's jump
    assert np.array_equal(s.encoder.position_counts, intact.encoder.position_counts[keep])
    missing = int(np.sum(np.diff(intact.encoder.index[2499:3001]) - 1))  # frames the drive never delivered there
    assert missing == 18 and s.encoder.index[2500] - s.encoder.index[2499] == 1 + 500 + missing
