"""A chunk the storage replaced by zeros (its samples and its checksum: Fletcher32 of zeros is 0, so it passes) is a
hole where its rows cannot be real, named "zeroed on disk"; a real chunk of zeros, stored byte for byte the same, is
kept (the rule: :mod:`acq.recording.zeroed`)."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

import h5py
import numpy as np
import pytest

from acq.config import load_bench, load_profile
from acq.recording.reader import load
from acq.recording.session import Session
from acq.recording.writer import SessionWriter
from acq.recording.zeroed import invented
from drivers.base import CurrentSourceInfo, DriveInfo, EncoderBlock
from tests.helpers import (footer_strings_past, record_session_in_subprocess, rewritten_as_older_acq,
                           rewritten_in_real_time, run_cli)

RATE_HZ = 25600
ENCODER_HZ = 1000
SECONDS = 30  # 300 DAQ reads: two chunks of the block table (256 rows, then 44)
TOTAL = SECONDS * RATE_HZ


@pytest.fixture(scope="module")
def fast(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A --fast simulated session of the three phases (dither seed 0), written by the real recorder in a child
    process. It commits at 2 MiB or at the 0.5 s clock, whichever the machine's load lets come first, so where its
    chunks, chunk indexes and footer strings lie differs from run to run."""
    return record_session_in_subprocess(tmp_path_factory.mktemp("rec3") / "out", SECONDS, ("i_a", "i_b", "i_c"))


@pytest.fixture(scope="module")
def recorded(fast: Path) -> Path:
    """:func:`fast` written again committed every 0.5 s of data as a real-time recording commits
    (:func:`rewritten_in_real_time`): its layout is the same in every run, whatever the machine's load."""
    return rewritten_in_real_time(fast, fast.with_name("session.h5"))


@pytest.fixture(scope="module")
def coarse(fast: Path) -> Path:
    """:func:`fast` written again committed every 1 s of data, as a recorder whose commits come at its byte limit
    rather than its clock (as a --fast one's mostly do): its chunks lie otherwise than :func:`recorded`'s."""
    return rewritten_in_real_time(fast, fast.with_name("coarse.h5"), commit_every_s=1.0)


@pytest.fixture(scope="module")
def older(fast: Path) -> Path:
    """:func:`recorded` as an older acq wrote it: its footer strings variable-length, which HDF5 puts at the file's
    end (:func:`rewritten_as_older_acq`)."""
    return rewritten_as_older_acq(fast, fast.with_name("older.h5"))


@pytest.fixture(scope="module")
def intact(recorded: Path) -> Session:
    s = load(recorded)
    assert s.damage == () and s.current.sample_count == TOTAL and s.encoder.index.size == SECONDS * ENCODER_HZ
    return s


def _zeroed(src: Path, dst: Path, *chunks: tuple[str, int]) -> Path:
    """A copy of ``src`` whose (dataset, chunk number) ``chunks`` are zero bytes, data and checksum, as storage that
    lost them leaves them (found by HDF5's chunk index: ``get_chunk_info_by_coord``)."""
    shutil.copyfile(src, dst)
    for name, number in chunks:
        with h5py.File(dst, "r") as f:
            info = f[name].id.get_chunk_info_by_coord((number * f[name].chunks[0],))
        with dst.open("r+b") as fh:
            fh.seek(info.byte_offset)
            fh.write(bytes(info.size))
        with h5py.File(dst, "r") as f:  # what the finding was: the zeroed chunk passes its checksum, reads as zeros
            ds = f[name]
            assert not np.any(ds[number * ds.chunks[0]:(number + 1) * ds.chunks[0]].view(np.uint8))
    return dst


def _keep(rows: int, *lost: tuple[int, int]) -> np.ndarray:
    keep = np.ones(rows, dtype=bool)
    for a, b in lost:
        keep[a:b] = False
    return keep


def _assert_kept(s: Session, intact: Session, current: np.ndarray, encoder: np.ndarray) -> None:
    """``s`` holds exactly the samples of ``intact`` in the masks, every column, with their DAQ index and cycle."""
    assert np.array_equal(s.current.sample_index(), np.flatnonzero(current))  # the recorder had no gap: index = row
    for phase in ("i_a", "i_b", "i_c"):
        assert np.array_equal(s.current.phases_a[phase], intact.current.phases_a[phase][current]), phase
    for name in ("index", "position_counts", "host_ns", "drive_time_s", "velocity_demand_counts_per_s"):
        assert np.array_equal(getattr(s.encoder, name), getattr(intact.encoder, name)[encoder]), name


