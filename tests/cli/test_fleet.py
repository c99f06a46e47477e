"""companion fleet simulate / analyze / report end to end: a local Dask cluster of 2 workers on loopback
(bounded in time), interruption and resume, failures recorded, idempotence, correctness over seeds."""

from __future__ import annotations

import html
import json
import os
import shutil
import signal
import sqlite3
import subprocess
import sys
import time

import numpy as np
import pytest

from companion.cli.main import main

TIMEOUT = 600  # generous bound for a busy machine; the runs take seconds


def _cli(*args, timeout=TIMEOUT):
    return subprocess.run([sys.executable, "-m", "companion", *args], capture_output=True, text=True,
                          timeout=timeout)


def _sick(truth):
    return {(v["board_id"], i["imu"]) for v in truth["vehicles"] for i in v["imus"] if i["degrading"]}


def _count(db):
    try:
        con = sqlite3.connect(db, timeout=5)
        try:
            return con.execute("SELECT COUNT(*) FROM logs").fetchone()[0]
        finally:
            con.close()
    except sqlite3.OperationalError:
        return 0


@pytest.mark.network
def test_dask_two_workers_interrupt_resume_report(tmp_path):
    pytest.importorskip("dask.distributed")
    logs = tmp_path / "logs"
    r = _cli("fleet", "simulate", str(logs), "--vehicles", "3", "--flights", "10", "--imus", "2",
             "--duration", "20", "--rate", "50", "--seed", "11")
    assert r.returncode == 0, r.stderr
    truth = json.loads((logs / "fleet_truth.json").read_text())
    (logs / "vehicle_000" / "broken.tlog").write_bytes(b"\xfe\x00not a log" * 50)
    db = str(tmp_path / "fleet.sqlite")
    # first run: interrupted (SIGINT, as Ctrl-C) once a few logs are recorded
    proc = subprocess.Popen([sys.executable, "-m", "companion", "fleet", "analyze", str(logs), "--db", db,
                             "--workers", "2"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            start_new_session=True)
    deadline = time.monotonic() + TIMEOUT
    while _count(db) < 3 and proc.poll() is None and time.monotonic() < deadline:
        time.sleep(0.2)
    if proc.poll() is None:
        os.killpg(proc.pid, signal.SIGINT)  # Ctrl-C reaches the whole process group, workers included
    out, err = proc.communicate(timeout=TIMEOUT)
    first = _count(db)
    if proc.returncode == 130:
        assert "interrupted" in out and 3 <= first < 31 and "Traceback" not in err
    else:  # it finished before the signal arrived
        assert proc.returncode == 0, err
    # resume: only what is missing is analysed; nothing lost, nothing twice
    r = _cli("fleet", "analyze", str(logs), "--db", db, "--workers", "2", "--batch", "3")
    assert r.returncode == 0, r.stderr
    assert f"{31 - first} to analyse, {first} already" in r.stderr
    assert "1 failed" in r.stdout.splitlines()[-1] and "broken.tlog" in (r.stderr + out + err)
    con = sqlite3.connect(db)
    assert con.execute("SELECT COUNT(*) FROM logs WHERE status='ok'").fetchone()[0] == 30
    err_text = con.execute("SELECT error FROM logs WHERE status='failed'").fetchone()[0]
    assert "no IMU messages" in err_text and "\n" not in err_text
    assert con.execute("SELECT COUNT(*) FROM results").fetchone()[0] == 30 * 2 * 3
    con.close()
    # idempotent: a third run analyses nothing
    r = _cli("fleet", "analyze", str(logs), "--db", db, "--workers", "2")
    assert r.returncode == 0 and "0 to analyse, 31 already" in r.stderr
    # report: the degrading IMUs first and flagged, no healthy one flagged
    out_json, out_html = tmp_path / "r.json", tmp_path / "r.html"
    r = _cli("fleet", "report", "--db", db, "--json", str(out_json), "--html", str(out_html))
    assert r.returncode == 4, r.stderr  # flagged IMUs: the exit status of faults found
    imus = json.loads(out_json.read_text())["imus"]
    assert len(imus) == 6
    sick = _sick(truth)
    assert {(e["vehicle"], e["imu"]) for e in imus[:len(sick)]} == sick
    assert all(e["flagged"] for e in imus[:len(sick)]) and not any(e["flagged"] for e in imus[len(sick):])
    for e in imus[:len(sick)]:
        assert e["param"] == "N" and 1.25 < e["trend"] < 1.8 and e["flights"] == 10
        assert isinstance(e["sysid"], int) and isinstance(e["evidence"], float) and e["axis"] in ("gx", "gy", "gz")
    page = out_html.read_text()
    assert page.count("data:image/png;base64,") == 6 and "FLAGGED" in page
    # self-contained: the plotting script is inline, nothing is loaded from elsewhere
    assert "src=" not in page.replace("src=\"data:", "").replace("src='data:", "") and "<link" not in page


@pytest.mark.parametrize("seed", [21, pytest.param(22, marks=pytest.mark.soak), pytest.param(23, marks=pytest.mark.soak)])
def test_degrading_imus_ranked_first_over_seeds(tmp_path, seed, capsys):
    """In-process (--workers 0) small fleets, one gyro axis: 3 of 6 IMUs' N rises 1.5x over 10 flights."""
    logs = tmp_path / "logs"
    assert main(["fleet", "simulate", str(logs), "--vehicles", "3", "--flights", "10", "--imus", "2",
                 "--duration", "30", "--rate", "50", "--seed", str(seed)]) == 0
    db = str(tmp_path / "f.sqlite")
    assert main(["fleet", "analyze", str(logs), "--db", db, "--workers", "0", "--axes", "gx", "--quiet"]) == 0
    out = tmp_path / "r.json"
    rc = main(["fleet", "report", "--db", db, "--json", str(out)])
    imus = json.loads(out.read_text())["imus"]
    assert rc == (4 if any(e["flagged"] for e in imus) else 0)  # flagged IMUs: faults found
    sick = _sick(json.loads((logs / "fleet_truth.json").read_text()))
    assert {(e["vehicle"], e["imu"]) for e in imus[:3]} == sick
    assert [e["flagged"] for e in imus] == [True] * 3 + [False] * 3


def test_time_limit_then_resume_and_vehicle_from_dir(tmp_path, capsys):
    logs = tmp_path / "logs"
    assert main(["fleet", "simulate", str(logs), "--vehicles", "2", "--flights", "3", "--imus", "1",
                 "--duration", "10", "--rate", "50", "--degrading", "0"]) == 0
    db = str(tmp_path / "f.sqlite")
    rc = main(["fleet", "analyze", str(logs), "--db", db, "--workers", "0", "--time-limit", "1e-9", "--quiet"])
    assert rc == 3 and "deadline" in capsys.readouterr().out
    assert main(["fleet", "analyze", str(logs), "--db", db, "--workers", "0", "--quiet", "--vehicle", "dir"]) == 0
    con = sqlite3.connect(db)
    assert con.execute("SELECT COUNT(*) FROM logs WHERE status='ok'").fetchone()[0] == 6
    vehicles = {v for (v,) in con.execute("SELECT DISTINCT vehicle FROM results")}
    con.close()
    assert vehicles <= {"vehicle_000", "vehicle_001"} and len(vehicles) >= 1
    # a copy of a log under another name is the same content: skipped
    shutil.copy(logs / "vehicle_000" / "flight_000.tlog", logs / "vehicle_000" / "copy.tlog")
    assert main(["fleet", "analyze", str(logs), "--db", db, "--workers", "0", "--quiet"]) == 0
    assert "0 to analyse, 7 already" in capsys.readouterr().err


def test_user_errors_are_one_line(tmp_path, capsys):
    db = str(tmp_path / "f.sqlite")
    assert main(["fleet", "analyze", str(tmp_path / "nothing"), "--db", db]) == 2
    assert main(["fleet", "report", "--db", str(tmp_path / "none.sqlite")]) == 2
    assert main(["fleet", "simulate", str(tmp_path / "s"), "--vehicles", "0", "--flights", "3"]) == 2
    assert main(["fleet", "analyze", str(tmp_path), "--db", db, "--axes", "qq"]) == 2
    err = capsys.readouterr().err
    assert err.count("companion: error:") == 4 and "Traceback" not in err
    # each names the option at fault
    for argv, opt in ((["simulate", str(tmp_path / "s"), "--vehicles", "1", "--flights", "2", "--seed", "-1"],
                       "--seed"),
                      (["simulate", str(tmp_path / "s"), "--vehicles", "1", "--flights", "2", "--degrading", "-1"],
                       "--degrading"),
                      (["report", "--db", db, "--top", "-1"], "--top"),
                      (["report", "--db", db, "--max-plots", "-2"], "--max-plots"),
                      (["report", "--db", str(tmp_path)], "is a directory")):
        assert main(["fleet", *argv]) == 2, argv
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and opt in err[0], (argv, err)


def test_missing_dask_is_one_clear_line(tmp_path, monkeypatch, capsys):
    import builtins

    logs = tmp_path / "logs"
    assert main(["fleet", "simulate", str(logs), "--vehicles", "1", "--flights", "1", "--imus", "1",
                 "--duration", "5", "--rate", "50", "--degrading", "0"]) == 0
    real = builtins.__import__

    def no_dask(name, *a, **k):
        if name.startswith("dask") or name.startswith("distributed"):
            raise ImportError(name)
        return real(name, *a, **k)

    monkeypatch.setattr(builtins, "__import__", no_dask)
    assert main(["fleet", "analyze", str(logs), "--db", str(tmp_path / "f.sqlite"), "--workers", "2"]) == 2
    err = capsys.readouterr().err
    assert "pip install 'companion[fleet]'" in err and err.count("\n") == 2  # plan line + the error


@pytest.mark.network
def test_existing_scheduler_on_loopback(tmp_path, capsys):
    """--scheduler: the same command on an already running cluster (here a loopback LocalCluster)."""
    distributed = pytest.importorskip("dask.distributed")
    logs = tmp_path / "logs"
    assert main(["fleet", "simulate", str(logs), "--vehicles", "2", "--flights", "2", "--imus", "1",
                 "--duration", "10", "--rate", "50", "--degrading", "0"]) == 0
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=True, host="127.0.0.1",
                                  dashboard_address="127.0.0.1:0") as cluster:
        assert cluster.scheduler_address.startswith("tcp://127.0.0.1:")
        db = str(tmp_path / "f.sqlite")
        assert main(["fleet", "analyze", str(logs), "--db", db, "--scheduler", cluster.scheduler_address,
                     "--quiet"]) == 0
    assert "4 analysed, 0 failed" in capsys.readouterr().out


