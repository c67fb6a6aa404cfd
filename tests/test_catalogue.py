"""The catalogue on both back ends — a SQLite file and a real PostgreSQL server (``postgres_server`` in
conftest.py) — with the same schema, migrations, upserts, and many concurrent writers."""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

import acq.monitoring.catalogue_db
from acq.monitoring.catalogue import Catalogue, Outcome
from acq.monitoring.catalogue_schema import MIGRATIONS, SCHEMA_VERSION
from acqcore.errors import ConfigError
from tests.helpers import read_only_view, run_cli
from tests.pg_server import new_database


def _outcome(session_id: str, k: float | None, *, request: str = "r", joint: str = "j1",
             error: str | None = None) -> Outcome:
    doc = None if k is None else {
        "options": {}, "analyzed_utc": "2026-01-02T00:00:00+00:00", "acq_version": "t", "K_Nm_per_rad": k,
        "ci95": {"K_Nm_per_rad": [k - 5.0, k + 5.0]}, "quality": {"verdict": "ok", "reasons": []},
        "antiresonance_hz": 55.0, "resonance_hz": 102.0}
    meta = {"session_id": session_id, "joint": joint, "created_utc": f"2026-01-01T00:00:{session_id[-2:]}+00:00",
            "start_monotonic_ns": 2**62 + 1, "status": "complete", "tags": {"robot": "r1", "payload_kg": 2.5}}
    return Outcome(f"/bench/{session_id}.h5", f"sha-{session_id}", request, meta, doc, error, 1.5)


def test_record_upserts_and_reads_back_the_same_on_both_back_ends(catalogue_location: Path | str) -> None:
    with Catalogue(catalogue_location) as c:
        assert c.schema_version == SCHEMA_VERSION
        c.record(_outcome("s-01", 890.123456789))
        c.record(_outcome("s-02", None, error="s-02.h5: too short"))
        c.record(_outcome("s-01", 880.5))  # same session and request: replaces
        c.record(_outcome("s-01", 870.0, request="other"))  # another request: a second analysis
        c.record(_outcome("s-03", 860.0, joint="j2"))
        entries = c.entries("j1")
        assert sorted(c.joints()) == ["j1", "j2"] and len(c.entries()) == 4
        assert c.current("r") == {"sha-s-01", "sha-s-03"} and c.current("other") == {"sha-s-01"}
    assert [(e.session_id, e.request_key, e.K_Nm_per_rad) for e in entries] == [
        ("s-01", "r", 880.5), ("s-01", "other", 870.0), ("s-02", "r", None)]
    first = entries[0]
    assert first.K_ci95 == (875.5, 885.5) and first.tags == {"robot": "r1", "payload_kg": 2.5}
    assert first.f_a_hz == 55.0 and first.verdict == "ok" and entries[2].error == "s-02.h5: too short"
    with Catalogue(catalogue_location) as c:  # reopened: no migration to run, doubles kept to the last bit
        c.record(_outcome("s-04", 890.123456789))
        assert c.entries("j1")[-1].K_Nm_per_rad == 890.123456789


