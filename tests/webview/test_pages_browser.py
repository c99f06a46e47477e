"""The pages in a real browser (headless chromium): the alarm report of `run --report`, the analyze report, the
fleet report's interactive part and the live page of `run --web` while a replay feeds it. Each: the table,
the plots (canvas elements drawn at their size), one alarm's evidence, a non-blank screenshot with colour in
it, nothing loaded from the network. The live page: its JSON endpoint advances while the run is fed, the
page re-renders from it, and the wrong address or a port in use is one error line before any work."""

from __future__ import annotations

import json
import re
import signal
import socket
import subprocess
import sys
import time
import urllib.request

import pytest

from companion.cli.main import main
from companion.cli.run_web import WEB_READY
from companion.errors import EXIT_FAULTS
from tests.support import browser
from tests.support.loopback import ROOT, env, stop
from tests.support.readiness import wait_for_text

pytestmark = browser.needs_chromium
FAULT_AT = 70


@pytest.fixture(scope="module")
def noisy_log(tmp_path_factory):
    """Two IMUs at rest, IMU1's Y axis noise 6x from 70 s on, 130 s (the sample model, 50 Hz)."""
    d = tmp_path_factory.mktemp("log")
    log = d / "noise.tlog"
    model = ROOT / "companion" / "examples" / "sample_model.yaml"
    assert main(["simulate", str(model), "--vehicle", "--imus", "2", "--duration", "130",
                 "--fault", "noise", "--fault-at", str(FAULT_AT), "--fault-imu", "1", "--fault-axis", "gy",
                 "--seed", "5", "--out", str(log)]) == 0
    return log


def _colour(px) -> int:
    """Pixels with colour (not grey, white or black): the plotted series and bands."""
    return int(((px.max(axis=2) - px.min(axis=2)) > 60).sum())


def _rows(html: str, table_id: str) -> list[str]:
    t = re.search(rf'<table id="{table_id}">(.*?)</table>', html, re.S)
    assert t, html[:3000]
    return re.findall(r"<tr\b.*?</tr>", t.group(1), re.S)


def test_alarm_report(noisy_log, tmp_path, capsys):
    page = tmp_path / "alarms.html"
    assert main(["run", "--source", str(noisy_log), "--baseline-s", "60", "--quiet", "--report", str(page)]) == EXIT_FAULTS  # the noise alarm
    text = page.read_text()
    assert browser.no_network(text)
    html = browser.dom(tmp_path / "chr", page.as_uri())
    assert 'data-rendered="alarms"' in html
    rows = _rows(html, "alarms")
    assert len(rows) >= 2 and "<th>" in rows[0] and ">noise<" in rows[1] and 'href="#ev-0"' in rows[1]
    ev = re.search(r'<section class="evidence" id="ev-0">(.*?)</section>', html, re.S).group(1)
    assert "IMU1 gyro axis Y: its noise rose to" in ev
    sizes = browser.canvases(ev)
    # the alarm IMU's gyro, its twin's, the statistic against its threshold, the spectrum; drawn at their size
    assert len(sizes) == 4 and all(w >= 600 and h >= 200 for w, h in sizes), sizes
    px = browser.screenshot(tmp_path / "chr", page.as_uri(), tmp_path / "alarms.png", height=1600)
    assert px.std() > 20 and _colour(px[700:]) > 20000  # the plots below the tables have colour in them
    # ?selftest: one wheel step in the middle of the first plot zooms its x range to 0.8 about the mouse, and the
    # readout under the mouse gives the time and every axis' bucket there
    ranges = re.findall(r'data-xrange="([^"]+)"', html)
    zoomed = browser.dom(tmp_path / "chr", page.as_uri() + "?selftest")
    (a0, a1), (b0, b1) = (map(float, r.split(",")) for r in (ranges[0], re.findall(r'data-xrange="([^"]+)"', zoomed)[0]))
    assert abs((b1 - b0) / (a1 - a0) - 0.8) < 0.01 and abs((b0 + b1) / 2 - (a0 + a1) / 2) < 0.05 * (a1 - a0)
    tip = re.search(r'<div class="cplot-tip" style="[^"]*display: block[^"]*">([^<]*)', zoomed).group(1)
    assert tip.startswith("message time (s): ") and all(f"{ax}: " in tip for ax in ("gx", "gy", "gz")), tip