def test_a_zeroed_chunk_of_one_phase_is_a_hole_in_every_phase(recorded: Path, intact: Session, tmp_path: Path,
                                                              capsys: pytest.CaptureFixture[str]) -> None:
    """Before: read as 2 560 samples of exactly 0 A in i_b, damage ()."""
    path = _zeroed(recorded, tmp_path / "z.h5", ("current/i_b_A", 100))
    s = load(path)
    span = "current: samples 256 000–258 559 zeroed on disk"
    assert s.damage == (span,)
    _assert_kept(s, intact, _keep(TOTAL, (256000, 258560)), _keep(SECONDS * ENCODER_HZ))
    run = run_cli(capsys, "check", str(path))
    assert run.code == 1
    assert f"{path}: {span}\n" in run.out
    assert run.err == (f"acq: damaged: {path} ({span}) — the intact part holds {TOTAL - 2560} current and 30000 "
                       f"encoder samples, {TOTAL - 258560} and 30000 of them after the first damaged span (acq analyze "
                       f"--partial uses it; acq check --repair copies it into {tmp_path / 'z.recovered.h5'})\n")


@pytest.mark.parametrize("column", ["index", "host_ns", "position_counts", "drive_time_s"])
def test_a_zeroed_chunk_of_one_encoder_column_is_a_hole_in_every_column(recorded: Path, intact: Session,
                                                                        tmp_path: Path, column: str) -> None:
    """The cycle index and the host stamps are never zero twice; the position and the drive's time are not 0 next to
    the chunk (rows 14 999 and 15 500), so 500 exact zeros between cannot be the joint resting at count 0."""
    if column in ("position_counts", "drive_time_s"):
        values = getattr(intact.encoder, column)
        assert values[14999] != 0 and values[15500] != 0
    s = load(_zeroed(recorded, tmp_path / "z.h5", (f"encoder/{column}", 30)))
    assert s.damage == ("encoder: samples 15 000–15 499 zeroed on disk",)
    _assert_kept(s, intact, _keep(TOTAL), _keep(SECONDS * ENCODER_HZ, (15000, 15500)))
    assert s.encoder.index[15000] - s.encoder.index[14999] == 501  # the loss is a jump in the drive cycle: a gap


@pytest.mark.parametrize("column", ["count", "first_index"])
def test_a_zeroed_chunk_of_the_block_table_costs_its_reads(recorded: Path, intact: Session, tmp_path: Path,
                                                           column: str) -> None:
    """Block-table rows 0–255 zeroed: the samples of those reads (0–655 359) cannot be placed; the 44 reads after
    them can, counted back from the committed total (a zeroed ``count`` read as 0 samples per read would have
    placed every later read's samples at the file's first rows)."""
    s = load(_zeroed(recorded, tmp_path / "z.h5", (f"current/blocks/{column}", 0)))
    assert s.damage == (f"current/blocks/{column}: rows 0–255 zeroed on disk",
                        "current: samples 0–655 359 zeroed on disk")
    _assert_kept(s, intact, _keep(TOTAL, (0, 655360)), _keep(SECONDS * ENCODER_HZ))
    assert np.array_equal(s.current.block_host_ns, intact.current.block_host_ns[256:])


def test_reads_whose_host_stamps_are_zeroed_join_the_next_read(recorded: Path, intact: Session,
                                                               tmp_path: Path) -> None:
    """Host stamps 0–255 zeroed, the counts and DAQ indices read: the 256 reads join read 256 into one block stamped
    when it returned; every sample kept (before: samples 0–655 359 lost)."""
    s = load(_zeroed(recorded, tmp_path / "z.h5", ("current/blocks/host_ns", 0)))
    assert s.damage == ("current/blocks/host_ns: rows 0–255 zeroed on disk",)
    _assert_kept(s, intact, _keep(TOTAL), _keep(SECONDS * ENCODER_HZ))
    assert (s.current.block_first_index[0], s.current.block_count[0]) == (0, 257 * 2560)
    assert np.array_equal(s.current.block_host_ns, intact.current.block_host_ns[256:])


