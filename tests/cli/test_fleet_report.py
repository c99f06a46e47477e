"""companion fleet report: the HTML page in a real browser (headless chromium) and the report when every log
failed."""

from __future__ import annotations

import json
import re
import shutil
import subprocess

import numpy as np
import pytest

from companion.cli.main import main

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")


def _chromium(tmp_path, *args):
    """Headless chromium on a page, as root too (--no-sandbox), with a profile of its own (xdist-safe)."""
    return subprocess.run([CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu", "--hide-scrollbars",
                           "--force-device-scale-factor=1", f"--user-data-dir={tmp_path / 'chromium'}", *args],
                          capture_output=True, text=True, timeout=180)


def _bands(rows, min_gap=100):
    """Runs of True in a 1-D mask, separated by at least ``min_gap`` False entries: [(first, last), ...]."""
    out = []
    for i in np.flatnonzero(rows):
        if out and i - out[-1][1] <= min_gap:
            out[-1][1] = i
        else:
            out.append([i, i])
    return [tuple(b) for b in out]


@pytest.mark.skipif(CHROMIUM is None, reason="chromium not installed (.ci/run installs Debian's chromium; "
                    "locally: apt-get install chromium)")
def test_html_opens_in_headless_chromium(tmp_path, capsys):
    """The report in a real browser: the rendered DOM has the ranking table (a header and one row per IMU) and
    one PNG plot per IMU; the screenshot is a real page (not blank), shows the table's grey header cells and
    the plots: the tab:green gy series of each IMU appears in its own band, one band per plot."""
    Image = pytest.importorskip("PIL.Image")
    logs = tmp_path / "logs"
    assert main(["fleet", "simulate", str(logs), "--vehicles", "2", "--flights", "5", "--imus", "1",
                 "--duration", "20", "--rate", "50", "--degrading", "1", "--rise", "2"]) == 0
    db = str(tmp_path / "f.sqlite")
    assert main(["fleet", "analyze", str(logs), "--db", db, "--workers", "0", "--quiet"]) == 0
    html = tmp_path / "r.html"
    assert main(["fleet", "report", "--db", db, "--html", str(html), "--json", str(tmp_path / "r.json")]) == 0
    vehicles = [e["vehicle"] for e in json.loads((tmp_path / "r.json").read_text())["imus"]]
    assert len(vehicles) == 2
    r = _chromium(tmp_path, "--dump-dom", html.as_uri())
    assert r.returncode == 0, r.stderr[-2000:]
    dom = r.stdout
    assert "<h1>Gyro trends across flights</h1>" in dom
    table = re.search(r'<table id="ranking">(.*?)</table>', dom, re.S)
    assert table, dom[:2000]
    rows = re.findall(r"<tr\b.*?</tr>", table.group(1), re.S)
    assert len(rows) == 1 + len(vehicles) and "<th" in rows[0]  # header + one row per IMU, in ranking order
    for row, vehicle in zip(rows[1:], vehicles):
        assert f">{vehicle}</a>" in row, row
    imgs = re.findall(r'<img [^>]*src="data:image/png;base64,', dom)
    assert len(imgs) == len(vehicles)
    shot = tmp_path / "shot.png"
    r = _chromium(tmp_path, f"--screenshot={shot}", "--window-size=1200,1400", html.as_uri())
    assert r.returncode == 0 and shot.is_file(), r.stderr[-2000:]
    px = np.asarray(Image.open(shot).convert("RGB")).astype(int)
    assert px.shape == (1400, 1200, 3)
    assert px.std() > 20  # not a blank page (white everywhere: 0)
    header = np.flatnonzero(np.all(px == 238, axis=2).sum(axis=1) > 300)  # rows across the header cells (#eee)
    assert header.size >= 10 and header.max() - header.min() < 40, header  # one header row of the table
    r_, g_, b_ = px[..., 0], px[..., 1], px[..., 2]
    green = (g_ > 110) & (r_ < 110) & (b_ < 110) & (g_ - r_ > 60)  # tab:green (44, 160, 44) and its edges
    # one band per plot: in a plot (232 px high at 80 dpi) the green series and legend entry lie < 100 px
    # apart; between two plots lie the x-axis label, the next section's heading and its paragraph
    bands = _bands(green.sum(axis=1) > 0)
    assert len(bands) == len(vehicles), bands
    assert all(b[0] > header.max() + 20 * len(vehicles) and b[1] - b[0] > 30 for b in bands), (bands, header)


def test_every_log_failed_still_writes_the_report_saying_why(tmp_path, capsys):
    logs = tmp_path / "logs"
    logs.mkdir()
    (logs / "a.tlog").write_text("not a telemetry log\n")
    (logs / "b.csv").write_text("time_s,gx\n0,0\n")
    db = str(tmp_path / "f.sqlite")
    assert main(["fleet", "analyze", str(logs), "--db", db, "--workers", "0", "--quiet"]) == 5  # no log analysed
    capsys.readouterr()
    out, page = tmp_path / "r.json", tmp_path / "r.html"
    assert main(["fleet", "report", "--db", db, "--html", str(page), "--json", str(out)]) == 5  # no usable data
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "all 2 log(s) failed" in err[0]
    text = page.read_text()
    assert "No IMU could be ranked: all 2 log(s) failed" in text
    assert "no IMU messages" in text and "missing column" in text  # the reasons
    assert "a.tlog" in text and "b.csv" in text
    rep = json.loads(out.read_text())
    assert rep["imus"] == [] and rep["logs"] == {"ok": 0, "failed": 2}
