"""Fleet rows per condition: a schema-1 database is migrated and stays readable; an armed-throughout flight log
(no still data) is analysed with flight rows per IMU, not failed; the report trends each condition apart."""

from __future__ import annotations

import math
import sqlite3

import numpy as np

from companion.fleet import store as st
from tests.redundancy.synthetic import flight

DEG = math.radians(1.0) / 60.0


def _v1(path):
    schema = st.SCHEMA.replace("    condition TEXT NOT NULL DEFAULT 'still',\n", "").replace(
        "PRIMARY KEY (hash, sysid, compid, message, imu, axis, condition)", "PRIMARY KEY (hash, sysid, compid, message, imu, axis)")
    con = sqlite3.connect(path)
    con.executescript(schema)
    con.execute("INSERT INTO meta VALUES ('schema_version', '1')")
    con.execute("INSERT INTO logs (hash, path, status, start_time) VALUES ('h1', '/x/a.bin', 'ok', 100.0)")
    cols = [c for c in st.RESULT_COLUMNS if c != "condition"]
    vals = {c: None for c in cols}
    vals.update(hash="h1", vehicle="v", sysid=1, compid=1, imu=0, message="IMU", axis="gx", status="ok", N=1e-4,
                N_lo=0.9e-4, N_hi=1.1e-4)
    con.execute(f"INSERT INTO results ({', '.join(cols)}) VALUES ({', '.join('?' * len(cols))})",
                [vals[c] for c in cols])
    con.commit()
    con.close()


def test_schema_1_database_is_migrated_and_readable(tmp_path):
    db = tmp_path / "old.sqlite"
    _v1(db)
    with st.FleetStore(db, create=False) as s:
        rows = list(s.all_results())
        assert len(rows) == 1 and rows[0]["condition"] == "still" and rows[0]["N"] == 1e-4
        assert list(s.all_results("flight")) == []
    con = sqlite3.connect(db)
    assert con.execute("SELECT value FROM meta WHERE key = 'schema_version'").fetchone()[0] == str(st.SCHEMA_VERSION)


def test_armed_throughout_log_gives_flight_rows(tmp_path):
    from companion.fleet.fleet_ranking import fleet_trends
    from companion.fleet.task import analyze_log
    from companion.sim.dataflash_writer import write_imu_log

    n_true = np.array([0.8, 1.6, 2.4]) * DEG
    t, g, _ = flight(11, n_true, seconds=200.0, offsets=[0.0, 0.001, 0.0005])
    t = t + 1.0
    accel = np.zeros((3, t.shape[0], 3))
    accel[..., 2] = -9.8
    path = tmp_path / "armed.bin"
    write_imu_log(path, t, np.array(g), accel, layout="4.x", armed=[(0.5, True)])
    out = analyze_log(str(path))
    assert out["status"] == "ok", out["error"]
    fl = [r for r in out["rows"] if r["condition"] == "flight"]
    assert sorted({r["imu"] for r in fl}) == [0, 1, 2] and len(fl) == 9
    for r in fl:
        assert r["N"] is not None and r["still_s"] > 150
        width = r["N_hi"] - r["N_lo"]
        assert r["N_lo"] - width <= n_true[r["imu"]] <= r["N_hi"] + width
    with st.FleetStore(tmp_path / "f.sqlite") as s:
        s.record("h", out, 1, 1.0)
        entries = fleet_trends(s)
    assert {e["condition"] for e in entries} == {"flight"} and len(entries) == 3