def _chunks_in(path: Path, start: int, stop: int) -> dict[str, tuple[list[tuple[int, int]], list[tuple[int, int]]]]:
    """Of each dataset, the row spans of its chunks lying wholly in bytes ``[start, stop)`` and of those partly."""
    found: dict[str, tuple[list[tuple[int, int]], list[tuple[int, int]]]] = {}
    with h5py.File(path, "r") as f:
        names: list[str] = []
        f.visititems(lambda name, obj: names.append(name) if isinstance(obj, h5py.Dataset) else None)
        for name in names:
            ds, whole, part = f[name], [], []
            for k in range(ds.id.get_num_chunks()):
                info = ds.id.get_chunk_info(k)
                a, b = info.byte_offset, info.byte_offset + info.size
                rows = (info.chunk_offset[0], min(info.chunk_offset[0] + ds.chunks[0], ds.shape[0]))
                if start <= a and b <= stop:
                    whole.append(rows)
                elif a < stop and start < b:
                    part.append(rows)
            found[name] = (whole, part)
    return found


def _lines(stream: str, rows: int, zeroed: list[tuple[int, int]], bad: list[tuple[int, int]]) -> list[str]:
    """The damage lines of ``stream`` whose chunks of ``zeroed`` and ``bad`` (checksum failed) rows are lost."""
    lost, broken = ~_keep(rows, *zeroed, *bad), ~_keep(rows, *bad)
    lines = []
    for mask, what in ((broken, "unreadable"), (lost & ~broken, "zeroed on disk")):
        edges = np.flatnonzero(np.diff(np.concatenate(([0], mask.astype(np.int8), [0]))))
        lines += [(a, f"{stream}: samples {a:,}–{b - 1:,} {what}".replace(",", " ")) for a, b in edges.reshape(-1, 2)]
    return [line for _, line in sorted(lines)]


def _encoder_run(path: Path, row: int) -> tuple[int, int]:
    """Bytes ``[start, stop)`` of the run of encoder chunks (every column's, one commit's) that holds ``row``: the
    writer puts them between the phase chunks of two commits."""
    with h5py.File(path, "r") as f:
        names = [f"encoder/{name}" for name in f["encoder"]] + [f"current/{name}" for name in f["current"]
                                                               if name.endswith("_A")]
        chunks = sorted((info.byte_offset, info.size, name) for name in names
                        for info in (f[name].id.get_chunk_info(k) for k in range(f[name].id.get_num_chunks())))
        here = f["encoder/position_counts"].id.get_chunk_info_by_coord((row - row % 500,)).byte_offset
    at = [offset for offset, _, _ in chunks].index(here)
    first = last = at
    while first > 0 and chunks[first - 1][2].startswith("encoder/"):
        first -= 1
    while last + 1 < len(chunks) and chunks[last + 1][2].startswith("encoder/"):
        last += 1
    return chunks[first][0], chunks[last][0] + chunks[last][1]


