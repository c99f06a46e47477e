"""The live page of `run --web` on a live link: sim-autopilot plays a vehicle whose gyro Y gets 6x its noise at
100 s into `companion run` over UDP (127.0.0.1); the page's JSON endpoint, polled as the page does, follows
the run (message time advancing, the coefficient N at the simulated value), then shows the noise alarm and
its evidence. Readiness lines only, no fixed wait."""

from __future__ import annotations

import json
import re
import time
import urllib.request

import pytest

from companion.cli.run_web import WEB_READY
from tests.support.loopback import MODEL, N_SI, free_udp_port, pacing, start, stop
from tests.support.readiness import READY, wait_for_text

pytestmark = pytest.mark.network



def _json(url):
    with urllib.request.urlopen(url, timeout=30) as r:
        return json.loads(r.read())


def test_live_page_follows_a_live_link(tmp_path):
    (tmp_path / "model.yaml").write_text(MODEL)
    port = free_udp_port()
    run = start(["run", "--source", f"udpin:127.0.0.1:{port}", "--no-state", "--duration", "200", "--baseline-s", "60",
                 "--quiet", "--web", "127.0.0.1:0"], tmp_path, "run.out")
    sim = None
    try:
        wait_for_text(tmp_path / "run.out", READY, run)  # the page is served before the link opens
        url = re.search(rf"{WEB_READY} (\S+)", (tmp_path / "run.out").read_text()).group(1)
        sim = start(["sim-autopilot", "--model", "model.yaml", "--connect", f"udpout:127.0.0.1:{port}", *pacing(10.0),
                     "--duration", "170", "--wait-request", "--wall-limit", "60", "--quiet", "--fault", "noise",
                     "--fault-at", "100", "--fault-size", "6", "--fault-axis", "gy", "--seed", "5"], tmp_path, "sim.out")
        seen, last = [], None
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline:
            last = _json(url + "data.json")
            if last["t_s"] is not None:
                seen.append(last["t_s"])
            if last["alarms"] and any(a["complete"] for a in last["alarms"]) or sim.poll() is not None:
                break
            time.sleep(0.25)  # polling interval (the page polls once a second)
        sim.wait(60)
        last = _json(url + "data.json")
        assert len(set(seen)) >= 3 and seen == sorted(seen), seen[:20]  # message time advanced while fed
        imu = last["imus"][0]
        n = next(c for c in imu["axes"]["gx"]["coefficients"] if c["param"] == "N")
        assert abs(n["value"] / N_SI - 1) < 0.1 and n["ci95"][0] < N_SI < n["ci95"][1]
        assert [(a["imu"], a["axis"], a["kind"]) for a in last["alarms"]][:1] == [(0, "gy", "noise")]
        ev = _json(url + "evidence.json")[0]
        assert 100 < ev["t_s"] < 115 and ev["series"][0]["role"] == "alarm" and ev["spectrum"]["two_sided"]
        assert "noise rose to" in ev["sentence"]
        assert imu["health"] == "degrading" and last["running"]
    finally:
        for p in (sim, run):
            if p is not None:
                stop(p)
    assert run.returncode == 4, (tmp_path / "run.out").read_text()  # the injected noise fault: EXIT_FAULTS
