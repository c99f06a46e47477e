"""Helpers for loopback tests: `companion sim-autopilot` -> `companion run` over UDP on 127.0.0.1.

Every wait is bounded and waits for a signal (a line in a process' output, a process' exit), never a
fixed time; every process is killed at the end.
"""

from __future__ import annotations

import json
import os
import re
import signal
import socket
import subprocess
import sys
from pathlib import Path

from tests.support.readiness import READY, wait_for_text  # noqa: F401 (re-exported for the loopback tests)
from tests.support.run_status import expected_run_status

ROOT = Path(__file__).resolve().parents[2]

#: Linux shows each UDP socket's unread bytes (/proc/net/udp): sim-autopilot --flow-control then sends as fast
#: as the receiver reads (simulated time waits for it, nothing is lost by overrunning it), capped at FAST x;
#: elsewhere, or with COMPANION_TEST_WALL_PACING=1, a test's own --speedup paces by the wall clock.
FLOW_CONTROL = Path("/proc/net/udp").is_file() and not os.environ.get("COMPANION_TEST_WALL_PACING")
FAST = 1000.0
#: the loopback tests' vehicle: white noise of N_SI rad/s/sqrt(Hz) on each gyro axis at RATE Hz (30 mrad/s per
#: sample, 30x the 1 mrad/s LSB of RAW_IMU)
N_SI = 3e-3
RATE = 100.0


def white_model(n_si: float = N_SI, rate: float = RATE) -> str:
    """A sim-autopilot model (YAML) of white noise ``n_si`` rad/s/sqrt(Hz) on each gyro axis at ``rate`` Hz."""
    return f"rate_hz: {rate:g}\naxes:\n" + "".join(f"  {a}: [{{effect: white_noise, N: {n_si}}}]\n" for a in ("gx", "gy", "gz"))


MODEL = white_model()


def pacing(speedup: float, *ports: int) -> list[str]:
    """sim-autopilot's pacing options: flow-controlled where possible (``ports``: further UDP queues to wait
    on, e.g. the next hop of a relay), else ``speedup`` simulated seconds per wall second. A test's deadlines
    stay those of ``speedup`` (the slowest pace the test allows for)."""
    if not FLOW_CONTROL:
        return ["--speedup", str(speedup)]
    return ["--speedup", str(FAST), "--flow-control", *(a for p in ports for a in ("--flow-port", str(p)))]


def free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def env() -> dict:
    e = dict(os.environ)
    e["PYTHONPATH"] = str(ROOT) + os.pathsep + e.get("PYTHONPATH", "")
    return e


def start(args, cwd, out_name):
    """``python -m companion ARGS`` in ``cwd``, stdout and stderr into ``cwd/out_name``, in its own session."""
    out = open(Path(cwd) / out_name, "w")
    proc = subprocess.Popen([sys.executable, "-m", "companion", *args], cwd=cwd, env=env(), stdout=out,
                            stderr=subprocess.STDOUT, start_new_session=True)
    out.close()
    return proc


def stop(proc, sig=signal.SIGTERM, timeout=20.0):
    """Signal the process group, wait (bounded), SIGKILL if needed; returns the exit code."""
    if proc.poll() is None:
        try:
            os.killpg(proc.pid, sig)
        except ProcessLookupError:
            pass
        try:
            proc.wait(timeout)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait(5)
    return proc.returncode


def read_record(path):
    """(NAMED_VALUE_FLOAT records, STATUSTEXT records) of a sim-autopilot --record file."""
    nvf, texts = [], []
    for line in Path(path).read_text().splitlines():
        d = json.loads(line)
        (nvf if d["type"] == "NAMED_VALUE_FLOAT" else texts).append(d)
    return nvf, texts


def link_losses(tmp_path) -> dict:
    """{message: fraction of the IMU messages sim-autopilot sent that run did not count} from both outputs."""
    sent = re.search(r"sent (.*?) and \d+ HEARTBEAT", (tmp_path / "sim.out").read_text())
    got = dict(re.findall(r"^IMU\d \((\w+), [^)]*\): .*?; (\d+) samples", (tmp_path / "run.out").read_text(), re.M))
    out = {}
    for count, name in re.findall(r"(\d+) (\w+)", sent.group(1) if sent else ""):
        out[name] = 1.0 - int(got.get(name, 0)) / max(int(count), 1)
    return out


def sim_against_run(tmp_path, model_text, sim_args, duration, speedup, run_args=(), slack_s=60.0, max_loss=0.25):
    """Run ``companion run`` on a free UDP port, wait until it listens, play ``sim-autopilot SIM_ARGS`` into
    it for ``duration`` simulated seconds (the simulation starts when run asks for data) as fast as run reads
    (``pacing``; deadlines from ``speedup``),
    stop run (SIGTERM); returns (nvf, texts) as sim-autopilot recorded them (``t_sim`` = time since boot,
    the simulation starts at 1 s). Fails with a clear message when the link lost more than ``max_loss`` of the IMU messages (default
    25 %: a busy machine's UDP receiver drops what it cannot take, and the pipeline is shown within 5 % at 20 %
    random or bursty loss in tests/mavlink/test_link.py, so a loaded CI run stays green)."""
    (tmp_path / "model.yaml").write_text(model_text)
    port = free_udp_port()
    wall = duration / speedup
    run = start(["run", "--source", f"udpin:127.0.0.1:{port}", "--no-state", "--duration", str(wall + 2 * slack_s),
                 *run_args], tmp_path, "run.out")
    sim = None
    try:
        wait_for_text(tmp_path / "run.out", READY, run)
        sim = start(["sim-autopilot", "--model", "model.yaml", "--connect", f"udpout:127.0.0.1:{port}",
                     *pacing(speedup), "--duration", str(duration), "--wait-request",
                     "--wall-limit", str(wall + slack_s), "--record", "rx.jsonl", "--quiet", *sim_args],
                    tmp_path, "sim.out")
        sim.wait(wall + 2 * slack_s)
        assert sim.returncode == 0, (tmp_path / "sim.out").read_text()
        rc = stop(run)  # SIGTERM: the summary, then the status it gives
        said = (tmp_path / "run.out").read_text()
        assert rc == expected_run_status(said), said
    finally:
        for p in (sim, run):
            if p is not None:
                stop(p)
    loss = link_losses(tmp_path)
    assert loss and max(loss.values()) <= max_loss, (
        f"UDP loopback lost IMU messages {loss} at {speedup:g}x: the receiver could not keep up (busy machine?)")
    return read_record(tmp_path / "rx.jsonl")