def test_a_zeroed_region_of_the_file_loses_the_chunks_in_it_in_every_stream(
        recorded: Path, intact: Session, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """4 KiB blocks zeroed, whatever lies there, as a file system leaves them after a crash: from 60 000 bytes before
    the encoder chunks of the commit holding cycle 20 000 to 30 000 bytes after them (the last phase chunks of one
    commit, one commit's encoder chunks in every column, the first phase chunks of the next). The chunks wholly inside
    are zeroed (they pass their checksums), the two cut by the region's ends fail theirs. Before: the rows of the
    zeroed chunks read as samples of 0, damage ().

    Cycle 20 000, not the middle (15 000): --partial analyses each stream's longest intact stretch, and with a hole
    in the middle of both those may lie on either side of it and not overlap in time."""
    run_start, run_stop = _encoder_run(recorded, 20000)
    start, stop = (run_start - 60000) // 4096 * 4096, -(-(run_stop + 30000) // 4096) * 4096
    path = tmp_path / "region.h5"
    shutil.copyfile(recorded, path)
    chunks = _chunks_in(path, start, stop)
    with path.open("r+b") as fh:
        fh.seek(start)
        fh.write(bytes(stop - start))
    phases = [chunks[f"current/{p}_A"] for p in ("i_a", "i_b", "i_c")]
    encoder = [chunks[f"encoder/{c}"] for c in ("index", "position_counts", "host_ns", "drive_time_s",
                                                "velocity_demand_counts_per_s")]
    assert all(chunks[f"current/blocks/{c}"] == ([], []) for c in ("count", "first_index", "host_ns"))
    first, end = encoder[0][0][0][0], encoder[0][0][-1][1]
    assert first <= 20000 < end and all(whole == encoder[0][0] and part == [] for whole, part in encoder)
    assert sum(len(whole) for whole, _ in phases) >= 3 and sum(len(part) for _, part in phases) == 2
    expected = (_lines("current", TOTAL, [r for whole, _ in phases for r in whole], [r for _, p in phases for r in p])
                + [f"encoder: samples {first:,}–{end - 1:,} zeroed on disk".replace(",", " ")])
    s = load(path)
    assert list(s.damage) == expected and len(expected) == 4 and expected[1].endswith(" zeroed on disk")
    current = _keep(TOTAL, *(r for whole, part in phases for r in (*whole, *part)))
    _assert_kept(s, intact, current, _keep(SECONDS * ENCODER_HZ, (first, end)))
    run = run_cli(capsys, "analyze", str(path), "--partial", "--no-report", "--json")
    assert run.code == 0, run.err
    doc = json.loads(run.out)
    low, high = doc["ci95"]["K_Nm_per_rad"]
    assert doc["partial"] is True and doc["quality"]["verdict"] == "ok"
    assert low <= 891.0 <= high and abs(doc["K_Nm_per_rad"] - 891.0) < 0.01 * 891.0


def _rest_at_zero_session(path: Path) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray]]:
    """3 s written by the session writer as the recorder writes it (a block every 0.1 s, a flush every 0.5 s): phase
    i_c reads exactly 0.0 throughout (a channel that reads exact zeros), i_a and i_b a noisy sine; the joint moves,
    then rests exactly at count 0 for rows 900–2 099 (position and speed 0), then moves on. Returns what was written:
    the phases and the encoder columns."""
    rng = np.random.default_rng(1)
    t = np.arange(3 * RATE_HZ) / RATE_HZ
    phases = {"i_a": np.sin(2 * np.pi * 7 * t) + rng.normal(0, 0.01, t.size),
              "i_b": np.cos(2 * np.pi * 7 * t) + rng.normal(0, 0.01, t.size), "i_c": np.zeros(t.size)}
    cycle = np.arange(3 * ENCODER_HZ, dtype=np.int64)
    position = np.where(cycle < 900, 900 - cycle, np.where(cycle < 2100, 0, 2099 - cycle)) * 40
    encoder = {"index": cycle + 17, "position_counts": position, "host_ns": 10**12 + cycle * 10**6,
               "drive_time_s": cycle * 1e-3 + 5.0, "velocity_counts_per_s": np.gradient(position * 1e3)}
    w = SessionWriter(path, bench=load_bench(), profile=load_profile("triangle_0.2s"),
                      current_info=CurrentSourceInfo(RATE_HZ, ("i_a", "i_b", "i_c"), "test-daq"),
                      drive_info=DriveInfo(1e-3, 131072, "sim", "drive_cycle", "test-drive"), host_ns_at_start=10**12)
    for k in range(30):
        rows, cycles = slice(k * 2560, (k + 1) * 2560), slice(k * 100, (k + 1) * 100)
        w.append_current_blocks([phases[p][rows] for p in ("i_a", "i_b", "i_c")], np.array([k * 2560]),
                                np.array([2560]), np.array([10**12 + (k + 1) * 10**8]))
        w.append_encoder(EncoderBlock(**{name: values[cycles] for name, values in encoder.items()}))
        if k % 5 == 4:
            w.flush()
    w.finish("complete", "")
    return phases, encoder


def test_real_zeros_are_kept_and_zeroed_chunks_next_to_them_are_not(tmp_path: Path) -> None:
    """A phase reading exact zeros and a joint resting at count 0 are stored as chunks of zero bytes with checksum 0,
    exactly as storage zeroes them; the rows next to them are 0 as well, so they are kept. In the same file a zeroed
    chunk of a phase with a signal, or of the position while the joint moves, is a hole."""
    path = tmp_path / "rest.h5"
    phases, encoder = _rest_at_zero_session(path)
    with h5py.File(path, "r") as f:  # the real zeros' chunks: zero bytes, checksum included
        for name, row in (("current/i_c_A", 25600), ("encoder/position_counts", 1000),
                            ("encoder/velocity_counts_per_s", 1500)):
            assert not any(f[name].id.read_direct_chunk((row,))[1]), name
    s = load(path)
    assert s.damage == ()
    for p, values in phases.items():
        assert np.array_equal(s.current.phases_a[p], values), p
    for name, values in encoder.items():
        assert np.array_equal(getattr(s.encoder, name), values), name
    damaged = load(_zeroed(path, tmp_path / "z.h5", ("current/i_a_A", 10), ("encoder/position_counts", 5),
                           ("current/i_c_A", 20)))
    assert damaged.damage == ("current: samples 25 600–28 159 zeroed on disk",
                              "encoder: samples 2 500–2 999 zeroed on disk")
    keep = _keep(3 * RATE_HZ, (25600, 28160))
    assert np.array_equal(damaged.current.phases_a["i_a"], phases["i_a"][keep])
    assert np.array_equal(damaged.current.phases_a["i_c"], phases["i_c"][keep])
    assert np.array_equal(damaged.encoder.position_counts, encoder["position_counts"][_keep(3000, (2500, 3000))])