def test_analyze_report_with_the_flagged_imus_evidence(noisy_log, tmp_path, capsys):
    page, js = tmp_path / "analyze.html", tmp_path / "analyze.json"
    assert main(["analyze", str(noisy_log), "--report", str(page), "--json", str(js), "--quiet"]) == 0
    rep = json.loads(js.read_text())
    assert [(e["imu"], e["axis"], e["kind"]) for e in rep["evidence"]] == [(1, "gy", "noise")]
    assert browser.no_network(page.read_text())
    html = browser.dom(tmp_path / "chr", page.as_uri())
    assert 'data-rendered="analyze"' in html
    rows = _rows(html, "terms")
    assert len(rows) == 1 + 2 * 6 and "deg/sqrt(h)" in rows[1]
    adev = re.findall(r'<div class="plotbox adev">', html)
    assert len(adev) == 4  # gyro and accelerometer of each IMU
    assert len(_rows(html, "alarms")) == 2 and 'id="ev-0"' in html
    assert len(browser.canvases(html)) == 4 + 4 and all(w >= 600 for w, _ in browser.canvases(html))
    px = browser.screenshot(tmp_path / "chr", page.as_uri(), tmp_path / "analyze.png")
    assert px.std() > 20 and _colour(px) > 5000  # the curves and their bands


def test_fleet_report_interactive_part(tmp_path, capsys):
    logs, db = tmp_path / "logs", str(tmp_path / "f.sqlite")
    assert main(["fleet", "simulate", str(logs), "--vehicles", "2", "--flights", "6", "--imus", "1",
                 "--duration", "20", "--rate", "50", "--degrading", "1", "--rise", "3"]) == 0
    assert main(["fleet", "analyze", str(logs), "--db", db, "--workers", "0", "--quiet"]) == 0
    page, js = tmp_path / "r.html", tmp_path / "r.json"
    assert main(["fleet", "report", "--db", db, "--html", str(page), "--json", str(js)]) == EXIT_FAULTS  # degrading
    rep = json.loads(js.read_text())
    flagged = [e for e in rep["imus"] if e["flagged"]]
    assert len(flagged) == 1 and len(rep["evidence"]) == 1
    st = rep["evidence"][0]["statistic"]
    assert st["value"][-1] >= st["threshold"][-1] and st["state"][-1] == 1
    assert browser.no_network(page.read_text())
    html = browser.dom(tmp_path / "chr", page.as_uri() + "?interactive")
    assert '<details id="interactive" open="">' in html and 'data-rendered="fleet"' in html
    assert len(_rows(html, "ranking")) == 3  # the fixed page is still there
    sizes = browser.canvases(html)
    # one trend plot per IMU, then the flagged IMU's evidence: three axes and the statistic
    assert len(sizes) == 2 + 3 + 1 and all(w >= 600 for w, _ in sizes), sizes
    assert "rose" in re.search(r'id="ev-0">(.*?)</section>', html, re.S).group(1)


def _get(url: str) -> bytes:
    with urllib.request.urlopen(url, timeout=30) as r:
        return r.read()


