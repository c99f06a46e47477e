"""The companion in a real chain over loopback: `companion sim-autopilot` -> MAVProxy (from PyPI, as the
router) -> `companion run --gcs udpout:...` -> a pymavlink ground-station listener. MAVProxy does not
forward what its --out peer sends to its other outputs, so the reports reach the GCS through --gcs.
Every wait is for a signal with a generous deadline; every process is killed at the end.

Test model: white noise N = 3e-3 rad/s/sqrt(Hz) per gyro axis at 100 Hz; a stuck gyro X after the
baseline is learned gives alarm STATUSTEXTs besides the reports.
"""

from __future__ import annotations

import re
import shutil
import signal

import pytest
from tests.support.chain import (FAULT_WORDS, MODEL, Listener, imu_times, low_rate_episodes, mavlink_routerd, sent_by_companion,
                   start_chain, start_mavlink_router)
from tests.support.readiness import READY, wait_for_text

from tests.support.loopback import free_udp_port, read_record, start, stop
from tests.support.run_status import expected_run_status

pytestmark = [pytest.mark.network,
              pytest.mark.skipif(shutil.which("mavproxy.py") is None, reason="MAVProxy not installed")]


def stuck_run_stopped(tmp_path, run):
    """Stop `run` (SIGTERM: the summary, then the status it gives) after a stuck gyro X; the NAMED_VALUE_FLOAT
    names and STATUSTEXTs it sent (its --out-tlog run.tlog): the reports, an alarm and the learned baseline."""
    rc = stop(run)
    said = (tmp_path / "run.out").read_text()
    assert rc == expected_run_status(said), said
    names, texts = sent_by_companion(tmp_path / "run.tlog")
    assert {"IMU0GX_N", "IMU0G_HLTH", "IMU0G_FLT"} <= names, names
    assert any("stuck" in t for t in texts), texts  # an alarm was sent
    assert any("baseline learned" in t for t in texts), texts
    return names, texts


def test_reports_reach_a_gcs_behind_mavproxy_through_gcs_output(tmp_path):
    duration, speedup = 90.0, 10.0
    chain = start_chain(tmp_path, ["--baseline-s", "30", "--duration", "300", "--out-tlog", str(tmp_path / "run.tlog")])
    gcs, run = chain.gcs, chain.run
    try:
        sim = chain.start_sim(["--speedup", str(speedup), "--duration", str(duration), "--wait-request",
                               "--fault", "stuck", "--fault-at", "50", "--fault-axis", "gx", "--wall-limit", "120",
                               "--record", "rx.jsonl", "--quiet"])
        sim.wait(240)  # bounded by its --wall-limit
        assert sim.returncode == 0, (tmp_path / "sim.out").read_text()
        names, texts = stuck_run_stopped(tmp_path, run)
        # everything the companion sent is at the GCS (UDP on loopback: wait for the listener to catch up)
        ok = gcs.wait_for(lambda g: names <= set(g.names) and sorted(texts) == sorted(t for _, t in g.texts))
        assert ok, (sorted(names - set(gcs.names)), texts, gcs.texts)
        assert gcs.heartbeats > 0
        # the last values the GCS got are those of the run summary (one source of truth)
        out = (tmp_path / "run.out").read_text()
        counted = re.search(r"stopping: \d+ messages sent, (\d+) NAMED_VALUE_FLOAT, (\d+) STATUSTEXT", out)
        assert counted and int(counted.group(2)) == len(texts), (counted, texts)  # the exit line counts right
        m = re.search(r"^  gy online: N ([\d.]+) \+- [\d.]+ .*?; B (<? ?)([\d.e+]+) deg/h; K (<? ?)([\d.e+]+) deg/h\^1.5", out, re.M)
        assert m, out
        with gcs.lock:
            last = dict(gcs.names)
        assert last["IMU0GY_N"] == pytest.approx(float(m.group(1)), rel=2e-3, abs=1e-3)
        for param, bound, value in (("B", m.group(2), m.group(3)), ("K", m.group(4), m.group(5))):
            assert last[f"IMU0GY_{param}"] == pytest.approx(float(value), rel=1e-2, abs=0.5), (param, last, m.group(0))
            assert (last[f"IMU0GY_{param}S"] == -1.0) == bool(bound.strip())  # a bound is sent with sigma -1
    finally:
        chain.close()