def _merged(spans: tuple[tuple[str, int, int], ...]) -> list[tuple[str, int, int]]:
    """``spans`` with the spans of a stream that adjoin joined."""
    merged: list[tuple[str, int, int]] = []
    for stream, a, b in spans:
        if merged and merged[-1][0] == stream and merged[-1][2] == a:
            merged[-1] = (stream, merged[-1][1], b)
        else:
            merged.append((stream, a, b))
    return merged


@pytest.mark.parametrize(("source", "percent"), [("older", 10), ("older", 50), ("recorded", 10), ("coarse", 50)])
def test_a_cut_copy_pre_allocated_to_full_size_keeps_what_a_cut_copy_keeps(
        source: str, percent: int, tmp_path: Path, capsys: pytest.CaptureFixture[str],
        request: pytest.FixtureRequest) -> None:
    """A copier or downloader that pre-allocates the whole file and is cut leaves the rest zero. Where the footer's
    strings lie past the cut (an older acq's variable-length strings, the file committed every 0.5 s: HDF5 puts them
    at its end) they are unreadable, as in a cut copy. Before: refused whole, 'not a readable HDF5 session file (root
    attributes unreadable)'. Now the file's data ends where its zeros begin: the same samples as the copy cut there.
    Where they lie before the cut (acq's fixed-length strings, written in place, whether committed every 0.5 s or 1 s)
    the footer reads and the zeroed chunks are holes: "zeroed on disk" or "unreadable" (those whose chunk index is
    zeroed), the same samples lost as in the cut copy."""
    recorded: Path = request.getfixturevalue(source)
    size = recorded.stat().st_size
    cut_at = size * percent // 100
    zeroed, cut = tmp_path / "zeroed.h5", tmp_path / "cut.h5"
    for path in (zeroed, cut):
        shutil.copyfile(recorded, path)
    with zeroed.open("r+b") as fh:
        fh.seek(cut_at)
        fh.write(bytes(size - cut_at))
    with cut.open("r+b") as fh:
        fh.truncate(cut_at)
    z, c = load(zeroed), load(cut)
    past = footer_strings_past(recorded, cut_at)
    assert past == (["stop_reason", "stopped_utc"] if source == "older" else [])  # the case the test is about
    lost = f", {' and '.join(past)} lost" if past else ""
    assert c.damage[0] == f"file cut: {cut_at:,} of {size:,} bytes".replace(",", " ") + lost
    if past:
        tail = len((recorded.read_bytes()[:cut_at]).rstrip(b"\0"))  # the zeros begin where the kept bytes' zeros do
        assert z.damage == (f"file zeroed from byte {tail:,} to its end ({size:,} bytes)".replace(",", " ") + lost,
                            *c.damage[1:])
    else:
        table = [span for span in z.damage_spans if span[0].startswith("current/blocks/")]  # zeroed table rows, named
        assert _merged(tuple(span for span in z.damage_spans if span not in table)) == list(c.damage_spans)
        assert len(z.damage) == len(z.damage_spans)
        assert all(line.endswith((" zeroed on disk", " unreadable")) for line in z.damage), z.damage
    assert (z.current.sample_count, z.encoder.index.size) == (c.current.sample_count, c.encoder.index.size)
    assert c.current.sample_count >= (percent - 10) / 100 * TOTAL and c.encoder.index.size >= 3000  # a real part
    for phase in ("i_a", "i_b", "i_c"):
        assert np.array_equal(z.current.phases_a[phase], c.current.phases_a[phase])
    assert np.array_equal(z.encoder.position_counts, c.encoder.position_counts)
    run = run_cli(capsys, "check", "--repair", str(zeroed))
    assert run.code == 1  # damaged: the copy holds the intact part only
    assert run.err == (f"acq: damaged: {zeroed} ({'; '.join(z.damage)}) — not modified; its intact part is in "
                       f"{tmp_path / 'zeroed.recovered.h5'}\n")
    copy = load(tmp_path / "zeroed.recovered.h5")
    assert copy.damage == () and (copy.current.sample_count, copy.encoder.index.size) == (c.current.sample_count,
                                                                                          c.encoder.index.size)