def test_live_page_follows_a_replay(noisy_log, tmp_path):
    out = tmp_path / "run.err"
    with open(out, "w") as fh:
        proc = subprocess.Popen([sys.executable, "-m", "companion", "run", "--source", str(noisy_log),
                                 "--baseline-s", "60", "--quiet", "--web", "127.0.0.1:0"], cwd=tmp_path, env=env(),
                                stdout=subprocess.DEVNULL, stderr=fh, start_new_session=True)
    try:
        url = re.search(rf"{WEB_READY} (\S+)", wait_for_text(out, WEB_READY, proc)).group(1)
        assert url.startswith("http://127.0.0.1:")
        seen = []
        deadline = time.monotonic() + 300
        while time.monotonic() < deadline:  # polled as the page does, until the replay is done
            d = json.loads(_get(url + "data.json"))
            seen.append((d["t_s"], d["running"], len(d["alarms"])))
            if not d["running"]:
                break
            time.sleep(0.05)  # polling interval
        running = sorted({t for t, r, _ in seen if r and t is not None})
        assert len(running) >= 2 and running[0] < 100, seen  # the values advanced while the run was fed
        assert seen[-1][1] is False and seen[-1][0] > 129 and seen[-1][2] >= 1
        assert json.loads(_get(url + "evidence.json"))[0]["kind"] == "noise"
        with pytest.raises(urllib.error.HTTPError):
            _get(url + "elsewhere")
        assert browser.no_network(_get(url).decode())
        html = browser.dom(tmp_path / "chr", url, "--virtual-time-budget=4000")
        count = int(re.search(r'<p id="updated" data-t="[^"]*" data-count="(\d+)"', html).group(1))
        assert count >= 1  # the page polled data.json and rendered it again
        assert re.findall(r'<section class="imu" id="imu-(\d)"', html) == ["0", "1"]
        assert len(_rows(html, "coef-0")) == 4 and "deg/sqrt(h)" in _rows(html, "coef-0")[1]
        assert len(_rows(html, "alarms")) >= 2 and 'id="ev-0"' in html
        assert len(browser.canvases(html)) >= 2 + 4
        px = browser.screenshot(tmp_path / "chr", url, tmp_path / "live.png")
        assert px.std() > 20 and _colour(px) > 5000
    finally:
        proc.send_signal(signal.SIGTERM)
        rc = stop(proc)
    assert rc == EXIT_FAULTS, out.read_text()  # stopped by SIGTERM: the summary with its noise alarm


@pytest.mark.parametrize("where", ["in use", "bad"])
def test_web_address_errors_before_any_work(noisy_log, where, capsys):
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        s.listen(1)
        arg = f"127.0.0.1:{s.getsockname()[1]}" if where == "in use" else "host:port"
        assert main(["run", "--source", str(noisy_log), "--web", arg]) == 2
    out, err = capsys.readouterr()
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("companion: error: --web"), err
    assert "replayed" not in out + err and "IMU0" not in out


def test_live_page_shows_the_noise_per_condition(tmp_path):
    """Three IMUs of the copter preset flying 20-140 s: the live page's condition table per IMU, still, on the
    ground and in flight, the flight row a three-cornered-hat figure with its interval or bound."""
    log = tmp_path / "flight.tlog"
    assert main(["simulate", "--vehicle", "--preset", "copter", "--imus", "3", "--arm-at", "20", "--disarm-at",
                 "140", "--duration", "150", "--seed", "3", "--out", str(log)]) == 0
    out = tmp_path / "run.err"
    with open(out, "w") as fh:
        proc = subprocess.Popen([sys.executable, "-m", "companion", "run", "--source", str(log), "--no-state",
                                 "--quiet", "--web", "127.0.0.1:0"], cwd=tmp_path, env=env(),
                                stdout=subprocess.DEVNULL, stderr=fh, start_new_session=True)
    try:
        url = re.search(rf"{WEB_READY} (\S+)", wait_for_text(out, WEB_READY, proc)).group(1)
        deadline = time.monotonic() + 300
        while time.monotonic() < deadline:  # polled as the page does, until the replay is done
            d = json.loads(_get(url + "data.json"))
            if not d["running"]:
                break
            time.sleep(0.05)  # polling interval
        assert not d["running"]
        for m in d["imus"]:
            rows = {(r["condition"], r["axis"]): r for r in m["conditions"]}
            assert sorted({c for c, _ in rows}) == ["flight", "ground", "still"] and len(rows) == 9
            for ax in ("gx", "gy", "gz"):
                fl = rows[("flight", ax)]
                assert "three-cornered hat" in fl["source"] and fl["value"] > 0, fl
                assert fl["bound"] or fl["ci95"][0] < fl["value"] < fl["ci95"][1]
                assert fl["text"].startswith("<") == fl["bound"]
        html = browser.dom(tmp_path / "chr", url, "--virtual-time-budget=2000")
        for imu in range(3):
            rows = _rows(html, f"cond-{imu}")
            assert len(rows) == 1 + 9 and "N (95 %)" in rows[0], rows[:2]
            flight = [r for r in rows if "in flight" in r]
            assert len(flight) == 3 and all("deg/sqrt(h)" in r and "three-cornered hat" in r for r in flight)
            assert sum("still (at rest)" in r for r in rows) == 3 and sum("on the ground" in r for r in rows) == 3
    finally:
        proc.send_signal(signal.SIGTERM)
        rc = stop(proc)
    assert rc == 0, out.read_text()