def test_a_damaged_copy_does_not_hide_the_analysis_of_an_intact_copy(catalogue_location: Path | str) -> None:
    """Copies of a session share its id: the failure of a damaged copy (another file) leaves the intact copy's
    analysis — and the session's path — in place, in one statement (a separate check before the upsert let two
    PostgreSQL writers both pass it: the review); a failure of the very file (the same path) replaces it."""
    intact = _outcome("s-01", 889.6)
    damaged = Outcome("/bench/copy/s-01.h5", "sha-damaged", "r", intact.session, None,
                      "s-01.h5: damaged: current samples 143 360-255 999 unreadable", 0.1)
    with Catalogue(catalogue_location) as c:
        c.record(intact)
        c.record(damaged)
        assert [(e.path, e.K_Nm_per_rad, e.error) for e in c.entries("j1")] == [("/bench/s-01.h5", 889.6, None)]
        part = {**intact.doc, "K_Nm_per_rad": 880.0, "partial": True}  # acq analyze copy/s-01.h5 --partial
        c.record(Outcome(damaged.path, damaged.sha256, "r", intact.session, part, None, 0.1))
        assert [(e.path, e.K_Nm_per_rad) for e in c.entries("j1")] == [("/bench/s-01.h5", 889.6)]  # the second trial
        # the very file, damaged in place (another hash, the same path): its failure replaces its analysis
        c.record(Outcome(intact.path, "sha-rotten", "r", intact.session, None, "s-01.h5: unreadable", 0.1))
        assert [(e.path, e.K_Nm_per_rad, e.error) for e in c.entries("j1")] == [
            ("/bench/s-01.h5", None, "s-01.h5: unreadable")]
        c.record(damaged)  # a failure replacing a failure: the session row names the file that failed last
        assert [(e.path, e.error) for e in c.entries("j1")] == [("/bench/copy/s-01.h5", damaged.error)]
        # a row filed before schema 5 (no file path): the file hash tells a copy (the second read)
        c.record(intact)
        with c._transaction():
            c._execute("UPDATE analyses SET file_path = NULL")
        c.record(damaged)
        assert [(e.K_Nm_per_rad, e.error) for e in c.entries("j1")] == [(889.6, None)]
        # each analysis is listed with the file it was made of, not the session row's last file (the second read)
        c.record(intact)
        c.record(Outcome(damaged.path, damaged.sha256, "paper", intact.session, {**intact.doc, "K_Nm_per_rad": 1536.0},
                         None, 0.1))
        assert sorted((e.request_key, e.path) for e in c.entries("j1")) == [("paper", "/bench/copy/s-01.h5"),
                                                                            ("r", "/bench/s-01.h5")]