@pytest.mark.soak  # kept out of the README's command for its time (python -m benchmarks.soak_checks)
def test_mavproxy_default_stream_rates_beside_the_companion_raise_no_alarm(tmp_path):
    """An autopilot that refuses SET_MESSAGE_INTERVAL, MAVProxy with its default stream-rate behaviour
    (REQUEST_DATA_STREAM of all streams at 4 Hz, again every 15 s of wall clock): the IMU rate falls from
    50 to 4 Hz; the companion asks again and gets it back within 10 s of wall clock each time, and no
    alarm is raised (a rate change is not a gyro fault)."""
    duration, speedup = 170.0, 8.0  # MAVProxy asks again every 15 s of wall clock: at 120 s simulated
    chain = start_chain(tmp_path, ["--baseline-s", "30", "--duration", "300", "--out-tlog", str(tmp_path / "run.tlog")],
                        default_streamrate=True)
    try:
        sim = chain.start_sim(["--speedup", str(speedup), "--duration", str(duration), "--wait-request",
                               "--refuse-interval", "--wall-limit", "80", "--record", "rx.jsonl"])
        sim.wait(300)  # bounded by its --wall-limit
        assert sim.returncode == 0, (tmp_path / "sim.out").read_text()
        rc = stop(chain.run)  # SIGTERM: the summary, then the status it gives
        said = (tmp_path / "run.out").read_text()
        assert rc == expected_run_status(said), said
    finally:
        chain.close()
    out = (tmp_path / "run.out").read_text()
    sim_out = (tmp_path / "sim.out").read_text()
    assert "REQUEST_DATA_STREAM 0 at 4 Hz" in sim_out, sim_out  # MAVProxy did ask for 4 Hz
    t = imu_times(tmp_path / "run.tlog")
    assert t and t[-1] - t[0] > 0.8 * duration
    drops = low_rate_episodes(t, 50.0)
    assert drops, "MAVProxy's requests never lowered the rate: the test shows nothing"
    # in message time: every drop came back before the record ended, and before MAVProxy asked again (its
    # requests 15 s apart start the drops: back within 2/3 of that spacing, i.e. 10 s of its 15 s)
    for (start_t, length), nxt in zip(drops, drops[1:] + [None]):
        assert start_t + length < t[-1] - 1.0, (drops, out)
        if nxt is not None:
            assert length < 2.0 / 3.0 * (nxt[0] - start_t), (drops, out)
    assert "asking again" in out
    records = read_record(tmp_path / "rx.jsonl")[1]
    texts = [d["text"] for d in records]
    assert not [x for x in texts if any(w in x.lower() for w in FAULT_WORDS)], texts
    learned = [d["t_sim"] for d in records if d["text"] == "IMU0 gyro baseline learned"]
    assert learned, texts
    # a drop while the detectors watch (after the baseline), not only one while they learn
    assert any(start_t > learned[0] for start_t, _ in drops), (drops, learned)