def test_dataflash_fleet_board_ids_and_ranking(tmp_path, capsys):
    """`fleet simulate --format bin` writes DataFlash logs that `fleet analyze` reads: vehicles by the MCU id
    in the boot banner, flights ordered by the GPS start time, the degrading IMUs ranked first."""
    logs = tmp_path / "bin"
    assert main(["fleet", "simulate", str(logs), "--vehicles", "2", "--flights", "8", "--imus", "2",
                 "--degrading", "2", "--rise", "2", "--duration", "30", "--rate", "50", "--seed", "5",
                 "--format", "bin"]) == 0
    assert len(list(logs.glob("*/*.bin"))) == 16
    truth = json.loads((logs / "fleet_truth.json").read_text())
    db = str(tmp_path / "f.sqlite")
    assert main(["fleet", "analyze", str(logs), "--db", db, "--workers", "0", "--axes", "gx", "--quiet"]) == 0
    con = sqlite3.connect(db)
    rows = con.execute("SELECT vehicle, start_time, start_source, board_id FROM logs").fetchall()
    con.close()
    by_path = {e["path"]: e for e in truth["logs"]}
    assert {r[0] for r in rows} == {v["board_id"] for v in truth["vehicles"]}
    assert all(r[2] == "log" and r[3] == r[0] for r in rows)
    assert sorted(round(r[1], 1) for r in rows) == sorted(round(e["start_time"], 1) for e in by_path.values())
    out = tmp_path / "r.json"
    assert main(["fleet", "report", "--db", db, "--json", str(out)]) == 4  # degrading IMUs flagged
    imus = json.loads(out.read_text())["imus"]
    assert {(e["vehicle"], e["imu"]) for e in imus[:2]} == _sick(truth)