def test_an_older_catalogue_is_migrated_with_its_rows(catalogue_location: Path | str,
                                                      monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(acq.monitoring.catalogue_db, "SCHEMA_VERSION", 1)
    with Catalogue(catalogue_location) as old, old._transaction():
        assert old.schema_version == 1
        old._execute("INSERT INTO sessions (session_key, session_id, path, joint, created_utc) "
                     "VALUES ('s1', 's1', '/a.h5', 'joint1', '2026-01-01T00:00:00+00:00')")
        old._execute("INSERT INTO analyses (session_key, sha256, request_key, analyzed_utc, verdict, K_Nm_per_rad,"
                     " K_lo, K_hi) VALUES ('s1', 'h', '{}', '2026-01-01T00:01:00+00:00', 'ok', 890.0, 880.0, 900.0)")
    monkeypatch.undo()
    with Catalogue(catalogue_location) as catalogue:
        assert catalogue.schema_version == SCHEMA_VERSION == len(MIGRATIONS) > 1
        (entry,) = catalogue.entries("joint1")
    assert entry.K_Nm_per_rad == 890.0 and entry.tags == {} and entry.K_ci95 == (880.0, 900.0)


def test_a_newer_catalogue_is_refused(catalogue_location: Path | str, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(acq.monitoring.catalogue_db, "MIGRATIONS", (*MIGRATIONS, "CREATE TABLE later (x TEXT)"))
    monkeypatch.setattr(acq.monitoring.catalogue_db, "SCHEMA_VERSION", SCHEMA_VERSION + 1)
    Catalogue(catalogue_location).close()
    monkeypatch.undo()
    with pytest.raises(ConfigError) as error:
        Catalogue(catalogue_location)
    assert str(error.value).endswith(f": catalogue schema version {SCHEMA_VERSION + 1} is newer than this acq knows "
                                     f"({SCHEMA_VERSION}) — update acq")


_WRITER = """
import sys, time
from acq.monitoring.catalogue import Catalogue, Outcome
time.sleep(max(0.0, float(sys.argv[3]) - time.time()))  # all open the fresh catalogue together
with Catalogue(sys.argv[1]) as c:
    for i in range(50):
        c.record(Outcome(f"/x/{sys.argv[2]}-{i}.h5", f"h{sys.argv[2]}-{i}", "r",
                         {"session_id": f"{sys.argv[2]}-{i}", "joint": "j"}, None, "synthetic", 0.0))
"""


def test_four_processes_writing_50_sessions_each_at_once_lose_nothing(catalogue_location: Path | str) -> None:
    """All four create and migrate the fresh catalogue at once, then write: 200 rows, none twice, none lost."""
    start = f"{time.time() + 4.0:.3f}"  # after the writers' imports (≈ 1 s, more under load)
    writers = [subprocess.Popen([sys.executable, "-c", _WRITER, str(catalogue_location), f"w{n}", start],
                                stderr=subprocess.PIPE, text=True) for n in range(4)]
    errors = [w.communicate(timeout=120)[1] for w in writers]
    assert [w.returncode for w in writers] == [0] * 4, errors
    with Catalogue(catalogue_location) as c:
        entries = c.entries()
        counts = [c._execute(f"SELECT COUNT(*) FROM {table}").fetchone()[0] for table in ("sessions", "analyses")]
        assert c.schema_version == SCHEMA_VERSION
    assert counts == [200, 200]
    assert sorted(e.session_id for e in entries) == sorted(f"w{n}-{i}" for n in range(4) for i in range(50))


def test_an_unreachable_server_is_one_line(capsys: pytest.CaptureFixture[str]) -> None:
    url = "postgresql://acq:secret@127.0.0.1:1/fleet"  # port 1: nothing listens
    if os.environ.get("CI", "").lower() not in ("true", "1"):
        pytest.importorskip("psycopg")
    run = run_cli(capsys, "trend", "--catalogue", url, "--joint", "j1")
    assert run.code == 2 and run.out == ""
    assert run.err == ("acq: error: postgresql://acq:***@127.0.0.1:1/fleet: cannot open the catalogue (connection failed: "
                       "connection to server at \"127.0.0.1\", port 1 failed: Connection refused)\n")


def _insert_as_an_older_acq(catalogue: Catalogue, tags_by_key: dict[str, str]) -> None:
    """Sessions of joint1 (``session_key``: tags JSON) with an ok analysis, inserted as an acq before schema 6 did:
    without the ``monitor_id`` column."""
    with catalogue._transaction():
        for key, tags in tags_by_key.items():
            catalogue._execute("INSERT INTO sessions (session_key, session_id, path, joint, created_utc, tags_json) "
                               f"VALUES (?, ?, '/{key}.h5', 'joint1', '2026-01-01T00:00:0{key[1]}+00:00', ?)",
                               (key, key, tags))
            catalogue._execute("INSERT INTO analyses (session_key, sha256, request_key, analyzed_utc, verdict) "
                               "VALUES (?, 'h', '{}', '2026-01-01T00:01:00+00:00', 'ok')", (key,))


def test_a_monitors_windows_are_read_by_its_column_and_an_older_catalogue_gets_it_from_the_tags(
        catalogue_location: Path | str, monkeypatch: pytest.MonkeyPatch) -> None:
    """Scoping to one monitor filtered every row of a joint's name in Python (the review): now a query on the
    ``monitor_id`` column (indexed), which a catalogue of schema 5 gets from its rows' tags when it is opened."""
    monkeypatch.setattr(acq.monitoring.catalogue_db, "SCHEMA_VERSION", 5)
    with Catalogue(catalogue_location) as old:
        _insert_as_an_older_acq(old, {"s1": '{"monitor_id": "h:/m1:0000000a"}', "s2": '{"monitor_id": "h:/m2:0000000b"}',
                                      "s3": '{"robot": "r1"}'})
    monkeypatch.undo()
    with Catalogue(catalogue_location) as c:
        c.record(Outcome("/s4.h5", "h4", "{}", {"session_id": "s4", "joint": "joint1",
                                                "created_utc": "2026-01-01T00:00:04+00:00",
                                                "tags": {"monitor_id": "h:/m1:0000000a"}}, None, "failed", 0.1))
        m1 = [e.session_id for e in c.entries("joint1", monitor="h:/m1:0000000a")]
        m1_and_unowned = [e.session_id for e in c.entries("joint1", monitor="h:/m1:0000000a", unowned=True)]
        m2_other_joint = [e.session_id for e in c.entries("joint2", monitor="h:/m2:0000000b")]
        everyone = [e.session_id for e in c.entries("joint1")]
    assert (m1, m1_and_unowned, m2_other_joint, everyone) == (["s1", "s4"], ["s1", "s3", "s4"], [],
                                                              ["s1", "s2", "s3", "s4"])


def test_a_monitors_windows_are_copied_into_another_catalogue_with_their_analyses(
        catalogue_location: Path | str, tmp_path: Path) -> None:
    """``acq monitor --move-catalogue`` (SQLite to PostgreSQL): a monitor's sessions and analyses, nobody else's; its
    windows from before identities filed as its own."""
    source = tmp_path / "old.sqlite"
    with Catalogue(source) as old:
        for sid, tags in (("s-01", {"monitor_id": "m1"}), ("s-02", {"monitor_id": "m2"}), ("s-03", {})):
            outcome = _outcome(sid, 890.0 + int(sid[-1]))
            old.record(Outcome(outcome.path, outcome.sha256, "r", {**outcome.session, "tags": tags}, outcome.doc,
                               None, 1.0))
        with Catalogue(catalogue_location) as new:
            assert new.copy_windows(old, "m1", unowned=True) == 2
            assert new.copy_windows(old, "m1", unowned=True) == 2  # again: the rows it has are kept, none doubled
            rows = [(e.session_id, e.tags, e.K_Nm_per_rad, e.K_ci95, e.path) for e in new.entries(monitor="m1")]
    assert rows == [("s-01", {"monitor_id": "m1"}, 891.0, (886.0, 896.0), "/bench/s-01.h5"),
                    ("s-03", {"monitor_id": "m1"}, 893.0, (888.0, 898.0), "/bench/s-03.h5")]


def test_sessions_an_earlier_acq_files_without_the_monitor_column_get_it_from_their_tags(
        catalogue_location: Path | str) -> None:
    """An acq of before schema 6 still running names only the columns it knows: its windows have the monitor_id tag and
    no monitor_id column, and the scoping query missed them (the third read). fill_monitor_ids fills the column from
    the tags (read in Python: json_extract and ::jsonb reject a NaN tag), and leaves the sessions of no monitor alone.
    Before it is filled the scoping reads such a session by its tag (readers such as acq trend write nothing)."""
    with Catalogue(catalogue_location) as c:
        _insert_as_an_older_acq(c, {"s1": '{"monitor_id": "h:/m1:0000000a", "monitor_window": 0}',
                                    "s2": '{"robot": "r"}', "s3": '{}'})
        before = [e.session_id for e in c.entries("joint1", monitor="h:/m1:0000000a")]
        filled = c.fill_monitor_ids(), c.fill_monitor_ids()
        after = [e.session_id for e in c.entries("joint1", monitor="h:/m1:0000000a")]
        unowned = [e.session_id for e in c.entries("joint1", monitor="none", unowned=True)]
    assert (before, filled, after, unowned) == (["s1"], (1, 0), ["s1"], ["s2", "s3"])


def test_a_catalogue_whose_tags_hold_nan_migrates_to_the_monitor_column(catalogue_location: Path | str,
                                                                         monkeypatch: pytest.MonkeyPatch) -> None:
    """``--tag operator=Nan`` is a float tag, NaN, written as Python's JSON writes it. The migration to schema 6 read
    the tags with json_extract / ::jsonb, which refuse NaN: the catalogue failed to open for every acq command ("not a
    usable catalogue (malformed JSON)", the third read). The tags are read in Python."""
    monkeypatch.setattr(acq.monitoring.catalogue_db, "SCHEMA_VERSION", 5)
    with Catalogue(catalogue_location) as old, old._transaction():
        for key, tags in (("s1", {"operator": float("nan"), "monitor_id": "h:/m1:0000000a"}),
                          ("s2", {"operator": float("nan")}), ("s3", {"monitor_id": "h:/m2:0000000b"})):
            old._execute("INSERT INTO sessions (session_key, session_id, path, joint, created_utc, tags_json) "
                         f"VALUES (?, ?, '/{key}.h5', 'joint1', '2026-01-01T00:00:0{key[1]}+00:00', ?)",
                         (key, key, json.dumps(tags)))
            old._execute("INSERT INTO analyses (session_key, sha256, request_key, analyzed_utc, verdict) "
                         "VALUES (?, 'h', '{}', '2026-01-01T00:01:00+00:00', 'ok')", (key,))
    monkeypatch.undo()
    with Catalogue(catalogue_location) as c:
        version = c.schema_version
        m1 = [(e.session_id, math.isnan(e.tags["operator"])) for e in c.entries("joint1", monitor="h:/m1:0000000a")]
        m2 = [e.session_id for e in c.entries("joint1", monitor="h:/m2:0000000b")]
        unowned = [e.session_id for e in c.entries("joint1", monitor="-", unowned=True)]
    assert (version, m1, m2, unowned) == (6, [("s1", True)], ["s3"], ["s2"])


def test_a_failed_upgrade_of_a_postgresql_catalogue_is_one_line_with_its_detail(
        postgres_server: str, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    """psycopg's message goes on with DETAIL:/HINT: lines: an error opening or upgrading a PostgreSQL catalogue
    printed on several. One line: the first, with the DETAIL (which row) folded in."""
    url = new_database(postgres_server)
    with Catalogue(url) as c:
        for n in (1, 2):
            c.record(_outcome(f"s-0{n}", 890.0))  # two sessions of joint j1
    monkeypatch.setattr(acq.monitoring.catalogue_db, "MIGRATIONS",
                        (*MIGRATIONS, "CREATE UNIQUE INDEX one_session_per_joint ON sessions (joint)"))
    monkeypatch.setattr(acq.monitoring.catalogue_db, "SCHEMA_VERSION", SCHEMA_VERSION + 1)
    run = run_cli(capsys, "trend", "--catalogue", url, "--joint", "j1")
    assert (run.code, run.out, run.err) == (
        2, "", f"acq: error: {url}: not a usable catalogue (could not create unique index \"one_session_per_joint\": "
               "Key (joint)=(j1) is duplicated.)\n")


@pytest.mark.parametrize("writer_open", [False, True], ids=["immutable", "wal"])
def test_trend_and_fleet_read_a_catalogue_in_a_read_only_folder(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                                               writer_open: bool) -> None:
    """The trial: acq trend ro/mon1 --joint joint1 on a read-only mount said "read-only file system: …
    (SQLite writes beside a catalogue, also to read it)", exit 1. Without -wal/-shm beside it the file is read
    immutable=1; with a writer's -wal/-shm there (a writer still has it open) mode=ro."""
    folder = tmp_path / "mon1"
    folder.mkdir()
    writer = Catalogue(folder / "catalogue.sqlite")
    for i, k in enumerate((890.0, 891.0, 892.0)):
        writer.record(_outcome(f"s-0{i}", k))
    if not writer_open:
        writer.close()
    assert (folder / "catalogue.sqlite-wal").exists() == writer_open
    try:
        with read_only_view(folder) as ro:
            trend = run_cli(capsys, "trend", str(ro), "--joint", "j1", "--json")
            assert trend.code == 0, trend.err
            assert [s["K_Nm_per_rad"] for s in json.loads(trend.out)["points"]] == [890.0, 891.0, 892.0]
            fleet = run_cli(capsys, "fleet", str(ro), "--json")
            assert fleet.code == 0, fleet.err
            assert [(j["joint"], j["K_Nm_per_rad"]) for j in json.loads(fleet.out)] == [("j1", 892.0)]
            assert sorted(p.name for p in ro.iterdir()) == sorted(p.name for p in folder.iterdir())
    finally:
        if writer_open:
            writer.close()


def test_two_analyses_of_a_window_in_the_same_second_keep_the_later_against_the_spool(
        catalogue_location: Path | str, tmp_path: Path) -> None:
    """The monitor's spool holds window A's analysis; ``acq analyze`` of the same file, made later within the same
    second, was filed meanwhile. Replaying the spool keeps the later one and says so. Before: both were stamped to the
    second, the tie went to the spooled (earlier) copy and replaced the later analysis."""
    from dataclasses import replace

    from acq.monitoring.catalogue_spool import FilingQueue, Waiting
    from acq.offline.analyze import not_excited_json, request_for, sha256_of
    from acq.recording.reader import load
    from tests.helpers import record_session_in_subprocess

    session = load(record_session_in_subprocess(tmp_path / "s", 1.0))
    request = request_for(session)
    while True:  # two analyses of the file made within one second of the wall clock
        second = int(time.time())
        spooled_doc = not_excited_json(session, request, "the monitor's")
        later_doc = not_excited_json(session, request, "acq analyze's")
        if int(time.time()) == second:
            break
    assert spooled_doc["analyzed_utc"] < later_doc["analyzed_utc"]
    meta = {"session_id": session.meta.session_id, "joint": session.meta.joint,
            "created_utc": session.meta.created_utc, "start_monotonic_ns": 1, "status": "complete", "tags": {}}
    spooled = Outcome(str(session.path), sha256_of(session.path), request.key(), meta, spooled_doc, None, 1.0)
    with Catalogue(catalogue_location) as c:
        assert c.record(replace(spooled, doc=later_doc)) is None  # acq analyze --catalogue, meanwhile
        queue = FilingQueue(c, tmp_path / "spool.jsonl")
        filed = queue.file(Waiting("A", spooled))
        assert filed == [Waiting("A", replace(spooled, analyzed_utc=spooled_doc["analyzed_utc"]))]
        (entry,) = c.entries()
    assert entry.analyzed_utc == later_doc["analyzed_utc"]
    assert queue.notes == [f"{session.path.name}: not filed — the catalogue holds a later analysis of it "
                           f"({later_doc['analyzed_utc']}; this one {spooled_doc['analyzed_utc']})"]


def test_a_whole_second_stamp_replayed_against_a_later_one_in_its_second_loses_under_an_icu_collation(
        postgres_server: str) -> None:
    """Stamps compare as text. A database whose default collation is ICU's orders '…05+00:00' (an older acq's
    whole-second stamp, replayed from a spool) after '…05.500000+00:00' (weighing the punctuation last), so the older
    analysis replaced the later one (reviewer, session 14). The comparison is bytewise on both back ends."""
    import psycopg
    from dataclasses import replace

    url = new_database(postgres_server)
    name = url.rsplit("/", 1)[1]
    with psycopg.connect(f"{postgres_server}/postgres", autocommit=True) as db:
        db.execute(f"DROP DATABASE {name}")
        db.execute(f"CREATE DATABASE {name} TEMPLATE template0 LOCALE_PROVIDER icu ICU_LOCALE 'en-US' LOCALE 'C'")
        icu_order = db.execute("SELECT '2026-01-02T00:00:05+00:00' COLLATE \"und-x-icu\""
                               " <= '2026-01-02T00:00:05.500000+00:00' COLLATE \"und-x-icu\"").fetchone()[0]
    later, older = _outcome("s-01", 890.0), _outcome("s-01", 880.0)
    later = replace(later, doc={**later.doc, "analyzed_utc": "2026-01-02T00:00:05.500000+00:00"})
    older = replace(older, doc={**older.doc, "analyzed_utc": "2026-01-02T00:00:05+00:00"})
    with Catalogue(url) as c:
        assert c.record(later) is None
        kept = c.record(older, keep_newer=True)
        (entry,) = c.entries()
    assert (icu_order, kept, entry.K_Nm_per_rad) == (False, "2026-01-02T00:00:05.500000+00:00", 890.0)
