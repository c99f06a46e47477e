"""Fleet database: schema, one transaction per log, idempotence, failures, history query."""

from __future__ import annotations

import sqlite3

import pytest

from companion.errors import CompanionError
from companion.fleet.store import FleetStore


def _result(path, status="ok", n=2e-4, start=1.75e9, error=None):
    rows = [] if status != "ok" else [
        {"vehicle": "veh", "sysid": 1, "compid": 1, "imu": 0, "message": "RAW_IMU", "axis": a, "status": "ok",
         "N": n, "N_lo": 0.9 * n, "N_hi": 1.1 * n, "still_s": 60.0, "rate_hz": 50.0,
         "extra": {"terms": [{"effect": "gauss_markov", "sigma": 1e-4, "tau_c": 5.0}]} if a == "gz" else None}
        for a in ("gx", "gy", "gz")]
    return {"path": path, "format": "tlog", "status": status, "error": error, "elapsed_s": 0.1,
            "log": {"sysid": 1, "vehicle": "veh", "start_time": start, "imu_ids": {0: 123}} if rows else {},
            "rows": rows}


def test_record_history_and_idempotence(tmp_path):
    db = tmp_path / "f.sqlite"
    with FleetStore(db) as s:
        s.record("h2", _result("/b.tlog", n=3e-4, start=2e9), 10, 1.0)
        s.record("h1", _result("/a.tlog", start=1e9), 10, 1.0)
        s.record("h1", _result("/a.tlog", start=1e9), 10, 1.0)  # again: replaced, not duplicated
        hist = s.history("veh", 0, "gx")
        assert [h["N"] for h in hist] == [2e-4, 3e-4]  # oldest flight first
        assert s.counts() == {"ok": 2, "failed": 0}
        assert s.cached_hash("/a.tlog", 10, 1.0) == "h1" and s.cached_hash("/a.tlog", 11, 1.0) is None
        assert s.con.execute("SELECT COUNT(*) FROM results").fetchone()[0] == 6
        assert s.con.execute("SELECT imu_ids FROM logs WHERE hash='h1'").fetchone()[0] == '{"0": 123}'
        assert "gauss_markov" in s.con.execute("SELECT extra FROM results WHERE axis='gz' LIMIT 1").fetchone()[0]


def test_failed_log_recorded_then_replaced_by_success(tmp_path):
    with FleetStore(tmp_path / "f.sqlite") as s:
        s.record("h", _result("/x.tlog", status="failed", error="x.tlog: no IMU messages"), 5, 2.0)
        assert s.failures() == [("/x.tlog", "x.tlog: no IMU messages")]
        assert s.status("h") == "failed"
        s.record("h", _result("/x.tlog"), 5, 2.0)
        assert s.status("h") == "ok" and s.failures() == []


def test_a_crash_mid_transaction_leaves_nothing_half_written(tmp_path):
    db = tmp_path / "f.sqlite"
    with FleetStore(db) as s:
        bad = _result("/c.tlog")
        bad["rows"][1]["axis"] = None  # NOT NULL violated on the second row
        with pytest.raises(sqlite3.IntegrityError):
            s.record("hc", bad, 1, 1.0)
        assert s.status("hc") is None
        assert s.con.execute("SELECT COUNT(*) FROM results").fetchone()[0] == 0


def test_report_on_missing_or_foreign_database_is_one_line(tmp_path):
    with pytest.raises(CompanionError, match="no such database"):
        FleetStore(tmp_path / "none.sqlite", create=False)
    junk = tmp_path / "junk.sqlite"
    junk.write_bytes(b"this is not sqlite" * 100)
    with pytest.raises(CompanionError, match="not a fleet database"):
        FleetStore(junk)
    other = tmp_path / "other.sqlite"
    sqlite3.connect(other).execute("CREATE TABLE meta (key TEXT PRIMARY KEY, value TEXT)").connection.commit()
    con = sqlite3.connect(other)
    con.execute("INSERT INTO meta VALUES ('schema_version', '99')")
    con.commit()
    con.close()
    with pytest.raises(CompanionError, match="schema 99"):
        FleetStore(other)


def test_plan_skips_known_and_duplicate_content_and_reports_unreadable(tmp_path):
    from companion.fleet.discover import discover
    from companion.fleet.dask_runner import plan

    for name, data in (("a.tlog", b"A" * 100), ("b.tlog", b"B" * 100), ("c.tlog", b"A" * 100), ("d.tlog", b"D")):
        (tmp_path / name).write_bytes(data)
    logs = discover([str(tmp_path)])
    with FleetStore(tmp_path / "f.sqlite") as s:
        work, skipped, unreadable, dup = plan(s, logs)
        assert [w.log.path.rsplit("/", 1)[1] for w in work] == ["a.tlog", "b.tlog", "d.tlog"]
        assert skipped == 0 and dup == 1 and unreadable == []  # c.tlog is a.tlog's content, not in the database
        s.record(work[0].hash, _result(work[0].log.path), work[0].log.size, work[0].log.mtime)

        def hasher(paths):  # as on a cluster where one file cannot be read
            return {p: ("error: Permission denied" if p.endswith("d.tlog") else "h" + p[-6]) for p in paths}

        work, skipped, unreadable, dup = plan(s, logs, hasher=hasher)
        assert [w.log.path.rsplit("/", 1)[1] for w in work] == ["b.tlog", "c.tlog"]
        assert skipped == 1 and dup == 0  # a.tlog: its hash came from the paths table, no re-hashing
        assert unreadable == [(str(tmp_path / "d.tlog"), "cannot read (Permission denied)")]


def test_another_programs_sqlite_file_is_refused_untouched(tmp_path):
    """An SQLite file that is not a fleet database (another program's, with or without a table named meta)
    is refused with one line and left as it was: no tables of ours added to it."""
    for name, ddl in (("users.sqlite", "CREATE TABLE users (id INTEGER)"),
                      ("meta.sqlite", "CREATE TABLE meta (key TEXT, value TEXT)")):
        path = tmp_path / name
        con = sqlite3.connect(path)
        con.execute(ddl)
        con.commit()
        con.close()
        before = path.read_bytes()
        for create in (True, False):
            with pytest.raises(CompanionError, match="not a fleet database"):
                FleetStore(path, create=create)
        assert path.read_bytes() == before
        con = sqlite3.connect(path)
        assert [t for (t,) in con.execute("SELECT name FROM sqlite_master WHERE type = 'table'")] == [ddl.split()[2]]
        con.close()