def test_simulate_format_errors_are_one_line(tmp_path, capsys):
    assert main(["fleet", "simulate", str(tmp_path / "x"), "--vehicles", "1", "--flights", "2", "--format", "bin",
                 "--message", "HIGHRES_IMU"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "DataFlash" in err[0]


def test_logs_grouped_by_system_id_alone_are_said_to_be_possibly_different_vehicles(tmp_path, capsys):
    """Logs without a board id (old DataFlash logs, CSVs) all become vehicle sys0: the report says that its
    trends may compare different vehicles, and not when the folders name the vehicles."""
    rng = np.random.default_rng(8)
    logs = tmp_path / "logs"
    t = np.arange(3000) / 50.0
    for k, name in enumerate(("rover_a", "plane_b")):
        (logs / name).mkdir(parents=True)
        d = np.column_stack([rng.normal(0, 2e-3 * (1 + k), (t.size, 3)), 9.81 * np.array([0, 0, -1]) + rng.normal(0, 0.02, (t.size, 3))])
        with open(logs / name / "flight.csv", "w") as f:
            f.write("time_s,gx,gy,gz,ax,ay,az\n")
            np.savetxt(f, np.column_stack([t, d]), delimiter=",", fmt="%.10g")
    db = str(tmp_path / "f.sqlite")
    assert main(["fleet", "analyze", str(logs), "--db", db, "--workers", "0", "--axes", "gx", "--quiet"]) == 0
    capsys.readouterr()
    assert main(["fleet", "report", "--db", db]) == 0
    out = capsys.readouterr().out
    notes = [x for x in out.splitlines() if x.startswith("note: vehicle sys0:")]
    assert len(notes) == 1 and "2 logs with no board id" in notes[0] and "different vehicles" in notes[0], out
    assert "--vehicle dir" in notes[0]
    db2 = str(tmp_path / "g.sqlite")
    assert main(["fleet", "analyze", str(logs), "--db", db2, "--workers", "0", "--axes", "gx", "--quiet",
                 "--vehicle", "dir"]) == 0
    capsys.readouterr()
    assert main(["fleet", "report", "--db", db2]) == 0
    assert "note: vehicle" not in capsys.readouterr().out


def _flights(db):
    con = sqlite3.connect(db)
    try:
        return con.execute("SELECT COUNT(*), COUNT(DISTINCT path) FROM logs").fetchone()
    finally:
        con.close()


def test_a_log_that_grew_replaces_its_partial_record(tmp_path, capsys):
    """A log copied while still being written, then again once complete, is one flight, not two; a path
    whose content changed otherwise (a log number reused) is a different flight."""
    logs = tmp_path / "logs"
    assert main(["fleet", "simulate", str(logs), "--vehicles", "1", "--flights", "3", "--imus", "1",
                 "--duration", "10", "--rate", "50", "--degrading", "0"]) == 0
    f = logs / "vehicle_000" / "flight_002.tlog"
    full = f.read_bytes()
    f.write_bytes(full[:len(full) // 2])
    db = str(tmp_path / "f.sqlite")
    args = ["fleet", "analyze", str(logs), "--db", db, "--workers", "0", "--axes", "gx", "--quiet"]
    assert main(args) == 0 and _flights(db) == (3, 3)
    f.write_bytes(full)
    assert main(args) == 0
    assert _flights(db) == (3, 3)
    con = sqlite3.connect(db)
    size = con.execute("SELECT size FROM logs WHERE path = ?", (str(f),)).fetchone()[0]
    con.close()
    assert size == len(full)
    # another log's bytes at the same path (the card wiped, the number reused): a flight of its own
    f.write_bytes((logs / "vehicle_000" / "flight_000.tlog").read_bytes()[:len(full) // 3] + b"\0")
    assert main(args) == 0 and _flights(db) == (4, 3)


def test_new_axes_on_an_existing_database_are_analysed(tmp_path, capsys):
    """--axes on a database that holds the logs for other axes: the logs are analysed for the new axes too,
    not skipped as done."""
    from companion.fleet.task import analyze_logs

    logs = tmp_path / "logs"
    assert main(["fleet", "simulate", str(logs), "--vehicles", "1", "--flights", "2", "--imus", "1",
                 "--duration", "10", "--rate", "50", "--degrading", "0"]) == 0
    db = str(tmp_path / "f.sqlite")

    def axes():
        con = sqlite3.connect(db)
        try:
            return dict(con.execute("SELECT axis, COUNT(*) FROM results GROUP BY axis"))
        finally:
            con.close()

    run = ["fleet", "analyze", str(logs), "--db", db, "--workers", "0", "--quiet", "--axes"]
    assert main(run + ["gx"]) == 0 and axes() == {"gx": 2}
    capsys.readouterr()
    assert main(run + ["gy"]) == 0 and axes() == {"gx": 2, "gy": 2}
    assert "2 to analyse (2 of them stored before" in capsys.readouterr().err
    assert main(run + ["gx,gy"]) == 0
    assert "0 to analyse, 2 already" in capsys.readouterr().err
    # a --batch task carries each log's own axes
    paths = sorted(str(p) for p in logs.glob("*/*.tlog"))
    out = analyze_logs(paths, [("gx",), ("gy", "gz")])
    assert [sorted({r["axis"] for r in o["rows"]}) for o in out] == [["gx"], ["gy", "gz"]]


def test_a_folder_of_several_boards_is_ranked_per_board(tmp_path, capsys):
    """--vehicle dir on a folder holding the DataFlash logs of 3 boards (all system id 0): each board's IMU is
    ranked apart as folder/board id (in full), so the degrading one is flagged; mixed into one IMU of 24
    flights its rise was lost. The identity note says so, in the HTML too."""
    sim = tmp_path / "sim"
    assert main(["fleet", "simulate", str(sim), "--vehicles", "3", "--flights", "8", "--imus", "1",
                 "--degrading", "1", "--rise", "2", "--duration", "30", "--rate", "50", "--seed", "4",
                 "--format", "bin"]) == 0
    truth = json.loads((sim / "fleet_truth.json").read_text())
    hangar = tmp_path / "logs" / "hangar"
    hangar.mkdir(parents=True)
    for f in sim.glob("*/*.bin"):
        shutil.copy(f, hangar / f"{f.parent.name}_{f.name}")
    db = str(tmp_path / "f.sqlite")
    assert main(["fleet", "analyze", str(tmp_path / "logs"), "--db", db, "--workers", "0", "--axes", "gx",
                 "--quiet", "--vehicle", "dir"]) == 0
    capsys.readouterr()
    out, html_out = tmp_path / "r.json", tmp_path / "r.html"
    rc = main(["fleet", "report", "--db", db, "--json", str(out), "--html", str(html_out)])
    printed = capsys.readouterr().out
    imus = json.loads(out.read_text())["imus"]
    assert rc == (4 if any(e["flagged"] for e in imus) else 0)  # flagged IMUs: faults found
    boards = {v["board_id"] for v in truth["vehicles"]}
    assert {e["vehicle"] for e in imus} == {f"hangar/{b}" for b in boards}
    assert [(e["vehicle"], e["flagged"]) for e in imus if e["flagged"]] == [
        (f"hangar/{b}", True) for b, _ in _sick(truth)]
    assert all(f"hangar/{b}" in printed for b in boards)  # not cut to the column's width
    note = imus[0]["identity_note"]
    assert note and "3 boards" in note and all(b in note for b in boards)
    assert html.escape(note) in html_out.read_text()


def test_output_paths_are_checked_before_any_work(tmp_path, capsys, monkeypatch):
    """--db in a missing directory or on a directory, --html/--json that cannot be written: one error line
    naming the option, exit 2, before any log is read or any trend computed."""
    import companion.fleet.discover as discover_mod
    import companion.fleet.fleet_ranking as report_mod

    def boom(*a, **k):
        raise AssertionError("work started before the output paths were checked")

    logs = tmp_path / "logs"
    assert main(["fleet", "simulate", str(logs), "--vehicles", "1", "--flights", "1", "--imus", "1",
                 "--duration", "5", "--rate", "50", "--degrading", "0"]) == 0
    db = str(tmp_path / "f.sqlite")
    assert main(["fleet", "analyze", str(logs), "--db", db, "--workers", "0", "--quiet", "--axes", "gx"]) == 0
    capsys.readouterr()
    monkeypatch.setattr(discover_mod, "discover", boom)
    monkeypatch.setattr(report_mod, "fleet_trends", boom)
    missing = tmp_path / "no" / "such"
    cases = [(["fleet", "analyze", str(logs), "--db", str(missing / "f.sqlite"), "--workers", "0"], "--db"),
             (["fleet", "analyze", str(logs), "--db", str(tmp_path), "--workers", "0"], "--db"),
             (["fleet", "report", "--db", db, "--html", str(missing / "r.html")], "--html"),
             (["fleet", "report", "--db", db, "--json", str(tmp_path)], "--json")]
    for argv, opt in cases:
        assert main(argv) == 2, argv
        cap = capsys.readouterr()
        err = cap.err.strip().splitlines()
        assert len(err) == 1 and err[0].startswith(f"companion: error: {opt} "), (argv, cap.err)
        assert cap.out == ""
    assert not missing.exists()


def test_a_failed_logs_path_is_printed_once(tmp_path, capsys):
    logs = tmp_path / "logs"
    logs.mkdir()
    bad = logs / "a.tlog"
    bad.write_text("not a telemetry log\n")
    db = str(tmp_path / "f.sqlite")
    assert main(["fleet", "analyze", str(logs), "--db", db, "--workers", "0", "--quiet"]) == 5  # no log analysed
    lines = [x for x in capsys.readouterr().err.splitlines() if x.startswith("failed:")]
    assert len(lines) == 1 and lines[0].count("a.tlog") == 1 and "no IMU messages" in lines[0], lines
    con = sqlite3.connect(db)
    path, error = con.execute("SELECT path, error FROM logs").fetchone()
    con.close()
    assert path == str(bad) and "a.tlog" not in error and error.startswith("no IMU messages")


def _accel_batch_log(path, seed):
    """A DataFlash log: one IMU at 50 Hz and accelerometer-only batch-sampler bursts (ISBH type 0, ISBD)."""
    import struct

    from companion.sim.dataflash_writer import FMT_TYPE, HEAD, write_imu_log

    rng = np.random.default_rng(seed)
    t = np.arange(1500) / 50.0 + 1.0
    write_imu_log(path, t, rng.normal(0, 3e-3, (1, t.size, 3)),
                  np.array([0, 0, -9.81]) + rng.normal(0, 0.02, (1, t.size, 3)), params={"INS_LOG_BAT_MASK": 1.0})

    def fmt(tid, name, f, cols):
        size = 3 + struct.calcsize("<" + f.replace("a", "32h"))
        return HEAD + bytes([FMT_TYPE]) + struct.pack("<BB4s16s64s", tid, size, name.encode(), f.encode(), cols.encode())

    out = fmt(90, "ISBH", "QHBBHHQf", "TimeUS,N,type,instance,mul,smp_cnt,SampleUS,smp_rate")
    out += fmt(91, "ISBD", "QHHaaa", "TimeUS,N,seqno,x,y,z")
    for k in range(10):  # 1,024 accelerometer samples at 1 kHz every 3 s
        t0 = int((1.5 + 3 * k) * 1e6)
        out += HEAD + bytes([90]) + struct.pack("<QHBBHHQf", t0, k, 0, 0, 1000, 1024, t0, 1000.0)
        for s in range(32):
            v = np.round((np.array([0, 0, -9.81]) + rng.normal(0, 0.05, (32, 3))) * 1000).astype("<i2")
            out += HEAD + bytes([91]) + struct.pack("<QHH", t0, k, s) + b"".join(v[:, j].tobytes() for j in range(3))
    with open(path, "ab") as fh:
        fh.write(out)


def test_accelerometer_batches_are_not_ranked_as_gyros(tmp_path, capsys):
    logs = tmp_path / "logs"
    logs.mkdir()
    for i in range(2):
        _accel_batch_log(logs / f"f{i}.bin", i)
    db = str(tmp_path / "f.sqlite")
    assert main(["fleet", "analyze", str(logs), "--db", db, "--workers", "0", "--quiet"]) == 0
    con = sqlite3.connect(db)
    messages = {m for (m,) in con.execute("SELECT DISTINCT message FROM results")}
    con.close()
    assert messages == {"IMU"}
    out = tmp_path / "r.json"
    assert main(["fleet", "report", "--db", db, "--json", str(out)]) == 0
    assert [e["message"] for e in json.loads(out.read_text())["imus"]] == ["IMU"]
    # asked for accelerometer axes, the batch is analysed
    db2 = str(tmp_path / "g.sqlite")
    assert main(["fleet", "analyze", str(logs), "--db", db2, "--workers", "0", "--quiet", "--axes", "ax"]) == 0
    con = sqlite3.connect(db2)
    assert {m for (m,) in con.execute("SELECT DISTINCT message FROM results")} == {"IMU", "ISB_ACCEL"}
    con.close()


def _wait_for_line(stream, text):
    """Lines of ``stream`` up to and including the first holding ``text`` (or all of them, at EOF)."""
    lines = []
    for line in stream:
        lines.append(line)
        if text in line:
            break
    return "".join(lines)


def test_sigterm_stops_like_ctrl_c_with_exit_143_and_a_resumable_database(tmp_path):
    logs = tmp_path / "logs"
    assert main(["fleet", "simulate", str(logs), "--vehicles", "2", "--flights", "6", "--imus", "3",
                 "--duration", "60", "--rate", "100", "--degrading", "0"]) == 0
    db = str(tmp_path / "f.sqlite")
    proc = subprocess.Popen([sys.executable, "-m", "companion", "fleet", "analyze", str(logs), "--db", db,
                             "--workers", "0"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + TIMEOUT
    while _count(db) < 1 and proc.poll() is None and time.monotonic() < deadline:
        time.sleep(0.05)
    proc.send_signal(signal.SIGTERM)
    out, err = proc.communicate(timeout=TIMEOUT)
    first = _count(db)
    if proc.returncode == 0:
        pytest.skip("all 12 logs were analysed before the signal arrived")
    assert proc.returncode == 143, err
    assert "Traceback" not in err and f"terminated: {12 - first} log(s) not analysed, run again" in out
    con = sqlite3.connect(db)
    assert con.execute("PRAGMA integrity_check").fetchone()[0] == "ok"
    assert con.execute("SELECT COUNT(DISTINCT hash) FROM results").fetchone()[0] == first
    con.close()
    r = _cli("fleet", "analyze", str(logs), "--db", db, "--workers", "0", "--time-limit", "1e-9")
    assert f"{12 - first} to analyse, {first} already" in r.stderr


@pytest.mark.network
def test_sigterm_to_the_process_group_while_the_cluster_starts(tmp_path):
    """A batch system's SIGTERM reaches the workers too, here while the local cluster is starting: exit
    143 and one line, no traceback from a half-started cluster."""
    pytest.importorskip("dask.distributed")
    logs = tmp_path / "logs"
    assert main(["fleet", "simulate", str(logs), "--vehicles", "1", "--flights", "2", "--imus", "1",
                 "--duration", "10", "--rate", "50", "--degrading", "0"]) == 0
    db = str(tmp_path / "f.sqlite")
    proc = subprocess.Popen([sys.executable, "-m", "companion", "fleet", "analyze", str(logs), "--db", db,
                             "--workers", "2"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            start_new_session=True)
    head = _wait_for_line(proc.stderr, "to analyse")  # the plan is made: the cluster starts next
    os.killpg(proc.pid, signal.SIGTERM)
    out, err = proc.communicate(timeout=TIMEOUT)
    err = head + err
    assert proc.returncode == 143, err
    assert "Traceback" not in err and "Exception" not in err, err
    con = sqlite3.connect(db)
    assert con.execute("PRAGMA integrity_check").fetchone()[0] == "ok"
    con.close()