def test_a_joint_resting_at_count_0_through_the_first_encoder_chunk_is_intact(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The simulated robot 13 140 s into its program (``acq record --fast``, 10 s): the joint rests at count 0 (a drive
    zeroes its position at enable or homing) for rows 0–499, the whole first encoder chunk, stored as zero bytes with
    checksum 0, and moves from row 500 (9 counts). Before: "damaged (encoder: samples 0–499 zeroed on disk)", the
    analysis refused, a monitor window counted failed. The step 0 → 9 is no larger than the position's other steps,
    so the chunk is kept; a zeroed chunk of the moving joint in the same file (rows 1 000–1 499, −27 426 counts
    before it) is still a hole."""
    bench = (Path(__file__).parents[1] / "configs/benches/sim_robot.toml").read_text()
    assert "\n[sim]\n" in bench
    bench_path = tmp_path / "robot.toml"
    bench_path.write_text(bench.replace("\n[sim]\n", "\n[sim]\nelapsed_s = 13140.0\n"))
    proc = subprocess.run([sys.executable, "-m", "acq", "record", "--bench", str(bench_path), "--duration", "10",
                           "--fast", "--no-analyze", "--out", str(tmp_path / "out")],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    (path,) = (tmp_path / "out").glob("*.h5")
    with h5py.File(path, "r") as f:  # the case the test is about
        ds = f["encoder/position_counts"]
        assert ds.chunks == (500,) and not any(ds.id.read_direct_chunk((0,))[1])
        assert ds[495:505].tolist() == [0, 0, 0, 0, 0, 9, 26, 47, 66, 84]
    s = load(path)
    assert s.damage == () and s.encoder.index.size == 10000
    run = run_cli(capsys, "analyze", str(path), "--no-report", "--json")
    assert run.code == 0, run.err
    doc = json.loads(run.out)
    assert doc["partial"] is False and doc["quality"]["verdict"] == "ok"
    assert abs(doc["K_Nm_per_rad"] - 891.0) < 0.01 * 891.0
    damaged = load(_zeroed(path, tmp_path / "z.h5", ("encoder/position_counts", 2)))
    assert damaged.damage == ("encoder: samples 1 000–1 499 zeroed on disk",)


def test_a_zeroed_chunk_of_a_joint_resting_near_count_0_is_a_hole(tmp_path: Path) -> None:
    """The simulated robot as shipped (``acq record --fast``, 10 s): the joint rests at 361–364 counts through rows
    2 500–2 999 while a move elsewhere steps 1 762 counts. Zeroed, that chunk was taken for a joint at rest at 0 by the
    record's largest step (session 13's reviewer); by the pace beside it (steps of a few counts) 362 is a jump."""
    proc = subprocess.run([sys.executable, "-m", "acq", "record", "--bench", "sim_robot", "--duration", "10", "--fast",
                           "--no-analyze", "--out", str(tmp_path / "out")], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    (path,) = (tmp_path / "out").glob("*.h5")
    with h5py.File(path, "r") as f:  # the case the test is about
        rest = f["encoder/position_counts"][2500:3000]
        assert 0 < rest.min() and rest.max() < 1000 and np.ptp(rest) <= 10, (rest.min(), rest.max())
    damaged = load(_zeroed(path, tmp_path / "z.h5", ("encoder/position_counts", 5)))
    assert damaged.damage == ("encoder: samples 2 500–2 999 zeroed on disk",)


def test_a_phase_logged_as_exact_zeros_past_its_chunks_is_kept() -> None:
    """A drive disabled for the first 2.2 s of an import, its current logged as 0.000 (25.6 kS/s, chunks of 25 600
    rows): the two zero chunks and the zeros after them are the reading, not storage (the zeros go on past the chunks,
    which storage does not do); before, a run longer than any still stretch left outside it was called invented."""
    rng = np.random.default_rng(0)
    values = np.round(rng.normal(0.0, 0.5, 256_000), 3)
    values[:56_320] = 0.0
    assert invented("current/i_a_A", values, [(0, 25_600), (25_600, 51_200)], ()) == ()
    values[51_200:56_320] = rng.normal(0.0, 0.5, 5_120)  # the same chunks with the reading going on beside them
    assert invented("current/i_a_A", values, [(0, 25_600), (25_600, 51_200)], ()) == ((0, 51_200),)