@pytest.mark.soak  # kept out of the README's command for its time (python -m benchmarks.soak_checks)
def test_router_outage_texts_reach_the_gcs_and_health_is_back_to_healthy_at_once(tmp_path):
    """A healthy gyro, the baseline learned (HLTH 0 at the GCS), MAVProxy killed while data flow and
    restarted after two "data stopped" texts (>= 10 s): the GCS (behind --gcs) gets "IMU data stopped"
    while the router is down and "IMU data back" after it; the health IMU0G_HLTH it receives is 3 (stale)
    during the outage and reads 0 (healthy) again within 2 s of message time after "data back" (the
    NAMED_VALUE_FLOAT's time_boot_ms), and stays so. Order is arrival order at the GCS, not its clock."""
    chain = start_chain(tmp_path, ["--baseline-s", "30", "--duration", "300"])
    gcs = chain.gcs
    try:
        chain.start_sim(["--speedup", "10", "--wait-request", "--wall-limit", "200", "--quiet"])
        assert gcs.wait_for(lambda g: any(v == 0.0 for _, v in g.health), 120), (tmp_path / "run.out").read_text()
        stop(chain.proxy, signal.SIGKILL)
        with gcs.lock:
            i_kill = gcs.received
        stopped = lambda g: [i for i, x in g.texts_seq if x.startswith("companion: IMU data stopped")]  # noqa: E731
        assert gcs.wait_for(lambda g: len(stopped(g)) >= 2, 120), (gcs.texts, (tmp_path / "run.out").read_text())
        assert gcs.wait_for(lambda g: any(i > i_kill and v == 3.0 for i, v, _ in g.health_seq), 30)
        chain.restart_proxy()
        back = lambda g: [i for i, x in g.texts_seq if x.startswith("companion: IMU data back")]  # noqa: E731
        assert gcs.wait_for(lambda g: back(g), 120), (gcs.texts, (tmp_path / "run.out").read_text())
        i_back = back(gcs)[0]
        after = lambda g: [(v, t) for i, v, t in g.health_seq if i > i_back]  # noqa: E731
        assert gcs.wait_for(lambda g: any(v == 0.0 for v, _ in after(g)), 30), gcs.health_seq[-20:]
        with gcs.lock:
            seq = after(gcs)
        first_ok = next(k for k, (v, _) in enumerate(seq) if v == 0.0)
        assert seq[first_ok][1] - seq[0][1] < 2.0, seq[:first_ok + 1]  # message time from "data back"
        assert all(v == 0.0 for v, _ in seq[first_ok:]), seq
        assert stopped(gcs)[0] > i_kill
    finally:
        chain.close()


@pytest.mark.skipif(mavlink_routerd() is None, reason="mavlink-routerd not found: no Debian 12 package, none on PyPI (set MAVLINK_ROUTERD to a built one)")
def test_reports_reach_a_gcs_through_mavlink_router_on_the_companion_computer(tmp_path):
    """mavlink-router forwards between its endpoints: `companion run` on one UDP endpoint (no --gcs), the
    GCS on another; the GCS receives every NAMED_VALUE_FLOAT name and every STATUSTEXT the companion sent,
    and the vehicle's data reach the companion at the rate it asked for through the router."""
    (tmp_path / "model.yaml").write_text(MODEL)
    p_master, p_run, p_gcs = free_udp_port(), free_udp_port(), free_udp_port()
    gcs = Listener(p_gcs)
    procs = []
    try:
        procs.append(start_mavlink_router(tmp_path, p_master, [p_run, p_gcs]))
        run = start(["run", "--source", f"udpin:127.0.0.1:{p_run}", "--no-state", "--baseline-s", "30",
                     "--duration", "300", "--out-tlog", str(tmp_path / "run.tlog")], tmp_path, "run.out")
        procs.append(run)
        wait_for_text(tmp_path / "run.out", READY, run)
        sim = start(["sim-autopilot", "--model", "model.yaml", "--connect", f"udpout:127.0.0.1:{p_master}",
                     "--speedup", "10", "--duration", "90", "--wait-request", "--fault", "stuck", "--fault-at", "50",
                     "--fault-axis", "gx", "--wall-limit", "120", "--quiet"], tmp_path, "sim.out")
        procs.append(sim)
        sim.wait(240)  # bounded by its --wall-limit
        assert sim.returncode == 0, (tmp_path / "sim.out").read_text()
        names, texts = stuck_run_stopped(tmp_path, run)
        ok = gcs.wait_for(lambda g: names <= set(g.names) and sorted(texts) == sorted(t for _, t in g.texts))
        assert ok, (sorted(names - set(gcs.names)), texts, gcs.texts, (tmp_path / "router.out").read_text())
        assert gcs.heartbeats > 0
        t = imu_times(tmp_path / "run.tlog")
        assert len(t) > 100 and (len(t) - 1) / (t[-1] - t[0]) > 90.0  # the 100 Hz asked for, through the router
    finally:
        for p in procs:
            stop(p, signal.SIGKILL)
        gcs.close()
